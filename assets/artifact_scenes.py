"""Scenes that provoke the lightmap artifacts of issue 8: leaks, dark rims, seams.

Every function returns a ``GltfBuilder`` (save it with ``.save("x.glb")``) and describes what it
built in ``builder.info`` for the tests. Metres, linear RGB.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: make the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.gltf_builder import (  # noqa: E402
    GltfBuilder, box, cylinder, icosphere, quad, quat_axis_angle, rotation_matrix, transformed,
    uv_sphere)
from assets.make_scenes import WHITE, panel  # noqa: E402


def leak_room(half: float = 1.5, height: float = 2.5, floor_size: float = 8.0,
              wall_thickness: float = 0.6, box_size=(0.8, 0.6, 0.8),
              box_centre=(0.5, 0.4)) -> GltfBuilder:
    """A closed room standing on a large floor that runs under its walls into the open.

    Floor: one ``floor_size``² quad at y = 0 facing up, centred on the origin. Room interior:
    x, z in [−half, half], y in [0, height]. Walls at z = ±half and x = +half are single-sided
    quads facing in (zero thickness, from y = −0.01 to height + 0.01, overlapping each other and
    the thick wall by 0.01 so the room is closed to rays). The wall at −x is a closed box ``wall_thickness`` thick
    (x in [−half − thickness, −half]) whose bottom face lies on the floor: the floor runs under
    it. Ceiling: a quad at y = height facing down. A closed box ``box_size`` stands on the floor
    inside, centred at (x, z) = ``box_centre``, its bottom face on the floor (coplanar).

    ``info``: nodes (name → index), half, height, wall_thickness, box_size, box_centre
    (x, y, z of the box's centre).
    """
    b = GltfBuilder()
    white = b.material("white", WHITE)
    e = 0.01  # overlap, so that no ray slips through a corner or an edge
    t = wall_thickness
    nodes = {}
    nodes["floor"] = b.node("floor", b.shape_mesh(
        "floor", quad(floor_size, floor_size), material=white))
    thin = {
        "wall_back": panel(2 * half + 2 * e, height + 2 * e, "+z", (0.0, height / 2, -half)),
        "wall_front": panel(2 * half + 2 * e, height + 2 * e, "-z", (0.0, height / 2, half)),
        "wall_right": panel(height + 2 * e, 2 * half + 2 * e, "-x", (half, height / 2, 0.0)),
        "ceiling": panel(2 * half + 2 * e, 2 * half + 2 * e, "-y", (0.0, height, 0.0)),
    }
    for name, shape in thin.items():
        nodes[name] = b.node(name, b.shape_mesh(name, shape, material=white))
    thick = box((t, height + 2 * e, 2 * half + 2 * e))  # its top clear of the thin walls' tops
    nodes["wall_left"] = b.node("wall_left", b.shape_mesh("wall_left", thick, material=white),
                                translation=(-half - t / 2, (height + 2 * e) / 2, 0.0))
    centre = (float(box_centre[0]), box_size[1] / 2, float(box_centre[1]))
    nodes["box"] = b.node("box", b.shape_mesh("box", box(box_size), material=white),
                          translation=centre)
    b.info.update(nodes=nodes, half=half, height=height, wall_thickness=t,
                  box_size=tuple(box_size), box_centre=centre, floor_size=floor_size)
    return b


def sphere_on_floor(radius: float = 0.5, rings: int = 12, segments: int = 24,
                    floor_size: float = 3.0) -> GltfBuilder:
    """A smooth UV sphere resting on a floor quad: the floor darkens the sphere's lower half, so
    its lightmap varies across every chart; xatlas cuts the sphere into several charts, whose
    borders are seams (one edge in 3D, two in the atlas).

    ``info``: nodes (sphere, floor), radius.
    """
    b = GltfBuilder()
    white = b.material("white", WHITE)
    nodes = {
        "floor": b.node("floor", b.shape_mesh("floor", quad(floor_size, floor_size),
                                              material=white)),
        "sphere": b.node("sphere", b.shape_mesh("sphere", uv_sphere(radius, rings, segments),
                                                material=white),
                         translation=(0.0, radius, 0.0)),
    }
    b.info.update(nodes=nodes, radius=radius)
    return b


def cylinder_on_floor(radius: float = 0.3, length: float = 1.4, segments: int = 24,
                      floor_size: float = 3.0) -> GltfBuilder:
    """A closed cylinder (smooth side, flat caps) lying on a floor quad, its axis along x: the
    floor darkens the side's lower part, so the lightmap varies around it; xatlas cuts the
    side into several charts (four at the defaults) whose borders run along the axis — seams,
    one edge in 3D and two in the atlas. The caps meet the side at a crease (not a seam).

    ``info``: nodes (cylinder, floor), radius, length.
    """
    b = GltfBuilder()
    white = b.material("white", WHITE)
    lying = quat_axis_angle((0, 0, 1), 90.0)
    nodes = {
        "floor": b.node("floor", b.shape_mesh("floor", quad(floor_size, floor_size),
                                              material=white)),
        "cylinder": b.node("cylinder", b.shape_mesh("cylinder", cylinder(radius, length, segments),
                                                    material=white),
                           translation=(0.0, radius, 0.0), rotation=lying),
    }
    b.info.update(nodes=nodes, radius=radius, length=length)
    return b


def tiled_floor(tile: float = 1.0, depth: float = 2.0, radius: float = 0.4) -> GltfBuilder:
    """Two floor tiles, separate nodes, ``tile`` × ``depth`` quads at y = 0 side by side along
    x, touching along the line x = 0 (one edge in 3D, one in each tile's own chart), and a
    smooth sphere of ``radius`` resting on the joint: its shadow and occlusion make the light
    vary across the joint. ``info``: nodes (tile_left, tile_right, sphere).
    """
    b = GltfBuilder()
    white = b.material("white", WHITE)
    nodes = {}
    for name, x in (("tile_left", -tile / 2), ("tile_right", tile / 2)):
        nodes[name] = b.node(name, b.shape_mesh(name, quad(tile, depth), material=white),
                             translation=(x, 0.0, 0.0))
    nodes["sphere"] = b.node("sphere", b.shape_mesh("sphere", uv_sphere(radius, 12, 24),
                                                    material=white),
                             translation=(0.0, radius, 0.0))
    b.info.update(nodes=nodes)
    return b


def lit_leak_room(kind: str = "directional", position=(0.0, 10.0, 0.0),
                  direction=(0.6, -1.0, 0.3), intensity: float = 1000.0, **room) -> GltfBuilder:
    """``leak_room`` (keyword arguments ``room``) under one bright KHR_lights_punctual light of
    ``kind`` placed outside the room at ``position``, shining along ``direction`` (a
    directional light's position does not matter). ``info`` adds light_node and light
    (kind, position, direction, intensity)."""
    from assets.light_scenes import _add_light

    b = leak_room(**room)
    _add_light(b, kind, position, direction, intensity=intensity)
    b.info["light"] = dict(kind=kind, position=tuple(position), direction=tuple(direction),
                           intensity=intensity)
    return b


def shadow_edge(angle: float = 17.0, height: float = 0.5, size: float = 2.0) -> GltfBuilder:
    """A ``size``-metre floor (node 0, y = 0, facing up) under a hard directional light of 1 lux
    shining straight down, and above it at ``height`` a large occluder whose straight edge
    passes over the origin at ``angle`` degrees to the z axis, so that its hard shadow edge
    crosses the floor's texel rows at a slant.

    A floor point (x, z) is lit where ``x·cos(angle) − z·sin(angle) < 0`` (``info["lit"]``
    takes points (n, 3) and returns that as (n,) bool). ``info``: floor, occluder, angle.
    """
    from assets.light_scenes import _add_light

    b = GltfBuilder()
    white = b.material("white", WHITE)
    floor = b.node("floor", b.shape_mesh("floor", quad(size, size), material=white))
    rotation = rotation_matrix((0, 1, 0), angle)
    blocker = transformed(transformed(quad(3 * size, 3 * size), translation=(1.5 * size, 0.0, 0.0)),
                          rotation=rotation, translation=(0.0, height, 0.0))
    occluder = b.node("occluder", b.shape_mesh("occluder", blocker, material=white))
    _add_light(b, "directional", (0.0, 5.0, 0.0), (0.0, -1.0, 0.0), intensity=1.0)
    edge_normal = rotation @ np.array([1.0, 0.0, 0.0])  # the occluder lies on this side

    def lit(points: np.ndarray) -> np.ndarray:
        return points @ edge_normal < 0

    b.info.update(floor=floor, occluder=occluder, angle=angle, lit=lit)
    return b


def obscurance_edge(angle: float = 17.0, gap: float = 0.01, thickness: float = 0.05,
                    size: float = 2.0) -> GltfBuilder:
    """A ``size``-metre floor (y = 0, facing up) and, ``gap`` metres above it, a closed slab
    ``thickness`` thick covering half of it: the slab's straight edge passes over the origin at
    ``angle`` degrees to the z axis, so the sharp step in obscurance under its edge (dark
    beneath, open beside, over a width of about ``gap``) crosses the floor's texel rows at a
    slant. No light: the lightmap is the obscurance.

    A floor point (x, z) is under the slab where ``x·cos(angle) − z·sin(angle) > 0``
    (``info["under"]`` takes points (n, 3) and returns that as (n,) bool). ``info``: floor,
    slab, angle, gap.
    """
    b = GltfBuilder()
    white = b.material("white", WHITE)
    floor = b.node("floor", b.shape_mesh("floor", quad(size, size), material=white))
    rotation = rotation_matrix((0, 1, 0), angle)
    slab = transformed(transformed(box((3 * size, thickness, 3 * size)),
                                   translation=(1.5 * size, 0.0, 0.0)),
                       rotation=rotation, translation=(0.0, gap + thickness / 2, 0.0))
    occluder = b.node("slab", b.shape_mesh("slab", slab, material=white))
    edge_normal = rotation @ np.array([1.0, 0.0, 0.0])  # the slab lies on this side

    def under(points: np.ndarray) -> np.ndarray:
        return points @ edge_normal > 0

    b.info.update(floor=floor, slab=occluder, angle=angle, gap=gap, under=under)
    return b


def low_poly_sphere(radius: float = 0.5, rings: int = 8, segments: int = 12,
                    elevation: float = 0.0, azimuth: float = 17.0) -> GltfBuilder:
    """A smooth-shaded low-poly UV sphere (node 0, centred at the origin, ``rings`` × ``segments``
    facets, normals of the true sphere) lit by a hard directional light of 1 lux from +x turned
    ``azimuth`` degrees about +y and raised ``elevation`` degrees: the light's terminator runs
    across facets that face a little away from it (the worst case for faceting). Nothing else in the scene. ``info``: sphere,
    radius, rings, segments, light_direction (towards the light)."""
    from assets.light_scenes import _add_light

    b = GltfBuilder()
    white = b.material("white", WHITE)
    sphere = b.node("sphere", b.shape_mesh("sphere", uv_sphere(radius, rings, segments),
                                           material=white))
    e, a = math.radians(elevation), math.radians(azimuth)
    towards = (math.cos(e) * math.cos(a), math.sin(e), -math.cos(e) * math.sin(a))
    _add_light(b, "directional", (5.0, 0.0, 0.0), tuple(-c for c in towards), intensity=1.0)
    b.info.update(sphere=sphere, radius=radius, rings=rings, segments=segments,
                  light_direction=towards)
    return b


def icosphere_on_floor(radius: float = 0.5, subdivisions: int = 1, floor_size: float = 4.0,
                       gap: float = 0.0) -> GltfBuilder:
    """An 80-face (``subdivisions`` = 1) smooth-shaded geodesic sphere ``gap`` above a floor quad
    (0: resting on its lowest vertex), no light (I_A = 1, the lightmap is W): the floor darkens
    the sphere's lower half, so an obscurance hemisphere that tilts from facet to facet steps
    at every edge (issue 21, the lamp's base). ``info``: nodes (sphere, floor), radius, centre."""
    b = GltfBuilder()
    white = b.material("white", WHITE)
    centre = (0.0, radius + gap, 0.0)
    nodes = {
        "floor": b.node("floor", b.shape_mesh("floor", quad(floor_size, floor_size),
                                              material=white)),
        "sphere": b.node("sphere", b.shape_mesh("sphere", icosphere(radius, subdivisions),
                                                material=white), translation=centre),
    }
    b.info.update(nodes=nodes, radius=radius, centre=centre)
    return b


def panels_on_floor(floor_size: float = 6.0, light=(0.0, 1.5, 1.2)) -> GltfBuilder:
    """Single-sided panels standing on a floor in the open, the floor's texels on both sides of
    them: an opaque wall and a clear glass pane (each 2 × 1.2 m, facing +z, in the plane
    z = 0.02 on either side of x = 0), a card (0.8 × 0.5 m, facing −z, at z = −1.52) and an
    alpha-cut fence (vertical bars, 1.6 × 0.8 m, facing +x, at x = 2.02), all from y = 0 up,
    and a hard point light of 1 cd at ``light``: in front of the wall and the pane, behind
    the card and the fence. Floor: a ``floor_size``² quad at y = 0 facing up.

    ``info``: nodes (name → index) and panels: name → dict(kind ("opaque", "glass" or
    "fence"), centre (3,), normal (3,) the front, axes ((3,), (3,)) unit in-plane directions
    and half (2,) the half extents along them), light (3,)."""
    from assets.light_scenes import _add_light

    b = GltfBuilder()
    white = b.material("white", WHITE)
    grey = b.material("grey", (0.5, 0.5, 0.5))
    glass = b.material("glass", (1.0, 1.0, 1.0), roughness=0.0, extensions={
        "KHR_materials_transmission": {"transmissionFactor": 1.0}})
    bars = np.full((8, 8, 4), 255, np.uint8)
    bars[:, 1::2, 3] = 0  # every other column of texels clear: vertical bars
    fence = b.material("fence", (0.5, 0.4, 0.3), alpha_mode="MASK", alpha_cutoff=0.5,
                       base_color_image=bars)
    nodes = {"floor": b.node("floor", b.shape_mesh("floor", quad(floor_size, floor_size),
                                                   material=white))}
    x, y, z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
    panels = {  # name: (kind, material, width, height, facing, centre, normal, axes)
        "wall": ("opaque", grey, 2.0, 1.2, "+z", (-1.6, 0.6, 0.02), z, (x, y)),
        "pane": ("glass", glass, 2.0, 1.2, "+z", (1.6, 0.6, 0.02), z, (x, y)),
        "card": ("opaque", grey, 0.8, 0.5, "-z", (0.0, 0.25, -1.52), (0.0, 0.0, -1.0), (x, y)),
        "fence": ("fence", fence, 0.8, 1.6, "+x", (2.02, 0.4, -1.8), x, (y, z)),
    }
    info = {}
    for name, (kind, material, width, height, facing, centre, normal, axes) in panels.items():
        # (for "+x", make_scenes.panel turns the quad's width upright: axes (y, z))
        shape = panel(width, height, facing, centre)
        nodes[name] = b.node(name, b.shape_mesh(name, shape, material=material))
        info[name] = dict(kind=kind, centre=centre, normal=normal, axes=axes,
                          half=(width / 2, height / 2))
    _add_light(b, "point", light, (0.0, -1.0, 0.0), intensity=1.0)
    b.info.update(nodes=nodes, panels=info, light=tuple(light))
    return b


def main(out_dir: Path) -> list[Path]:
    """Write the scenes into ``out_dir``; return their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    return [leak_room().save(out_dir / "leak_room.glb"),
            sphere_on_floor().save(out_dir / "sphere_on_floor.glb"),
            cylinder_on_floor().save(out_dir / "cylinder_on_floor.glb")]


if __name__ == "__main__":
    for path in main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("scenes")):
        print(path)
