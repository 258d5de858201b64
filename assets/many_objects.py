"""A many-object scene for the fixed cost of a bake: a room with ~200 boxes and a sphere.

``boxes_and_sphere()`` builds a closed 12 × 3 × 12 m room (inward box) whose floor holds
``count`` boxes on a jittered grid, each its own mesh (as exports of a level usually have them),
with every face split into ``cuts`` × ``cuts`` squares, and one UV sphere in the middle. With the
defaults that is 200 × 432 + 12,320 + 12 = 98,732 triangles in 202 meshes: what unwrapping,
rasterising and validity cost per triangle and per object shows here, where the Cornell room
(36 triangles) shows their cost per texel. ``instanced=True`` places the boxes as nodes of one
shared mesh instead (scaled per node), for the reuse of one unwrap across instances.
Lengths in metres, colours linear RGB; deterministic in ``seed``.

    python assets/many_objects.py   # writes assets/scenes/boxes_and_sphere.glb
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: make the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.gltf_builder import (  # noqa: E402
    GltfBuilder, Shape, box, cylinder, lathe, merged, quat_axis_angle, uv_sphere)

ROOM = (12.0, 3.0, 12.0)


def grid_face(size, axis: int, sign: float, cuts: int) -> Shape:
    """One face of a box of ``size`` (3,) centred at the origin, normal ``sign`` along ``axis``,
    split into ``cuts`` × ``cuts`` squares (2·cuts² triangles); flat normals, UVs over [0, 1]²."""
    half = np.asarray(size, np.float64) / 2
    normal = np.zeros(3)
    normal[axis] = sign
    u = np.zeros(3)
    u[(axis + 1) % 3] = 1.0
    v = np.cross(normal, u)
    s = np.linspace(-1.0, 1.0, cuts + 1)
    su, sv = np.meshgrid(s, s, indexing="ij")
    hu, hv = half[(axis + 1) % 3], half[(axis + 2) % 3]
    positions = (normal * half + su.reshape(-1, 1) * hu * u + sv.reshape(-1, 1) * hv * v)
    i, j = np.meshgrid(np.arange(cuts), np.arange(cuts), indexing="ij")
    a = (i * (cuts + 1) + j).reshape(-1)
    b, c, d = a + cuts + 1, a + cuts + 2, a + 1  # a → b along u, d along v: u × v = normal
    triangles = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)
    uv = np.stack([(su.reshape(-1) + 1) / 2, (1 - sv.reshape(-1)) / 2], axis=1)
    return positions, triangles, np.tile(normal, (len(positions), 1)), uv


def grid_box(size, cuts: int) -> Shape:
    """A closed box of ``size`` (3,) centred at the origin, each face ``grid_face`` of ``cuts``."""
    return merged(*(grid_face(size, axis, sign, cuts) for axis in range(3) for sign in (1.0, -1.0)))


def boxes_and_sphere(count: int = 200, cuts: int = 6, sphere_rings: int = 56,
                     instanced: bool = False, seed: int = 0) -> GltfBuilder:
    """The room, ``count`` floor-standing boxes (sides 0.25–0.6 m, turned at random) and a sphere
    of radius 0.8 m with ``sphere_rings`` rings and twice as many segments on the floor's middle.
    ``builder.info["nodes"]``: node name → index."""
    rng = np.random.default_rng(seed)
    b = GltfBuilder()
    wall = b.material("wall", (0.73, 0.73, 0.73))
    crate = b.material("crate", (0.55, 0.45, 0.3))
    ball = b.material("ball", (0.6, 0.6, 0.7))
    nodes = {"room": b.node("room", b.shape_mesh("room", box(ROOM, inward=True), material=wall),
                            translation=(0.0, ROOM[1] / 2, 0.0))}
    shared = b.shape_mesh("box", grid_box((1.0, 1.0, 1.0), cuts), material=crate) if instanced else None
    side = int(np.ceil(np.sqrt(count)))
    cell = np.array([ROOM[0], ROOM[2]]) * 0.9 / side
    for k in range(count):
        i, j = divmod(k, side)
        centre = (np.array([i, j]) + 0.5) * cell - np.array([ROOM[0], ROOM[2]]) * 0.45
        centre = centre + rng.uniform(-0.15, 0.15, 2) * cell
        if np.hypot(*centre) < 1.2:  # the sphere's place
            centre = centre * 1.2 / np.hypot(*centre) + np.sign(centre) * 0.4
        size = rng.uniform(0.25, 0.6, 3)
        turn = quat_axis_angle((0, 1, 0), float(rng.uniform(0, 90)))
        at = (float(centre[0]), float(size[1] / 2), float(centre[1]))
        if instanced:
            nodes[f"box{k}"] = b.node(f"box{k}", shared, translation=at, rotation=turn,
                                      scale=tuple(float(x) for x in size))
        else:
            mesh = b.shape_mesh(f"box{k}", grid_box(size, cuts), material=crate)
            nodes[f"box{k}"] = b.node(f"box{k}", mesh, translation=at, rotation=turn)
    sphere = b.shape_mesh("sphere", uv_sphere(0.8, sphere_rings, 2 * sphere_rings), material=ball)
    nodes["sphere"] = b.node("sphere", sphere, translation=(0.0, 0.8, 0.0))
    b.info["nodes"] = nodes
    return b


def main(out_dir: Path = Path(__file__).resolve().parent / "scenes") -> list[Path]:
    """Write the default scene as ``boxes_and_sphere.glb``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    return [boxes_and_sphere().save(out_dir / "boxes_and_sphere.glb")]


def strewn_props(count: int, seed: int = 0) -> GltfBuilder:
    """``count`` boxes, spheres and cylinders of random sizes (0.1–1 m), each its own mesh,
    strewn through a 10 m cube: many small charts, whose padding can spill the default
    density's atlas onto a second page (tests/test_default_pages.py)."""
    rng = np.random.default_rng(seed)
    builder = GltfBuilder()
    grey = builder.material("grey", base_color=(0.6, 0.6, 0.6))
    for k in range(count):
        size = rng.uniform(0.1, 1.0)
        shape = (box(rng.uniform(0.05, 1.0, 3)), uv_sphere(size, 6, 10),
                 cylinder(size, rng.uniform(0.1, 2.0), segments=8))[k % 3]
        builder.node(f"prop{k}", builder.shape_mesh(f"prop{k}", shape, material=grey),
                     translation=rng.uniform(-5.0, 5.0, 3))
    return builder


LEVEL_ROOM = (40.0, 6.0, 40.0)


def level(count: int = 400, seed: int = 0) -> GltfBuilder:
    """A level of ``count`` distinct meshes of about 2,500 triangles each (1,024,812 triangles
    for 400): crates (boxes of 15 × 15 squares a face, 2,700), turned columns (a lathed profile
    of 20 rings, 66 segments: 2,508), balls (spheres of 36 rings, 2,520) and rocks (the same
    spheres, their radius bumped by smooth noise: 2,520), in turns, on a jittered grid on the
    floor of a closed 40 × 6 × 40 m room, each its own mesh (sizes and bumps drawn per object),
    turned about the vertical at random: what a level's unwrap costs per distinct mesh.
    Deterministic in ``seed``."""
    rng = np.random.default_rng(seed)
    b = GltfBuilder()
    wall = b.material("wall", (0.73, 0.73, 0.73))
    props = [b.material(name, colour) for name, colour in (
        ("crate", (0.55, 0.45, 0.3)), ("stone", (0.5, 0.5, 0.48)), ("ball", (0.6, 0.6, 0.7)))]
    b.node("room", b.shape_mesh("room", box(LEVEL_ROOM, inward=True), material=wall),
           translation=(0.0, LEVEL_ROOM[1] / 2, 0.0))
    side = int(np.ceil(np.sqrt(count)))
    cell = LEVEL_ROOM[0] * 0.9 / side
    for k in range(count):
        i, j = divmod(k, side)
        x, z = (np.array([i, j]) + 0.5 + rng.uniform(-0.2, 0.2, 2)) * cell - LEVEL_ROOM[0] * 0.45
        size = rng.uniform(0.4, 1.4, 3)
        kind = k % 4
        if kind == 0:
            shape, material, height = grid_box(size, 15), props[0], size[1]
        elif kind == 1:
            t = np.linspace(0.0, 1.0, 20)
            radius = size[0] / 2 * (0.6 + 0.25 * np.sin(np.pi * t * rng.uniform(1, 3)) ** 2)
            shape = lathe(np.stack([radius, (t - 0.5) * 2 * size[1]], axis=1), 66)
            material, height = props[1], 2 * size[1]
        else:
            positions, triangles, normals, uv = uv_sphere(size[0] / 2, 36, 36)
            if kind == 3:
                phase = rng.uniform(0, 2 * np.pi, (3, 3))
                bump = sum(0.08 * np.sin(f * normals @ np.cos(phase[n]) + phase[n, 0])
                           for n, f in enumerate((3.0, 5.0, 7.0)))
                positions = positions * (1.0 + bump)[:, None]
            shape, material, height = (positions, triangles, normals, uv), props[1 + kind // 3], size[0]
        turn = quat_axis_angle((0, 1, 0), float(rng.uniform(0, 360)))
        b.node(f"prop{k}", b.shape_mesh(f"prop{k}", shape, material=material),
               translation=(float(x), float(height / 2), float(z)), rotation=turn)
    return b


if __name__ == "__main__":
    for path in main():
        print(path)
