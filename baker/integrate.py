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
from .obscurance import RHO, UNIT_REFLECTIVITY
from .rasterise import Texels
from .sampling import cosine_hemisphere, sample_2d, tangent_frames
from .scene import Scene
from .settings import Resolved
from .surface import LUMINANCE, albedo
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


def hemisphere_rays(texels: Texels, rows: slice, rays: int, seed: int,
                    center: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cosine-distributed rays about each texel's front-face normal.

    Returns origins and directions, each (k·rays, 3) float64, texel-major (texel i's rays are
    rows i·rays … i·rays + rays − 1).
    """
    keys = texels.key[rows]
    local = cosine_hemisphere(sample_2d(seed, keys[:, None], np.arange(rays)[None, :], 0))
    normal = texels.geometric_normal[rows]
    t1, t2 = tangent_frames(normal)
    directions = (local[..., :1] * t1[:, None] + local[..., 1:2] * t2[:, None]
                  + local[..., 2:] * normal[:, None]).reshape(-1, 3)
    lift = ray_offsets(texels, rows, center)[:, None] * normal
    origins = np.repeat(texels.position[rows] + lift, rays, axis=0)
    return origins, directions


def _chunk_terms(scene: Scene, world: World, tracer: Tracer, texels: Texels, rows: slice,
                 settings: Resolved) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """w_hit (k, 3), escaped (k,), hit_sq (k,) for the texels in ``rows``."""
    n = settings.rays
    origins, directions = hemisphere_rays(texels, rows, n, settings.seed, tracer.center)
    hits = tracer.cast(origins, directions, settings.d_max)
    hit = hits.triangle >= 0
    value = np.zeros((len(origins), 3))
    if settings.rho not in UNIT_REFLECTIVITY and hit.any():
        reflectivity = albedo(scene, world, hits.triangle[hit], hits.barycentric()[hit])
        rho = RHO[settings.rho](np.clip(hits.distance[hit] / settings.d_max, 0.0, 1.0))
        value[hit] = reflectivity * rho[:, None]
    k = len(origins) // n
    w_hit = value.reshape(k, n, 3).mean(axis=1)
    escaped = (~hit).reshape(k, n).mean(axis=1)
    hit_sq = ((value @ LUMINANCE) ** 2).reshape(k, n).mean(axis=1)
    return w_hit, escaped, hit_sq


def integrate(scene: Scene, world: World, tracer: Tracer, texels: Texels, settings: Resolved,
              progress: Callable[[int], None] | None = None) -> Terms:
    """Estimate the obscurance terms of every texel, ``settings.rays`` rays each."""
    count = len(texels)
    w_hit = np.zeros((count, 3))
    escaped = np.zeros(count)
    hit_sq = np.zeros(count)
    chunks = [slice(start, min(start + settings.chunk_texels, count))
              for start in range(0, count, settings.chunk_texels)]

    def work(rows: slice) -> None:
        w_hit[rows], escaped[rows], hit_sq[rows] = _chunk_terms(
            scene, world, tracer, texels, rows, settings)
        if progress is not None:
            progress(rows.stop - rows.start)

    threads = settings.threads or _cores()
    if threads == 1:
        for rows in chunks:
            work(rows)
    else:
        with ThreadPoolExecutor(threads) as pool:
            list(pool.map(work, chunks))
    return Terms(w_hit=w_hit, escaped=escaped, hit_sq=hit_sq, rays=count * settings.rays)


def _cores() -> int:
    """Cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
