"""Seeded random rooms and random edits of them, for the rebake-equals-full-bake property.

``random_room(seed)`` draws a room spec (a dict: room size, open or closed, props, lights, sky)
and ``random_edit(spec, seed)`` a changed copy of it: a prop moved, turned, scaled or recoloured,
a light moved or recoloured, or several of these at once. ``build(spec)`` makes the glTF. Each
prop is its own node over a shared unit mesh per (shape, material), so a move or a turn is a
rigid change of one node, as an editor makes it. Materials: diffuse, alpha-cut (MASK), mirror,
clear glass, translucent (diffuse transmission) and emissive (a lamp panel). Lengths in metres.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from assets.gltf_builder import GltfBuilder, box, quad, quat_axis_angle, rotation_matrix, transformed

KINDS = ("diffuse", "diffuse", "diffuse", "alpha", "mirror", "glass", "translucent", "emissive")
EDITS = ("move", "turn", "scale", "recolour", "light", "several")


def _material(b: GltfBuilder, kind: str, colour) -> int:
    """A material of ``kind`` with base colour ``colour`` (3,)."""
    colour = tuple(float(c) for c in colour)
    if kind == "alpha":
        pixels = np.full((8, 8, 4), 255, np.uint8)
        pixels[::2, ::2, 3] = 0  # a checker of holes
        return b.material("alpha", colour, alpha_mode="MASK", alpha_cutoff=0.5,
                          double_sided=True, base_color_image=pixels)
    if kind == "mirror":
        return b.material("mirror", colour, metallic=1.0, roughness=0.0)
    if kind == "glass":
        return b.material("glass", (1.0, 1.0, 1.0), roughness=0.0, extensions={
            "KHR_materials_transmission": {"transmissionFactor": 1.0}})
    if kind == "translucent":
        return b.material("translucent", colour, extensions={
            "KHR_materials_diffuse_transmission": {"diffuseTransmissionFactor": 0.5}})
    if kind == "emissive":
        return b.material("emissive", colour, emissive=(4.0, 3.5, 3.0))
    return b.material(f"diffuse {colour}", colour)


def random_room(seed: int, crowd: int | None = None) -> dict[str, Any]:
    """A room spec drawn from ``seed``: 2–5 props on the floor (``crowd`` props instead, in a
    room grown to give each as much floor: a crowded level), 0–2 punctual lights (mostly 1
    or 2), maybe sky, and the bake's rays (8 or 16), texel density (3 or 5 a metre) and
    supersampling (2 in one room of ten: the rebake does not follow it yet, a full bake)."""
    rng = np.random.default_rng(seed)
    size = [float(rng.uniform(2.5, 4.0)), float(rng.uniform(2.0, 3.0)), float(rng.uniform(2.5, 4.0))]
    count = int(rng.integers(2, 6))
    if crowd is not None:
        count = crowd
        size[0], size[2] = (float(side * np.sqrt(crowd / 3.5)) for side in (size[0], size[2]))
    props = []
    for i in range(count):
        kind = str(rng.choice(KINDS))
        props.append({"name": f"prop{i}", "kind": kind,
                      "shape": "panel" if kind in ("alpha", "emissive") else "box",
                      "colour": [float(c) for c in rng.uniform(0.2, 0.9, 3)],
                      "size": [float(s) for s in rng.uniform(0.2, 0.7, 3)],
                      "at": [float(rng.uniform(-0.35, 0.35) * size[0]),
                             float(rng.uniform(-0.35, 0.35) * size[2])],
                      "lift": float(rng.uniform(0.0, 0.8)), "turn": float(rng.uniform(0, 90))})
    lights = []
    for i in range(int(rng.choice([0, 1, 1, 2, 2]))):
        kind = str(rng.choice(["point", "spot", "directional"]))
        lights.append({"name": f"light{i}", "kind": kind,
                       "at": [float(rng.uniform(-0.3, 0.3) * size[0]), size[1] - 0.3,
                              float(rng.uniform(-0.3, 0.3) * size[2])],
                       "colour": [float(c) for c in rng.uniform(0.5, 1.0, 3)],
                       "intensity": float(rng.uniform(2.0, 8.0)),
                       "radius": float(rng.choice([0.0, 0.1]))})
    return {"size": size, "open": bool(rng.random() < 0.4), "props": props, "lights": lights,
            "sky": bool(rng.random() < 0.5), "rays": int(rng.choice([8, 16])),
            "density": float(rng.choice([3.0, 5.0])),
            "supersample": 2 if rng.random() < 0.1 else 1}


def random_edit(spec: dict[str, Any], seed: int) -> tuple[str, dict[str, Any]]:
    """(what was done, the edited copy of ``spec``) drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    edited = copy.deepcopy(spec)
    what = str(rng.choice(EDITS))
    steps = [str(rng.choice(EDITS[:5])) for _ in range(int(rng.integers(2, 4)))] \
        if what == "several" else [what]
    for step in steps:
        _edit_once(edited, step, rng)
    return "+".join(steps), edited


def _edit_once(spec: dict[str, Any], step: str, rng: np.random.Generator) -> None:
    """Apply one ``step`` of ``EDITS`` to ``spec`` in place."""
    prop = spec["props"][int(rng.integers(len(spec["props"])))]
    if step == "move":
        prop["at"] = [float(prop["at"][0] + rng.uniform(-0.8, 0.8)),
                      float(prop["at"][1] + rng.uniform(-0.8, 0.8))]
        prop["lift"] = float(max(0.0, prop["lift"] + rng.uniform(-0.2, 0.2)))
    elif step == "turn":
        prop["turn"] = float(prop["turn"] + rng.uniform(10, 80))
    elif step == "scale":
        prop["size"] = [float(s * rng.uniform(0.7, 1.3)) for s in prop["size"]]
    elif step == "recolour":
        prop["colour"] = [float(c) for c in rng.uniform(0.2, 0.9, 3)]
    elif step == "light":
        if not spec["lights"]:
            spec["sky"] = not spec["sky"]
            return
        light = spec["lights"][int(rng.integers(len(spec["lights"])))]
        if rng.random() < 0.5:
            light["at"] = [float(light["at"][0] + rng.uniform(-0.5, 0.5)), light["at"][1],
                           float(light["at"][2] + rng.uniform(-0.5, 0.5))]
        else:
            light["colour"] = [float(c) for c in rng.uniform(0.5, 1.0, 3)]
            light["intensity"] = float(light["intensity"] * rng.uniform(0.5, 2.0))


def build(spec: dict[str, Any]) -> GltfBuilder:
    """The glTF of a room ``spec`` (``random_room``); info["nodes"]: node name → index."""
    b = GltfBuilder()
    w, h, d = spec["size"]
    walls = b.material("walls", (0.7, 0.7, 0.7))
    faces = ("-x", "+x", "-y", "-z", "+z") if spec["open"] else ("-x", "+x", "-y", "+y", "-z", "+z")
    nodes = {"room": b.node("room", b.shape_mesh("room", box((w, h, d), inward=True, faces=faces),
                                                 material=walls), translation=(0.0, h / 2, 0.0))}
    meshes: dict[tuple, int] = {}
    for prop in spec["props"]:
        key = (prop["shape"], prop["kind"], tuple(prop["colour"]))
        if key not in meshes:
            material = _material(b, prop["kind"], prop["colour"])
            shape = (box((1.0, 1.0, 1.0)) if prop["shape"] == "box" else
                     transformed(quad(1.0, 1.0), rotation=rotation_matrix((1, 0, 0), 180)))
            meshes[key] = b.shape_mesh(f"{prop['kind']} {len(meshes)}", shape, material=material)
        sx, sy, sz = prop["size"]
        y = prop["lift"] + (sy / 2 if prop["shape"] == "box" else 0.3)
        nodes[prop["name"]] = b.node(prop["name"], meshes[key],
                                     translation=(prop["at"][0], y, prop["at"][1]),
                                     rotation=quat_axis_angle((0, 1, 0), prop["turn"]),
                                     scale=(sx, sy if prop["shape"] == "box" else 1.0, sz))
    for spec_light in spec["lights"]:
        kind = spec_light["kind"]
        index = b.light(kind, name=spec_light["name"], color=spec_light["colour"],
                        intensity=spec_light["intensity"],
                        outer_cone=0.9 if kind == "spot" else None,
                        extras={"radius": spec_light["radius"]} if spec_light["radius"] else None)
        nodes[spec_light["name"]] = b.node(
            spec_light["name"], translation=spec_light["at"],
            rotation=quat_axis_angle((1, 0, 0), -90.0 if kind != "point" else 0.0),
            extensions={"KHR_lights_punctual": {"light": index}})
    b.info["nodes"] = nodes
    return b
