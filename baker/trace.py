"""The only module that talks to Embree (through embreex).

The scene is built once from every world triangle, recentred on the world's centre so that
float32 keeps its precision far from the origin; callers pass float64 world coordinates and get
float64 back. Embree releases the GIL while it traces, so the integrator runs several ``cast``
calls at once from a thread pool.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from .geometry import World


# Smallest ray offset, in texel sizes and in float32 units of the position's magnitude.
_OFFSET_TEXELS = 1e-3
_OFFSET_ULPS = 64 * 2.0 ** -23


def ray_lift(position: np.ndarray, size: np.ndarray, center: np.ndarray) -> np.ndarray:
    """How far (k,) to lift ray origins at ``position`` (k, 3) off their surface, world units.

    The larger of 10⁻³ of the texel's world size ``size`` (k,) and 64 float32 ulps of the
    position's distance from the tracer's ``center``: neither big texels nor scenes far from the
    origin self-intersect inside Embree's float32.
    """
    magnitude = np.abs(position - center).max(axis=1)
    return np.maximum(_OFFSET_TEXELS * size, _OFFSET_ULPS * np.maximum(magnitude, 1e-30))


@dataclass(frozen=True)
class Hits:
    """Nearest hits of n rays. triangle: (n,) int64 world triangle, -1 for a miss; distance:
    (n,) float64 along the (unit) direction, inf for a miss; u, v: (n,) float64 barycentric
    weights of the triangle's second and third corners at the hit."""

    triangle: np.ndarray
    distance: np.ndarray
    u: np.ndarray
    v: np.ndarray

    def barycentric(self) -> np.ndarray:
        """(n, 3) barycentric coordinates of the hit points (meaningless for misses)."""
        return np.stack([1.0 - self.u - self.v, self.u, self.v], axis=1)


class Tracer:
    """Casts rays against all of a ``World``'s triangles."""

    def __init__(self, world: World):
        self.center = world.center
        self.triangle_count = len(world.triangles)
        self._scene = rtcore_scene.EmbreeScene()
        if self.triangle_count:
            corners = world.positions[world.triangles] - self.center  # (T, 3, 3)
            TriangleMesh(self._scene, corners.astype(np.float32))
            # The first run commits the scene; do it here, not from several threads at once.
            self._scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32),
                            dists=np.zeros(1, np.float32))

    def cast(self, origins: np.ndarray, directions: np.ndarray, length: np.ndarray | float) -> Hits:
        """Nearest hit of each ray within ``length``.

        origins: (n, 3) float64 world; directions: (n, 3) unit; length: scalar or (n,) float64.
        """
        n = len(origins)
        if n == 0 or self.triangle_count == 0:
            return Hits(np.full(n, -1, np.int64), np.full(n, np.inf), np.zeros(n), np.zeros(n))
        local = (origins - self.center).astype(np.float32)
        dists = np.empty(n, np.float32)
        dists[:] = length
        result = self._scene.run(local, directions.astype(np.float32), dists=dists, output=1)
        triangle = result["primID"].astype(np.int64)
        hit = triangle >= 0
        distance = np.where(hit, result["tfar"].astype(np.float64), np.inf)
        return Hits(np.where(hit, triangle, -1), distance, result["u"].astype(np.float64),
                    result["v"].astype(np.float64))

    def cast_local(self, origins: np.ndarray, directions: np.ndarray,
                   lengths: np.ndarray) -> dict[str, np.ndarray]:
        """Nearest hits of rays already in the tracer's recentred float32 frame (hot path).

        origins: (n, 3) float32 world position − ``center``; directions: (n, 3) float32 unit;
        lengths: (n,) float32, overwritten. Returns embreex's arrays: ``primID`` (n,) int32 world
        triangle or −1, ``tfar`` (n,) float32 distance, ``u``/``v`` (n,) float32 barycentrics.
        """
        if self.triangle_count == 0:
            n = len(origins)
            return {"primID": np.full(n, -1, np.int32), "tfar": lengths,
                    "u": np.zeros(n, np.float32), "v": np.zeros(n, np.float32)}
        return self._scene.run(origins, directions, dists=lengths, output=1)

    def occluded(self, origins: np.ndarray, directions: np.ndarray,
                 length: np.ndarray | float) -> np.ndarray:
        """(n,) bool: whether anything lies along each ray within ``length`` (shadow rays)."""
        n = len(origins)
        if n == 0 or self.triangle_count == 0:
            return np.zeros(n, bool)
        local = (origins - self.center).astype(np.float32)
        dists = np.empty(n, np.float32)
        dists[:] = length
        result = self._scene.run(local, directions.astype(np.float32), dists=dists,
                                 query="OCCLUDED")
        return result >= 0
