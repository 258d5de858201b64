"""Scenes that provoke the lightmap artifacts of issue 8: leaks, dark rims, seams.

Every function returns a ``GltfBuilder`` (save it with ``.save("x.glb")``) and describes what it
built in ``builder.info`` for the tests. Metres, linear RGB.
"""

from __future__ import annotations

import sys
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.gltf_builder import GltfBuilder, box, quad, uv_sphere  # noqa: E402
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


def main(out_dir: Path) -> list[Path]:
    """Write the scenes into ``out_dir``; return their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    return [leak_room().save(out_dir / "leak_room.glb"),
            sphere_on_floor().save(out_dir / "sphere_on_floor.glb")]


if __name__ == "__main__":
    for path in main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("scenes")):
        print(path)
