"""Per-texel estimation of the obscurance with colour bleeding, equation (2) of the paper:

    W(P) = 1/π ∫_Ω R(Q) ρ(d(P, ω)) cosθ dω

With cosine-weighted directions (pdf cosθ / π) the estimator is the mean of R(Q)·ρ(d) over the
texel's rays. The terms are kept apart (DESIGN.md §2): ``w_hit`` is the hits' part (RGB) and
``escaped`` the fraction of rays that met nothing closer than d_max, so W = w_hit + escaped·R_ave
and a change of R_ave needs no new ray.

Work is split into chunks of texels run on a thread pool (Embree releases the GIL). Every texel's
rays depend only on its key and the seed (sampling.py), and every chunk writes only its own rows,
so the result is the same bytes for any chunk size, thread count or order.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .geometry import World
from .obscurance import RHO_KINDS, UNIT_REFLECTIVITY, rho
from .rasterise import Texels
from .sampling import TECHNIQUES, fill_cosine, fill_points, frame, jit
from .scene import Scene
from .settings import Resolved
from .surface import LUMINANCE, albedo, triangle_albedo
from .trace import Tracer

# Smallest ray offset, in texel sizes and in float32 units of the position's magnitude.
_OFFSET_TEXELS = 1e-3
_OFFSET_ULPS = 64 * 2.0 ** -23


@dataclass(frozen=True)
class Terms:
    """The estimated terms of N texels (rows in ``Texels`` order).

    w_hit: (N, 3) mean of R(Q)·ρ(d) over the rays that hit (zero rows for misses included).
    escaped: (N,) fraction of rays with no hit closer than d_max.
    hit_sq: (N,) mean over rays of the squared luminance of R(Q)·ρ(d) (0 for escaped rays),
    for the sample variance. rays: how many rays were cast in all.
    """

    w_hit: np.ndarray
    escaped: np.ndarray
    hit_sq: np.ndarray
    rays: int

    def obscurance(self, r_ave: np.ndarray) -> np.ndarray:
        """W (N, 3) for average reflectivity ``r_ave`` (3,)."""
        return self.w_hit + self.escaped[:, None] * r_ave

    def standard_error(self, r_ave: np.ndarray, rays: int) -> np.ndarray:
        """(N,) standard error of the luminance of W, from the rays' sample variance."""
        mean = self.obscurance(r_ave) @ LUMINANCE
        second = self.hit_sq + self.escaped * float(r_ave @ LUMINANCE) ** 2
        variance = np.maximum(second - mean * mean, 0.0) * rays / max(rays - 1, 1)
        return np.sqrt(variance / rays)


def ray_offsets(texels: Texels, rows: slice, center: np.ndarray) -> np.ndarray:
    """How far (k,) to lift each texel's ray origins off its surface, in world units.

    Scales with the texel's world size and with the float32 spacing at the position's distance
    from the tracer's centre, so neither big texels nor far-away scenes self-intersect.
    """
    magnitude = np.abs(texels.position[rows] - center).max(axis=1)
    return np.maximum(_OFFSET_TEXELS * texels.size[rows], _OFFSET_ULPS * np.maximum(magnitude, 1e-30))


@jit
def _to_world_kernel(rays, positions, normals, offsets, center, x, y, z, origins, directions):
    """Turn local cosine directions (x, y, z) (k·rays,) into Embree's float32 rays.

    Each texel's directions go into the frame of its normal; its origin (lifted off the surface
    by its offset, recentred on ``center``) is repeated for each of its rays.
    """
    for i in range(len(positions)):
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        f = frame(nx, ny, nz)
        ox = positions[i, 0] - center[0] + offsets[i] * nx
        oy = positions[i, 1] - center[1] + offsets[i] * ny
        oz = positions[i, 2] - center[2] + offsets[i] * nz
        for r in range(i * rays, (i + 1) * rays):
            origins[r, 0], origins[r, 1], origins[r, 2] = ox, oy, oz
            directions[r, 0] = x[r] * f[0] + y[r] * f[3] + z[r] * nx
            directions[r, 1] = x[r] * f[1] + y[r] * f[4] + z[r] * ny
            directions[r, 2] = x[r] * f[2] + y[r] * f[5] + z[r] * nz


def hemisphere_rays(texels: Texels, rows: slice, rays: int, seed: int, center: np.ndarray,
                    technique: str = "sobol") -> tuple[np.ndarray, np.ndarray]:
    """Cosine-distributed rays about each texel's front-face normal, ready for Embree.

    Returns origins and directions, each (k·rays, 3) float32 in the tracer's recentred frame
    (world − ``center``), texel-major (texel i's rays are rows i·rays … i·rays + rays − 1).
    Computed in float64 (points, then directions, in flat arrays that the compiler vectorises),
    rounded once at the end.
    """
    k = rows.stop - rows.start
    u, v = np.empty(k * rays), np.empty(k * rays)
    fill_points(TECHNIQUES.index(technique), np.uint64(seed), texels.key[rows], rays,
                np.uint64(0), u, v)
    x, y, z = np.empty(k * rays), np.empty(k * rays), np.empty(k * rays)
    fill_cosine(u, v, x, y, z)
    origins = np.empty((k * rays, 3), np.float32)
    directions = np.empty((k * rays, 3), np.float32)
    _to_world_kernel(rays, texels.position[rows], texels.geometric_normal[rows],
                     ray_offsets(texels, rows, center), center, x, y, z, origins, directions)
    return origins, directions


@jit
def _accumulate_kernel(rays, primitive, distance, d_max, rho_kind, table, varying, ray_albedo,
                       luminance, w_hit, escaped, hit_sq):
    """Per texel: mean of R(Q)·ρ(d) (RGB), the escaped fraction, mean squared luminance.

    primitive/distance: (k·rays,) Embree's primID (−1: no hit within d_max) and tfar.
    table/varying: ``surface.triangle_albedo``; ray_albedo (k·rays, 3): the albedo at each
    hit of a ``varying`` triangle (may be (0, 3) when the chunk hits none).
    """
    for i in range(len(escaped)):
        red = green = blue = square = 0.0
        missed = 0
        for s in range(rays):
            r = i * rays + s
            t = primitive[r]
            if t < 0:
                missed += 1
                continue
            weight = rho(rho_kind, distance[r] / d_max)
            if weight == 0.0:
                continue
            if varying[t]:
                cr, cg, cb = ray_albedo[r, 0], ray_albedo[r, 1], ray_albedo[r, 2]
            else:
                cr, cg, cb = table[t, 0], table[t, 1], table[t, 2]
            cr, cg, cb = cr * weight, cg * weight, cb * weight
            red += cr
            green += cg
            blue += cb
            lum = cr * luminance[0] + cg * luminance[1] + cb * luminance[2]
            square += lum * lum
        w_hit[i, 0], w_hit[i, 1], w_hit[i, 2] = red / rays, green / rays, blue / rays
        escaped[i] = missed / rays
        hit_sq[i] = square / rays


@dataclass(frozen=True)
class _Surfaces:
    """What the shading of obscurance hits needs, built once per bake."""

    scene: Scene
    world: World
    table: np.ndarray  # (T, 3) constant albedo per world triangle
    varying: np.ndarray  # (T,) bool: albedo varies over the triangle (texture, vertex colours)

    def varying_albedo(self, primitive: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(n, 3) albedo at the hits on varying triangles (other rows zero), or (0, 3) if none."""
        hit = primitive >= 0
        where = np.flatnonzero(hit)
        where = where[self.varying[primitive[where]]]
        if not len(where):
            return np.zeros((0, 3))
        out = np.zeros((len(primitive), 3))
        uu, vv = u[where].astype(np.float64), v[where].astype(np.float64)
        bary = np.stack([1.0 - uu - vv, uu, vv], axis=1)
        out[where] = albedo(self.scene, self.world, primitive[where].astype(np.int64), bary)
        return out


def _chunk_terms(surfaces: _Surfaces, tracer: Tracer, texels: Texels, rows: slice,
                 settings: Resolved) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """w_hit (k, 3), escaped (k,), hit_sq (k,) for the texels in ``rows``."""
    n = settings.rays
    origins, directions = hemisphere_rays(texels, rows, n, settings.seed, tracer.center,
                                          settings.sampling)
    hits = tracer.cast_local(origins, directions, np.full(len(origins), settings.d_max, np.float32))
    primitive = hits["primID"]
    kind = RHO_KINDS[settings.rho]
    if settings.rho in UNIT_REFLECTIVITY or not surfaces.varying.any():
        ray_albedo = np.zeros((0, 3))
    else:
        ray_albedo = surfaces.varying_albedo(primitive, hits["u"], hits["v"])
    varying = surfaces.varying if len(ray_albedo) else np.zeros_like(surfaces.varying)
    k = rows.stop - rows.start
    w_hit, escaped, hit_sq = np.empty((k, 3)), np.empty(k), np.empty(k)
    _accumulate_kernel(n, primitive, hits["tfar"], np.float32(settings.d_max), kind,
                       surfaces.table, varying, ray_albedo, LUMINANCE, w_hit, escaped, hit_sq)
    return w_hit, escaped, hit_sq


def integrate(scene: Scene, world: World, tracer: Tracer, texels: Texels, settings: Resolved,
              progress: Callable[[int], None] | None = None) -> Terms:
    """Estimate the obscurance terms of every texel, ``settings.rays`` rays each."""
    count = len(texels)
    table, varying = triangle_albedo(scene, world)
    surfaces = _Surfaces(scene, world, table, varying)
    w_hit = np.zeros((count, 3))
    escaped = np.zeros(count)
    hit_sq = np.zeros(count)
    chunks = [slice(start, min(start + settings.chunk_texels, count))
              for start in range(0, count, settings.chunk_texels)]

    def work(rows: slice) -> None:
        w_hit[rows], escaped[rows], hit_sq[rows] = _chunk_terms(
            surfaces, tracer, texels, rows, settings)
        if progress is not None:
            progress(rows.stop - rows.start)

    threads = settings.threads or cores()
    if threads == 1:
        for rows in chunks:
            work(rows)
    else:
        with ThreadPoolExecutor(threads) as pool:
            list(pool.map(work, chunks))
    return Terms(w_hit=w_hit, escaped=escaped, hit_sq=hit_sq, rays=count * settings.rays)


def cores() -> int:
    """Cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
