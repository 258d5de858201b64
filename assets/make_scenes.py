"""The demo scenes and the small scenes the tests bake.

Every function returns a ``GltfBuilder``; the caller saves it (``.save("x.glb")``). Lengths are in
metres, colours linear RGB. Scene functions describe what they built in ``builder.info`` (node
names and indices, triangle ranges, ...), which tests read and which is not written to the file.

    python assets/make_scenes.py        # or: python -m assets.make_scenes
writes the demo scenes (Cornell box, vase room, a tree) into ``assets/scenes/`` and prints their paths.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: make the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.gltf_builder import (  # noqa: E402
    GltfBuilder,
    box,
    box_face,
    lathe,
    merged,
    quad,
    quat_axis_angle,
    rotation_matrix,
    transformed,
)

SCENES_DIR = Path(__file__).resolve().parent / "scenes"

WHITE = (0.73, 0.73, 0.73)
RED = (0.63, 0.065, 0.05)
GREEN = (0.14, 0.45, 0.091)

# Rotations (axis, degrees) taking a quad's +Y normal to each direction (for ``panel``).
FACING_ROTATION = {
    "+y": ((0, 1, 0), 0.0),
    "-y": ((1, 0, 0), 180.0),
    "+x": ((0, 0, 1), -90.0),
    "-x": ((0, 0, 1), 90.0),
    "+z": ((1, 0, 0), 90.0),
    "-z": ((1, 0, 0), -90.0),
}
# The same as node rotations (quaternions x, y, z, w).
_FACING = {k: quat_axis_angle(*v) for k, v in FACING_ROTATION.items()}


def panel(width: float, depth: float, facing: str, centre) -> tuple:
    """A quad of ``width`` x ``depth`` whose normal points along ``facing``, moved to ``centre``.

    The quad's x extent stays x for "+y"/"-y"/"+z"/"-z"; for "+x"/"-x" it becomes the vertical.
    """
    return transformed(quad(width, depth), rotation=rotation_matrix(*FACING_ROTATION[facing]), translation=centre)


# ---------------------------------------------------------------------- demo scenes


def cornell_box(size: float = 2.0) -> GltfBuilder:
    """A Cornell-box-like room seen from inside, ``size`` metres wide, deep and high (default 2 m).

    The original box is about 5.5 units (555 mm) across; this one is scaled to ``size`` metres.
    Floor at y = 0, walls at x = ±size/2 (red at -x, green at +x, as seen from the open front),
    back wall at z = -size/2, the front (+z) open. Each wall is a unit-normal quad mesh of its own,
    placed by its node's rotation and translation. A tall block (rotated -17° about +Y) stands near
    the red wall at the back, a short one (+17°) near the green wall at the front, each about a
    tenth of ``size`` from its coloured wall, so colour bleeds onto their sides and the floor.
    The light is a small emissive square (emissive 1, KHR_materials_emissive_strength 10, base
    colour 0.78) facing down, a millimetre below the ceiling. Blocks are closed boxes (their
    bottoms lie on the floor).
    """
    s = size / 2.0  # everything below is laid out for a 2 m box and scaled by s
    b = GltfBuilder()
    white = b.material("white", WHITE)
    red = b.material("red", RED)
    green = b.material("green", GREEN)
    light = b.material("light", (0.78, 0.78, 0.78), emissive=(1.0, 1.0, 1.0), emissive_strength=10.0)

    nodes = {}
    for name, mat, facing, centre in (
        ("floor", white, "+y", (0, 0, 0)),
        ("ceiling", white, "-y", (0, 2, 0)),
        ("back_wall", white, "+z", (0, 1, -1)),
        ("left_wall", red, "+x", (-1, 1, 0)),
        ("right_wall", green, "-x", (1, 1, 0)),
    ):
        mesh = b.shape_mesh(name, quad(size, size), material=mat)
        nodes[name] = b.node(name, mesh, rotation=_FACING[facing], translation=[c * s for c in centre])
    lamp = b.shape_mesh("light", quad(0.47 * s, 0.38 * s), material=light)
    nodes["light"] = b.node("light", lamp, rotation=_FACING["-y"], translation=(0.0, 2.0 * s - 0.001, 0.0))

    tall = b.shape_mesh("tall_block", box((0.6 * s, 1.2 * s, 0.6 * s)), material=white)
    nodes["tall_block"] = b.node(
        "tall_block", tall, rotation=quat_axis_angle((0, 1, 0), -17.0), translation=(-0.33 * s, 0.6 * s, -0.29 * s)
    )
    short = b.shape_mesh("short_block", box((0.6 * s, 0.6 * s, 0.6 * s)), material=white)
    nodes["short_block"] = b.node(
        "short_block", short, rotation=quat_axis_angle((0, 1, 0), 17.0), translation=(0.33 * s, 0.3 * s, 0.3 * s)
    )
    b.info.update(nodes=nodes, size=size)
    return b


def _vase_profile() -> np.ndarray:
    """(radius, y) of a thick-walled vase 0.355 m high: out and up the outside, down the inside."""
    outside = [(0.0, 0.0), (0.06, 0.0), (0.09, 0.05), (0.11, 0.12), (0.10, 0.20), (0.06, 0.27), (0.045, 0.31)]
    outside.append((0.055, 0.35))
    lip = [(0.05, 0.355)]
    inside = [(0.045, 0.35), (0.04, 0.30), (0.085, 0.20), (0.095, 0.12), (0.07, 0.05), (0.0, 0.03)]
    return np.array(outside + lip + inside)


def vase_room(size=(4.0, 3.0, 4.0), segments: int = 20) -> GltfBuilder:
    """A closed room with a table and a vase on it, echoing the obscurances paper's figures.

    ``size`` (x, y, z) metres; floor at y = 0, centred on the y axis. Light grey walls and ceiling
    (0.7), a wooden-brown floor (0.35, 0.2, 0.1), a table in the middle (top slab 1.2 x 0.05 x 0.8
    at 0.75 m, four legs sharing one mesh), a blue (0.1, 0.2, 0.6) thick-walled vase on the table
    (a lathe of ``segments`` sides, smooth normals, ~480 triangles at 20) and a window: an emissive
    quad (1.2 m wide, 1 m high, strength 5) a millimetre in front of the +x wall, facing -x.
    """
    sx, sy, sz = (float(v) for v in size)
    b = GltfBuilder()
    grey = b.material("wall", (0.7, 0.7, 0.7))
    brown = b.material("floor", (0.35, 0.2, 0.1))
    wood = b.material("table", (0.45, 0.3, 0.15))
    blue = b.material("vase", (0.1, 0.2, 0.6), roughness=0.4)
    window = b.material("window", (0.8, 0.8, 0.8), emissive=(1.0, 1.0, 1.0), emissive_strength=5.0)
    lift = (0.0, sy / 2.0, 0.0)

    nodes = {}
    floor_shape = transformed(box_face((sx, sy, sz), "-y", inward=True), translation=lift)
    floor = b.shape_mesh("floor", floor_shape, material=brown)
    nodes["floor"] = b.node("floor", floor)
    walls = merged(*(box_face((sx, sy, sz), f, inward=True) for f in ("+x", "-x", "+y", "+z", "-z")))
    nodes["walls"] = b.node("walls", b.shape_mesh("walls", transformed(walls, translation=lift), material=grey))

    top_h, top_t = 0.75, 0.05
    top = b.shape_mesh("table_top", box((1.2, top_t, 0.8)), material=wood)
    parts = [b.node("table_top", top, translation=(0.0, top_h - top_t / 2.0, 0.0))]
    leg_h = top_h - top_t
    leg = b.shape_mesh("table_leg", box((0.05, leg_h, 0.05)), material=wood)
    for i, (x, z) in enumerate(((-0.55, -0.35), (0.55, -0.35), (-0.55, 0.35), (0.55, 0.35))):
        parts.append(b.node(f"table_leg_{i}", leg, translation=(x, leg_h / 2.0, z)))
    nodes["table"] = b.node("table", children=parts)

    vase = b.shape_mesh("vase", lathe(_vase_profile(), segments), material=blue)
    nodes["vase"] = b.node("vase", vase, translation=(0.1, top_h, 0.05))

    pane = b.shape_mesh("window", quad(1.0, 1.2), material=window)  # x extent becomes the height
    nodes["window"] = b.node("window", pane, rotation=_FACING["-x"], translation=(sx / 2.0 - 0.001, 1.6, 0.0))
    b.info.update(nodes=nodes, size=(sx, sy, sz))
    return b


# ---------------------------------------------------------------------- test scenes


def open_plane(size: float = 1.0, albedo: float = 0.8) -> GltfBuilder:
    """A single ``size`` x ``size`` quad at y = 0 facing up (+Y), nothing else: W = R_ave, no occlusion."""
    b = GltfBuilder()
    mat = b.material("plane", (albedo,) * 3)
    b.info["nodes"] = {"plane": b.node("plane", b.shape_mesh("plane", quad(size, size), material=mat))}
    return b


def parallel_planes(
    height: float = 0.5,
    half_extent: float = 50.0,
    probe_size: float = 0.2,
    ceiling_albedo=(0.5, 0.5, 0.5),
    probe_albedo: float = 1.0,
) -> GltfBuilder:
    """A small probe quad at y = 0 facing up under a huge ceiling quad at y = ``height`` facing down.

    Probe: ``probe_size`` square, centred at the origin, white (``probe_albedo``). Ceiling: side
    ``2 * half_extent``, albedo ``ceiling_albedo``. Every probe ray hits the ceiling at distance
    ``height / cos θ`` (bar the few that slip past the ceiling's edge), the closed-form case of
    two infinite parallel planes. Geometry is in world space (identity nodes).
    """
    b = GltfBuilder()
    white = b.material("probe", (probe_albedo,) * 3)
    grey = b.material("ceiling", tuple(float(c) for c in ceiling_albedo))
    side = 2.0 * half_extent
    probe = b.shape_mesh("probe", quad(probe_size, probe_size), material=white)
    ceiling = b.shape_mesh("ceiling", panel(side, side, "-y", (0.0, height, 0.0)), material=grey)
    b.info["nodes"] = {"probe": b.node("probe", probe), "ceiling": b.node("ceiling", ceiling)}
    return b


def red_wall_floor(
    floor_size: float = 4.0,
    wall_height: float = 2.0,
    floor_albedo: float = 0.8,
    wall_albedo=(0.8, 0.05, 0.05),
) -> GltfBuilder:
    """A white floor quad (``floor_size`` square, y = 0, facing up) and a red wall on its -z edge.

    The wall spans the floor's width, stands from y = 0 to ``wall_height`` at z = -floor_size/2 and
    faces +z, over the floor: floor texels near it should turn red. World-space geometry.
    """
    b = GltfBuilder()
    white = b.material("floor", (floor_albedo,) * 3)
    red = b.material("red_wall", tuple(float(c) for c in wall_albedo))
    floor = b.shape_mesh("floor", quad(floor_size, floor_size), material=white)
    wall_shape = panel(floor_size, wall_height, "+z", (0.0, wall_height / 2.0, -floor_size / 2.0))
    wall = b.shape_mesh("red_wall", wall_shape, material=red)
    b.info["nodes"] = {"floor": b.node("floor", floor), "red_wall": b.node("red_wall", wall)}
    return b


def three_instances(
    box_size: float = 0.3,
    floor_size: float = 8.0,
    wall_height: float = 1.0,
    shelf_size: float = 1.0,
    shelf_gap: float = 0.05,
    corner_gap: float = 0.02,
) -> GltfBuilder:
    """A floor and one ``box_size`` cube mesh used by three nodes in different surroundings.

    Floor: ``floor_size`` square at y = 0. Two walls (height ``wall_height``) along its -x and -z
    edges form a corner; box "box_corner" stands ``corner_gap`` from both. "box_shelf" stands under
    a floating ``shelf_size`` square slab (0.05 m thick) whose underside is ``shelf_gap`` above the
    box top, at (+d, +d) with d = floor_size * 0.3125. "box_open" stands at (+d, -d/5), metres away
    from walls and shelf. So the three instances share a mesh but not their obscurances.
    ``info["boxes"]`` maps "open"/"corner"/"shelf" to node indices, ``info["box_mesh"]`` the mesh.
    """
    b = GltfBuilder()
    white = b.material("white", (0.8, 0.8, 0.8))
    h = floor_size / 2.0
    d = floor_size * 0.3125
    nodes = {"floor": b.node("floor", b.shape_mesh("floor", quad(floor_size, floor_size), material=white))}
    wall_x = panel(wall_height, floor_size, "+x", (-h, wall_height / 2.0, 0.0))
    wall_z = panel(floor_size, wall_height, "+z", (0.0, wall_height / 2.0, -h))
    nodes["wall_x"] = b.node("wall_x", b.shape_mesh("wall_x", wall_x, material=white))
    nodes["wall_z"] = b.node("wall_z", b.shape_mesh("wall_z", wall_z, material=white))
    slab_t = 0.05
    shelf = b.shape_mesh("shelf", box((shelf_size, slab_t, shelf_size)), material=white)
    nodes["shelf"] = b.node("shelf", shelf, translation=(d, box_size + shelf_gap + slab_t / 2.0, d))

    cube = b.shape_mesh("box", box((box_size,) * 3), material=white)
    r = box_size / 2.0
    boxes = {
        "open": b.node("box_open", cube, translation=(d, r, -d / 5.0)),
        "corner": b.node("box_corner", cube, translation=(-h + corner_gap + r, r, -h + corner_gap + r)),
        "shelf": b.node("box_shelf", cube, translation=(d, r, d)),
    }
    nodes.update({f"box_{k}": v for k, v in boxes.items()})
    b.info.update(nodes=nodes, boxes=boxes, box_mesh=cube)
    return b


def _up_triangle(p0, p1, p2) -> np.ndarray:
    """(3, 3) vertices of a triangle in a y = const plane, ordered counter-clockwise seen from +Y."""
    tri = np.array([p0, p1, p2], dtype=np.float64)
    e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
    if e1[2] * e2[0] - e1[0] * e2[2] < 0.0:  # y of cross(e1, e2)
        tri = tri[[0, 2, 1]]
    return tri


def slivers_and_tiny(
    texel_density: float = 32.0,
    floor_size: float = 2.0,
    height: float = 0.1,
    sliver_length: float = 0.5,
    aspect_ratios=(1e4, 1e5, 1e6),
    include_degenerate: bool = False,
) -> GltfBuilder:
    """A floor and a "debris" mesh of awkward triangles lying flat ``height`` above it, facing up.

    The debris mesh holds, each triangle with its own three vertices and normal +Y:
    - 4 normal triangles (legs 0.25 m);
    - slivers: for every ratio in ``aspect_ratios``, two isosceles triangles of base
      ``sliver_length`` and height ``sliver_length / ratio`` (one along x, one diagonal), so the
      aspect ratio (longest edge / height on it) is the ratio (before float32 rounding);
    - tiny triangles: 8 with legs a tenth and 8 with legs a hundredth of a texel at
      ``texel_density`` texels per metre, spread 5 cm apart so they fall in different texels;
    - with ``include_degenerate``: one collinear and one with all three vertices equal.
    ``info["triangles"]`` maps "normal", "sliver", "tiny", "degenerate" to index arrays into the
    debris mesh's triangles; ``info["sliver_aspect"]`` gives each sliver's ratio.
    """
    b = GltfBuilder()
    white = b.material("white", (0.8, 0.8, 0.8))
    grey = b.material("debris", (0.5, 0.5, 0.5))
    y = height
    tris: dict[str, list[np.ndarray]] = {"normal": [], "sliver": [], "tiny": [], "degenerate": []}
    for i in range(4):
        x0, z0 = -0.8 + 0.3 * (i % 2), -0.6 + 0.3 * (i // 2)
        tris["normal"].append(_up_triangle((x0, y, z0), (x0 + 0.25, y, z0), (x0, y, z0 + 0.25)))
    aspects = []
    for k, ratio in enumerate(aspect_ratios):
        h = sliver_length / ratio
        z0 = 0.1 + 0.15 * k
        tris["sliver"].append(
            _up_triangle((-0.2, y, z0), (-0.2 + sliver_length, y, z0), (-0.2 + sliver_length / 2.0, y, z0 + h))
        )
        u = np.array([1.0, 0.0, 1.0]) / np.sqrt(2.0)
        n = np.array([-1.0, 0.0, 1.0]) / np.sqrt(2.0)
        p0 = np.array([-0.9, y, 0.1 + 0.12 * k])
        tris["sliver"].append(_up_triangle(p0, p0 + sliver_length * u, p0 + sliver_length / 2.0 * u + h * n))
        aspects += [float(ratio)] * 2
    texel = 1.0 / texel_density
    for k, leg in enumerate((texel / 10.0, texel / 100.0)):
        for i in range(8):
            x0, z0 = 0.4 + 0.05 * (i % 4), -0.7 + 0.05 * (i // 4) + 0.15 * k
            tris["tiny"].append(_up_triangle((x0, y, z0), (x0 + leg, y, z0), (x0, y, z0 + leg)))
    if include_degenerate:
        tris["degenerate"].append(np.array([(0.5, y, 0.5), (0.6, y, 0.5), (0.7, y, 0.5)]))
        tris["degenerate"].append(np.array([(0.5, y, 0.6)] * 3))

    order = ("normal", "sliver", "tiny", "degenerate")
    corners = np.concatenate([np.array(tris[k]).reshape(-1, 3) for k in order if tris[k]])
    count = len(corners) // 3
    triangles = np.arange(3 * count, dtype=np.int64).reshape(-1, 3)
    normals = np.tile([0.0, 1.0, 0.0], (len(corners), 1))
    uv0 = corners[:, [0, 2]] / floor_size + 0.5
    ranges, start = {}, 0
    for k in order:
        ranges[k] = np.arange(start, start + len(tris[k]))
        start += len(tris[k])

    nodes = {"floor": b.node("floor", b.shape_mesh("floor", quad(floor_size, floor_size), material=white))}
    debris = b.mesh("debris", corners, triangles, normals=normals, uv0=uv0, material=grey)
    nodes["debris"] = b.node("debris", debris)
    b.info.update(nodes=nodes, triangles=ranges, sliver_aspect=np.array(aspects), texel_density=texel_density)
    return b


def checker(size: int = 64, squares: int = 8, colors=((230, 230, 230), (40, 60, 160))) -> np.ndarray:
    """(size, size, 3) uint8 sRGB checker of ``squares`` x ``squares``; the top-left square is colors[0]."""
    idx = (np.arange(size) * squares // size)
    parity = (idx[:, None] + idx[None, :]) % 2
    return np.asarray(colors, dtype=np.uint8)[parity]


def textured_floor(
    size: float = 2.0,
    wall_height: float = 1.0,
    image_size: int = 64,
    squares: int = 8,
    colors=((230, 230, 230), (40, 60, 160)),
    vertex_colors=((1.0, 1.0, 1.0), (1.0, 0.5, 0.5), (0.5, 1.0, 0.5), (0.5, 0.5, 1.0)),
) -> GltfBuilder:
    """A floor whose albedo is a checker texture times per-vertex COLOR_0, beside a white wall.

    Floor: ``size`` square at y = 0, facing up, base colour factor 1, base colour texture a
    ``squares`` x ``squares`` checker (``colors``, uint8 sRGB, ``image_size`` pixels square) over
    TEXCOORD_0 in [0, 1]², COLOR_0 the four linear ``vertex_colors`` at the quad's corners (in
    vertex order). Wall: white (0.8), on the -z edge, facing +z. ``info["image"]`` holds the
    checker pixels, ``info["vertex_colors"]`` the (4, 3) colours.
    """
    b = GltfBuilder()
    image = checker(image_size, squares, colors)
    tex = b.material("checker", (1.0, 1.0, 1.0), base_color_image=image)
    white = b.material("wall", (0.8, 0.8, 0.8))
    positions, triangles, normals, uv0 = quad(size, size)
    vc = np.asarray(vertex_colors, dtype=np.float64)
    floor = b.mesh("floor", positions, triangles, normals=normals, uv0=uv0, colors=vc, material=tex)
    wall = b.shape_mesh("wall", panel(size, wall_height, "+z", (0.0, wall_height / 2.0, -size / 2.0)), material=white)
    b.info.update(nodes={"floor": b.node("floor", floor), "wall": b.node("wall", wall)}, image=image, vertex_colors=vc)
    return b


def tree() -> GltfBuilder:
    """A tree of 400 alpha-cut leaf quads and 100 grass blades (``assets/foliage_scenes.py``):
    many small flat loose parts, which baker charts by projection (``baker/atlas/planar.py``)."""
    from assets.foliage_scenes import tree as foliage_tree

    return foliage_tree(leaf_count=400, grass_count=100)


DEMO_SCENES = {"cornell_box": cornell_box, "vase_room": vase_room, "tree": tree}


def main(out_dir: Path = SCENES_DIR) -> list[Path]:
    """Write the demo scenes as ``.glb`` into ``out_dir`` (default ``assets/scenes/``); print their paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, make in DEMO_SCENES.items():
        path = make().save(out_dir / f"{name}.glb")
        print(path)
        paths.append(path)
    return paths


if __name__ == "__main__":
    main()
