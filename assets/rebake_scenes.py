"""Scenes for the incremental rebake: a room of boxes, and the same room after an edit.

``box_room(boxes, ...)`` builds a closed room (inward box) with a floor-standing box per entry of
``boxes`` (dicts: name, size (3,), at (x, z) on the floor, turn (degrees about +Y), colour key);
the tests and the benchmark edit the list (move, turn, drop or add a box), the colours or the lamp
and bake again. Every box is its own node over one shared unit-box mesh (scaled by the node), so
moving or turning it is a rigid change of one node. Lengths in metres, colours linear RGB.

    python assets/rebake_scenes.py   # writes assets/scenes/box_room_{before,after}.glb
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np

if __package__ in (None, ""):  # run as a script: make the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.gltf_builder import GltfBuilder, box, quat_axis_angle  # noqa: E402

COLOURS = {"wall": (0.73, 0.73, 0.73), "crate": (0.55, 0.45, 0.3), "accent": (0.63, 0.065, 0.05)}


def grid_boxes(count: int, room: tuple[float, float, float] = (6.0, 3.0, 6.0),
               size: float = 0.3, seed: int = 0) -> list[dict[str, Any]]:
    """``count`` boxes on a jittered grid over the floor, sides between 0.6 and 1.4 × ``size``,
    turned at random; box 0 has the "accent" colour. Deterministic in ``seed``."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(count)))
    cell = np.array([room[0], room[2]]) * 0.8 / side
    boxes = []
    for k in range(count):
        i, j = divmod(k, side)
        centre = (np.array([i, j]) + 0.5) * cell - np.array([room[0], room[2]]) * 0.4
        centre = centre + rng.uniform(-0.2, 0.2, 2) * cell
        s = size * rng.uniform(0.6, 1.4, 3)
        boxes.append({"name": f"box{k}", "size": tuple(float(v) for v in s),
                      "at": (float(centre[0]), float(centre[1])),
                      "turn": float(rng.uniform(0, 90)), "colour": "accent" if k == 0 else "crate"})
    return boxes


def box_room(boxes: list[dict[str, Any]], room: tuple[float, float, float] = (6.0, 3.0, 6.0),
             colours: dict[str, tuple[float, float, float]] | None = None,
             lamp: dict[str, Any] | None = None, roof: bool = True) -> GltfBuilder:
    """A closed room (floor at y = 0) with the given floor-standing boxes; open to the sky
    without its ceiling when not ``roof``.

    ``colours`` overrides ``COLOURS`` entries; ``lamp`` adds a point light node "lamp" with keys
    ``at`` (3,), ``intensity`` (candela), ``colour`` (3,), ``radius`` (extras.radius, metres).
    ``builder.info["nodes"]`` maps node names to indices.
    """
    palette = dict(COLOURS, **(colours or {}))
    b = GltfBuilder()
    materials = {name: b.material(name, colour) for name, colour in palette.items()}
    shape = box(room, inward=True) if roof else box(
        room, inward=True, faces=("-x", "+x", "-y", "-z", "+z"))
    walls = b.shape_mesh("room", shape, material=materials["wall"])
    nodes = {"room": b.node("room", walls, translation=(0.0, room[1] / 2, 0.0))}
    meshes: dict[str, int] = {}
    for spec in boxes:
        colour = spec.get("colour", "crate")
        if colour not in meshes:
            meshes[colour] = b.shape_mesh(f"unit box {colour}", box((1.0, 1.0, 1.0)),
                                          material=materials[colour])
        sx, sy, sz = spec["size"]
        x, z = spec["at"]
        nodes[spec["name"]] = b.node(spec["name"], meshes[colour], translation=(x, sy / 2, z),
                                     rotation=quat_axis_angle((0, 1, 0), spec.get("turn", 0.0)),
                                     scale=(sx, sy, sz))
    if lamp is not None:
        light = b.light("point", name="lamp", color=lamp.get("colour", (1.0, 1.0, 1.0)),
                        intensity=lamp.get("intensity", 5.0),
                        extras={"radius": lamp["radius"]} if lamp.get("radius") else None)
        nodes["lamp"] = b.node("lamp", translation=lamp.get("at", (0.0, room[1] - 0.3, 0.0)),
                               extensions={"KHR_lights_punctual": {"light": light}})
    b.info["nodes"] = nodes
    return b


def moved(boxes: list[dict[str, Any]], name: str, **changes: Any) -> list[dict[str, Any]]:
    """A copy of ``boxes`` with the box ``name``'s entries replaced by ``changes``."""
    return [dict(spec, **changes) if spec["name"] == name else dict(spec) for spec in boxes]


def main(out_dir: Path = Path(__file__).resolve().parent / "scenes") -> list[Path]:
    """Write a 50-box room before and after moving one box across it."""
    out_dir.mkdir(parents=True, exist_ok=True)
    boxes = grid_boxes(50)
    before = box_room(boxes).save(out_dir / "box_room_before.glb")
    after = box_room(moved(boxes, "box7", at=(1.9, -1.7))).save(out_dir / "box_room_after.glb")
    return [before, after]


if __name__ == "__main__":
    for path in main():
        print(path)
