"""Small scenes with light sources, for the direct-light tests (KHR_lights_punctual, emitters).

Every function returns a ``GltfBuilder`` and records in ``builder.info`` what the tests need
(node indices, the light's placement, the geometry's dimensions). Metres, linear RGB. The floor
is always node 0, a horizontal quad at y = 0 whose normal points up (+Y).
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from assets.gltf_builder import GltfBuilder, box, box_face, quad, rotation_matrix, transformed

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


def bumped_normals(size: int = 256, bumps: int = 6, tilt_degrees: float = 30.0) -> np.ndarray:
    """(size, size, 3) uint8 tangent-space normals of a field of ``bumps``² round bumps and dips
    (height sin(2πk·u)·sin(2πk·v)), tilted up to about ``tilt_degrees`` both across u (+X of
    the normal) and up the image (+Y): glTF's encoding 0.5 + 0.5·n, row 0 at the image top."""
    u = (np.arange(size) + 0.5) / size
    slope = np.tan(np.radians(tilt_degrees))
    su, cu = np.sin(2 * np.pi * bumps * u), np.cos(2 * np.pi * bumps * u)
    dx = slope * cu[None, :] * su[:, None]  # ∂h/∂u, the image's x
    dy = -slope * su[None, :] * cu[:, None]  # ∂h/∂(−v): up the image
    n = np.stack([-dx, -dy, np.ones_like(dx)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return np.round(255.0 * (0.5 + 0.5 * n)).astype(np.uint8)


def normal_mapped_floor(kind: str = "point", size: float = 2.0, intensity: float = 4.0,
                        position: Sequence[float] = (1.2, 1.0, 0.3),
                        direction: Sequence[float] = (-0.6, -0.8, 0.0)) -> GltfBuilder:
    """A white floor (its UVs: u along +Z, the image's up along +X; TANGENT given) whose
    material has a bumpy normal map (``bumped_normals``), lit by one light (point at
    ``position``, or directional along ``direction``): what directional lightmaps are for."""
    b = GltfBuilder()
    white = b.material("bumped", (0.8, 0.8, 0.8), normal_image=bumped_normals())
    positions, triangles, normals, uv = box_face((size, 0.0, size), "+y")
    tangents = np.tile([0.0, 0.0, 1.0, 1.0], (len(positions), 1))
    b.info["floor"] = b.node("floor", b.mesh("floor", positions, triangles, normals=normals,
                                             uv0=uv, material=white, tangents=tangents))
    b.info["floor_size"] = size
    _add_light(b, kind, position, direction, intensity=intensity)
    return b


def window_room(size: float = 4.0, height: float = 2.5,
                window: tuple[float, float, float, float] = (-0.8, 0.8, 1.0, 2.2)) -> GltfBuilder:
    """A closed room (``size`` square, ``height`` high, walls seen from inside) with one window
    opening in its +X wall (z from window[0] to window[1], y from window[2] to window[3]) and the
    bumped floor of ``normal_mapped_floor``: with a sky, the floor is lit through the window.
    ``info["window"]`` holds the opening's corners (4, 3), counter-clockwise seen from inside."""
    b = GltfBuilder()
    grey = b.material("wall", (0.6, 0.6, 0.6))
    bumped = b.material("bumped", (0.8, 0.8, 0.8), normal_image=bumped_normals())
    half = size / 2
    positions, triangles, normals, uv = box_face((size, 0.0, size), "+y")
    tangents = np.tile([0.0, 0.0, 1.0, 1.0], (len(positions), 1))
    b.info["floor"] = b.node("floor", b.mesh("floor", positions, triangles, normals=normals,
                                             uv0=uv, material=bumped, tangents=tangents))
    shell = box((size, height, size), inward=True, faces=("-x", "+y", "+z", "-z"))
    b.node("walls", b.shape_mesh("walls", shell, material=grey), translation=(0.0, height / 2, 0.0))
    z0, z1, y0, y1 = window
    pieces = [(-half, z0, 0.0, height), (z1, half, 0.0, height), (z0, z1, 0.0, y0),
              (z0, z1, y1, height)]  # the +X wall around the opening, facing −X
    for k, (za, zb, ya, yb) in enumerate(pieces):
        corners = np.array([[half, ya, za], [half, ya, zb], [half, yb, zb], [half, yb, za]])
        b.node(f"window wall {k}", b.mesh(f"window wall {k}", corners,
                                          np.array([[0, 1, 2], [0, 2, 3]]),
                                          normals=np.tile([-1.0, 0.0, 0.0], (4, 1)),
                                          uv0=np.array([[0, 1], [1, 1], [1, 0], [0, 0]], float),
                                          material=grey))
    b.info["floor_size"] = size
    b.info["window"] = np.array([[half, y0, z0], [half, y0, z1], [half, y1, z1], [half, y1, z0]])
    return b
