"""Extreme and stiff scenes for the numerics tests (issue 7, docs/design.md §7).

Each function returns a ``GltfBuilder`` (assets/gltf_builder.py); tests save and bake it.
"""

from __future__ import annotations

import numpy as np

from assets.gltf_builder import GltfBuilder, box, quad


def closed_room(scale: float = 1.0, offset=(0.0, 0.0, 0.0), albedo: float = 0.5,
                emission: float = 0.0) -> GltfBuilder:
    """A closed box room of side 2·``scale`` seen from inside, centred at ``offset`` (world units),
    walls of one grey ``albedo``; ``emission`` > 0 makes the walls glow uniformly."""
    b = GltfBuilder()
    wall = b.material("wall", (albedo,) * 3, emissive=(min(emission, 1.0),) * 3,
                      emissive_strength=max(emission, 1.0) if emission > 1.0 else None)
    shape = box((2.0 * scale,) * 3, inward=True)
    b.node("room", b.shape_mesh("room", shape, material=wall), translation=tuple(offset))
    return b


def single_triangle(size: float = 1.0) -> GltfBuilder:
    """One triangle of legs ``size`` facing up, nothing else."""
    b = GltfBuilder()
    positions = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -size], [size, 0.0, 0.0]])
    b.node("tri", b.mesh("tri", positions, np.array([[0, 2, 1]]), material=b.material("w")))
    return b


def panel_over_floor(scale=(1.0, 1.0, 1.0), depth: int = 0, mirrored: bool = False) -> GltfBuilder:
    """A 2 m floor under a 0.6 m square panel 0.3 m above it, facing down (world units).

    The panel's node carries ``scale`` (non-uniform and negative allowed: the mesh is divided by
    it, so the world panel is the same) and hangs under ``depth`` (even) nested parent nodes
    whose transforms compose to the identity (``_nested``).
    ``mirrored``: the panel's mesh is mirrored in x and its node scales x by −1 (winding flips).
    Every variant puts the same panel at the same place, so the floor's lightmap is the same.
    """
    b = GltfBuilder()
    white = b.material("floor", (0.8, 0.8, 0.8))
    grey = b.material("panel", (0.4, 0.4, 0.4))
    b.node("floor", b.shape_mesh("floor", quad(2.0, 2.0), material=white))
    s = np.asarray(scale, np.float64) * ([-1.0, 1.0, 1.0] if mirrored else 1.0)
    positions, triangles, normals, uv0 = quad(0.6, 0.6)
    triangles = triangles[:, [0, 2, 1]]  # facing down
    panel = b.mesh("panel", positions / s, triangles if np.prod(np.sign(s)) > 0 else triangles[:, [0, 2, 1]],
                   normals=-normals * np.sign(s), uv0=uv0, material=grey)
    node = b.node("panel", panel, translation=(0.0, 0.3, 0.0), scale=tuple(s))
    for level in range(depth):
        node = _nested(b, level, depth, node)
    return b


def _nested(b: GltfBuilder, level: int, depth: int, child: int) -> int:
    """A parent for ``child`` whose transform, composed over all ``depth`` levels, is the
    identity: it turns 360/depth degrees about y, and scales by 2 on even levels and ½ on odd
    ones (``depth`` even). Rotations about y and uniform scales commute, so the product is
    R(360°)·2^(k)·2^(−k) = I up to rounding."""
    angle = np.radians(360.0 / depth)
    rotation = (0.0, float(np.sin(angle / 2)), 0.0, float(np.cos(angle / 2)))
    factor = 2.0 if level % 2 == 0 else 0.5
    return b.node(f"level_{level}", rotation=rotation, scale=(factor,) * 3, children=[child])


def defect_panels() -> GltfBuilder:
    """Seven 0.5 m panels side by side in the plane y = 0, all facing up (+y winding), each with
    one defect exporters produce: "clean"; "duplicate_vertices" (every triangle its own three
    vertices); "zero_area" (plus collinear and single-point triangles); "inverted_normals"
    (NORMAL points down); "degenerate_normals" (NORMAL (0, 0, 0)); "missing_normals" (no
    NORMAL); "coincident" (two copies of the panel in the same place, z-fighting).
    Coplanar panels facing up cannot see one another: every ray of every texel escapes, so
    W = R_ave exactly whatever the defect. ``info["nodes"]`` maps each defect to its node.
    """
    b = GltfBuilder()
    grey = b.material("grey", (0.5, 0.5, 0.5))
    positions, triangles, normals, uv0 = quad(0.5, 0.5)
    nodes = {}

    def add(name, pos, tri, nrm, uv, x):
        nodes[name] = b.node(name, b.mesh(name, pos, tri, normals=nrm, uv0=uv, material=grey),
                             translation=(x, 0.0, 0.0))

    split = triangles.reshape(-1)
    cases = {
        "clean": (positions, triangles, normals, uv0),
        "duplicate_vertices": (positions[split], np.arange(len(split)).reshape(-1, 3),
                               normals[split], uv0[split]),
        "zero_area": (np.vstack([positions, [[0.1, 0, 0.1], [0.2, 0, 0.1], [0.3, 0, 0.1]]]),
                      np.vstack([triangles, [[4, 5, 6], [4, 4, 4], [5, 5, 6]]]),
                      np.vstack([normals, np.tile([0.0, 1.0, 0.0], (3, 1))]),
                      np.vstack([uv0, np.zeros((3, 2))])),
        "inverted_normals": (positions, triangles, -normals, uv0),
        "degenerate_normals": (positions, triangles, np.zeros_like(normals), uv0),
        "missing_normals": (positions, triangles, None, uv0),
        "coincident": (np.vstack([positions, positions]),
                       np.vstack([triangles, triangles + len(positions)]),
                       np.vstack([normals, normals]), np.vstack([uv0, uv0])),
    }
    for k, (name, case) in enumerate(cases.items()):
        add(name, *case, x=0.6 * k)
    b.info.update(nodes=nodes)
    return b


def non_manifold_fin() -> GltfBuilder:
    """Three 0.5 m panels sharing one edge (non-manifold: three faces on the edge along z at the
    origin): two lying flat facing up, on the +x and −x sides, and a fin standing on the edge,
    facing +x. The fin shades both flat panels near the edge; far from it they see open sky."""
    b = GltfBuilder()
    grey = b.material("grey", (0.5, 0.5, 0.5))
    h = 0.25
    positions = np.array([[0, 0, -h], [0, 0, h], [0.5, 0, h], [0.5, 0, -h],  # flat, +x side
                          [-0.5, 0, h], [-0.5, 0, -h],  # flat, −x side
                          [0, 0.5, h], [0, 0.5, -h]], np.float64)  # standing fin
    triangles = np.array([[0, 1, 2], [0, 2, 3],  # +x flat (up)
                          [5, 4, 1], [5, 1, 0],  # −x flat (up)
                          [0, 7, 6], [0, 6, 1]])  # fin (faces +x)
    b.node("fin", b.mesh("fin", positions, triangles, material=grey))
    return b


def instanced_boxes(count: int = 10_000, spacing: float = 2.0) -> GltfBuilder:
    """One 0.2 m box mesh placed by ``count`` nodes on a square grid ``spacing`` apart, on no
    floor: every instance sees the same empty world around it (d_max below the spacing)."""
    b = GltfBuilder()
    cube = b.shape_mesh("box", box((0.2, 0.2, 0.2)), material=b.material("grey", (0.5,) * 3))
    side = int(np.ceil(np.sqrt(count)))
    for i in range(count):
        b.node(f"box_{i}", cube, translation=(spacing * (i % side), 0.0, spacing * (i // side)))
    return b


def l_strip(length: float, width: float) -> GltfBuilder:
    """One L-shaped flat mesh facing up: two strips ``length`` × ``width`` (world units) joined
    at a right angle in one chart. Its texels are few (2·length·width·density²) but no packing
    fits it in less than a ``length``-square page: the sparse way to fill a page of 8192²."""
    b = GltfBuilder()
    xz = np.array([[0, 0], [0, length], [width, length], [width, width], [length, width],
                   [length, 0]], np.float64)
    positions = np.column_stack([xz[:, 0], np.zeros(len(xz)), xz[:, 1]])
    triangles = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]])
    normals = np.tile([0.0, 1.0, 0.0], (len(xz), 1))
    b.node("l_strip", b.mesh("l_strip", positions, triangles, normals=normals,
                             material=b.material("grey", (0.5, 0.5, 0.5))))
    return b
