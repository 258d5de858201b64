"""Small scenes with light sources, for the direct-light tests (KHR_lights_punctual, emitters).

Every function returns a ``GltfBuilder`` and records in ``builder.info`` what the tests need
(node indices, the light's placement, the geometry's dimensions). Metres, linear RGB. The floor
is always node 0, a horizontal quad at y = 0 whose normal points up (+Y).
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from assets.gltf_builder import GltfBuilder, box, quad, rotation_matrix, transformed

FLOOR_ALBEDO = (0.5, 0.5, 0.5)


def aim(direction: Sequence[float]) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) turning the node's −Z (where glTF lights shine) to ``direction``."""
    d = np.asarray(direction, np.float64)
    d = d / np.linalg.norm(d)
    minus_z = np.array([0.0, 0.0, -1.0])
    axis = np.cross(minus_z, d)
    s, c = np.linalg.norm(axis), float(minus_z @ d)
    if s < 1e-12:
        return (0.0, 0.0, 0.0, 1.0) if c > 0 else (1.0, 0.0, 0.0, 0.0)
    half = math.atan2(s, c) / 2
    axis = axis / s * math.sin(half)
    return (float(axis[0]), float(axis[1]), float(axis[2]), math.cos(half))


def _floor(b: GltfBuilder, width: float, depth: float, albedo: float | None = None) -> int:
    floor = b.material("floor", FLOOR_ALBEDO if albedo is None else (albedo,) * 3)
    return b.node("floor", b.shape_mesh("floor", quad(width, depth), material=floor))


def _add_light(b: GltfBuilder, kind: str, position: Sequence[float], direction: Sequence[float],
               **light: Any) -> int:
    index = b.light(kind, **light)
    node = b.node(f"{kind} light", translation=position, rotation=aim(direction),
                  extensions={"KHR_lights_punctual": {"light": index}})
    b.info["light_node"] = node
    return node


def lit_floor(kind: str, position: Sequence[float] = (0.0, 2.0, 0.0),
              direction: Sequence[float] = (0.0, -1.0, 0.0), size: float = 4.0,
              albedo: float | None = None, **light: Any) -> GltfBuilder:
    """A ``size``-metre square floor (grey ``albedo``, default 0.5) and one light of ``kind`` at
    ``position`` shining along ``direction``; ``light`` goes to ``GltfBuilder.light`` (intensity,
    color, range, cones, extras)."""
    b = GltfBuilder()
    b.info["floor"] = _floor(b, size, size, albedo)
    _add_light(b, kind, position, direction, **light)
    return b


def blocked_floor(blocker_height: float = 1.0, size: float = 2.0) -> GltfBuilder:
    """A floor under a straight-down directional light of 1 lux, and above it a quad twice the
    floor's size (node 1) that hides the light from every floor point."""
    b = GltfBuilder()
    b.info["floor"] = _floor(b, size, size)
    grey = b.material("blocker", (0.5, 0.5, 0.5))
    b.info["blocker"] = b.node("blocker", b.shape_mesh("blocker", quad(2 * size, 2 * size), material=grey),
                               translation=(0.0, blocker_height, 0.0))
    _add_light(b, "directional", (0.0, 5.0, 0.0), (0.0, -1.0, 0.0), intensity=1.0)
    return b


def penumbra(radius: float, light_height: float = 2.0, edge_height: float = 1.0,
             length: float = 2.0, width: float = 0.1) -> GltfBuilder:
    """A point light of 1 cd with sphere radius ``radius`` (extras.radius) at (0, H, 0) above a
    floor strip along x, and a large occluder at height ``edge_height`` covering x < 0.

    Across the strip the shadow edge is a penumbra centred on x = 0; a floor point at |x| beyond
    ``R·h / sqrt((H − h)² − R²)`` sees all of the sphere or none of it (``info["half_width"]``).
    """
    b = GltfBuilder()
    b.info["floor"] = _floor(b, length, width)
    grey = b.material("occluder", (0.5, 0.5, 0.5))
    b.info["occluder"] = b.node(
        "occluder", b.shape_mesh("occluder", quad(3.0, 3.0), material=grey),
        translation=(-1.5, edge_height, 0.0))
    _add_light(b, "point", (0.0, light_height, 0.0), (0.0, -1.0, 0.0), intensity=1.0,
               extras={"radius": radius})
    h, big_h = edge_height, light_height
    b.info["half_width"] = radius * h / math.sqrt((big_h - h) ** 2 - radius ** 2)
    return b


def emissive_square(side: float = 1.0, height: float = 0.5, radiance: float = 2.0,
                    floor: float = 0.04) -> GltfBuilder:
    """A square emitter of ``side`` metres facing down at ``height`` above a small ``floor``-metre
    floor patch centred below it (node 0); the emitter (node 1) has uniform radiance
    ``radiance`` (emissiveFactor 1 × KHR_materials_emissive_strength)."""
    b = GltfBuilder()
    b.info["floor"] = _floor(b, floor, floor)
    lamp = b.material("emitter", (0.8, 0.8, 0.8), emissive=(1.0, 1.0, 1.0),
                      emissive_strength=radiance)
    down = transformed(quad(side, side), rotation=rotation_matrix((1, 0, 0), 180.0))
    b.info["emitter"] = b.node("emitter", b.shape_mesh("emitter", down, material=lamp),
                               translation=(0.0, height, 0.0))
    b.info.update(side=side, height=height, radiance=radiance)
    return b


def open_floor(size: float = 2.0) -> GltfBuilder:
    """A floor alone (for the sky)."""
    b = GltfBuilder()
    b.info["floor"] = _floor(b, size, size)
    return b


def floor_under_box() -> GltfBuilder:
    """A 3 m floor with a 0.6 m box on it, for the sky (its shadow and the box's sides)."""
    b = GltfBuilder()
    grey = b.material("grey", (0.6, 0.6, 0.6))
    b.node("floor", b.shape_mesh("floor", box((3.0, 0.02, 3.0)), material=grey),
           translation=(0.0, -0.01, 0.0))
    b.node("box", b.shape_mesh("box", box((0.6, 0.6, 0.6)), material=grey),
           translation=(0.0, 0.3, 0.0))
    return b


def facing_walls(side: float = 1.0, gap: float = 4.0) -> GltfBuilder:
    """Two upright panels facing away from each other, +X (node ``east``) and −X (``west``),
    ``gap`` apart, so that neither sees the other (for an image sky's closed forms)."""
    b = GltfBuilder()
    grey = b.material("grey", FLOOR_ALBEDO)
    for name, degrees, x in (("east", -90.0, gap / 2), ("west", 90.0, -gap / 2)):
        wall = transformed(quad(side, side), rotation=rotation_matrix((0, 0, 1), degrees))
        b.info[name] = b.node(name, b.shape_mesh(name, wall, material=grey),
                              translation=(x, 0.0, 0.0))
    return b
