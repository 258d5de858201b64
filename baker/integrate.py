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

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .geometry import World
from .obscurance import RHO_KINDS, UNIT_REFLECTIVITY, rho
from .parallel import run_chunks
from .rasterise import Texels
from .sampling import TECHNIQUES, fill_cosine, fill_points, frame, jit
from .scene import Scene
from .settings import Resolved
from .surface import LUMINANCE, albedo, triangle_albedo
from .trace import Tracer, ray_lift

@dataclass(frozen=True)
class Terms:
    """The estimated terms of N texels (rows in ``Texels`` order, or of the rows asked for).

    w_hit: (N, 3) mean of R(Q)·ρ(d) over the texel's rays (misses count 0).
    escaped: (N,) fraction of rays with no hit closer than d_max.
    hit_sq: (N,) mean over rays of the squared luminance of R(Q)·ρ(d) (0 for escaped rays),
    for the sample variance. counts: (N,) int64 rays cast per texel (all equal unless adaptive).
    half_split: (N, 2) mean over the first half of the texel's rays minus the mean over the
    second half, in luminance of R·ρ and in escaped fraction; quarter_split: (N, 2) the same
    within the first half (first quarter minus second quarter). See ``rmse``.
    """

    w_hit: np.ndarray
    escaped: np.ndarray
    hit_sq: np.ndarray
    counts: np.ndarray
    half_split: np.ndarray
    quarter_split: np.ndarray

    @property
    def rays(self) -> int:
        """How many obscurance rays were cast in all."""
        return int(self.counts.sum())

    def obscurance(self, r_ave: np.ndarray) -> np.ndarray:
        """W (N, 3) for average reflectivity ``r_ave`` (3,)."""
        return self.w_hit + self.escaped[:, None] * r_ave

    def standard_error(self, r_ave: np.ndarray) -> np.ndarray:
        """(N,) standard error of the luminance of W, from the rays' sample variance."""
        mean = self.obscurance(r_ave) @ LUMINANCE
        second = self.hit_sq + self.escaped * float(r_ave @ LUMINANCE) ** 2
        n = np.maximum(self.counts, 1)
        variance = np.maximum(second - mean * mean, 0.0) * n / np.maximum(n - 1, 1)
        return np.sqrt(variance / n)

    def rmse(self, r_ave: np.ndarray, technique: str) -> float:
        """Estimated RMSE over the texels of W's luminance, from the rays alone.

        The sample variance assumes independent samples, so it overstates the error of
        stratified and low-discrepancy points (4–8× for Owen-scrambled Sobol at 64–1024 rays,
        measured by ``baker study``). Instead: e = half the difference of the means of the two
        halves of each texel's rays (each half of a scrambled Sobol net is a net itself). Were
        the halves' errors independent, E[e²] would be the variance of the full mean; they are
        anti-correlated (correlation c), and E[e²] = var·(1 − c)/(1 + c). The same split one
        level down (quarters of the first half) measures the convergence: the ratio
        r = E[e_half²] / E[e_quarter²] = 2^(−2α) for error ∝ N^(−α), and (1 + c)/2 = r, so
        var = E[e²]·r/(1 − r) — exact for independent samples (r = ½), and measured within
        1.5× of the true RMSE for Sobol at 64 rays and more. r is averaged over all texels
        (one texel's is far too noisy) and kept within [0.05, 0.5]. For ``stratified`` points,
        whose halves cover different cells, the sample variance is used (an overestimate).
        """
        if not len(self.counts):
            return 0.0
        if technique == "stratified":
            return float(np.sqrt(np.mean(self.standard_error(r_ave) ** 2)))
        lum = np.array([1.0, float(r_ave @ LUMINANCE)])
        half = np.mean((0.5 * self.half_split @ lum) ** 2)
        quarter = np.mean((0.5 * self.quarter_split @ lum) ** 2)
        ratio = float(np.clip(half / quarter, 0.05, 0.5)) if quarter > 0 else 0.5
        return float(np.sqrt(half * ratio / (1.0 - ratio)))


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


def hemisphere_rays(texels: Texels, rows: np.ndarray | slice, rays: int, seed: int,
                    center: np.ndarray, technique: str = "sobol", first: int = 0,
                    total: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Cosine-distributed rays about each texel's front-face normal, ready for Embree.

    rows: the texels (indices or a slice); their samples ``first`` … ``first + rays − 1`` of
    ``total`` (default ``rays``; the stratified grid's size). Returns origins and directions,
    each (k·rays, 3) float32 in the tracer's recentred frame (world − ``center``), texel-major
    (texel i's rays are rows i·rays … i·rays + rays − 1). Computed in float64 (points, then
    directions, in flat arrays that the compiler vectorises), rounded once at the end.
    """
    keys = texels.key[rows]
    k = len(keys)
    u, v = np.empty(k * rays), np.empty(k * rays)
    fill_points(TECHNIQUES.index(technique), np.uint64(seed), keys, first, rays,
                total or rays, np.uint64(0), u, v)
    x, y, z = np.empty(k * rays), np.empty(k * rays), np.empty(k * rays)
    fill_cosine(u, v, x, y, z)
    origins = np.empty((k * rays, 3), np.float32)
    directions = np.empty((k * rays, 3), np.float32)
    _to_world_kernel(rays, texels.position[rows], texels.geometric_normal[rows],
                     ray_lift(texels.position[rows], texels.size[rows], center), center, x, y, z,
                     origins, directions)
    return origins, directions


# Columns of the per-texel sums the kernel accumulates.
_RGB, _ESCAPED, _SQUARE = slice(0, 3), 3, 4
_HALF, _QUARTER = slice(5, 7), slice(7, 9)  # (hit luminance, escaped) over the first ½, ¼
_COLUMNS = 9


@jit
def _accumulate_kernel(rays, primitive, distance, d_max, rho_kind, table, varying, ray_albedo,
                       luminance, sums):
    """Per texel, summed over its ``rays`` rays, into ``sums`` (k, 9): R(Q)·ρ(d) (RGB), escaped
    rays, squared luminance of R·ρ; then over the first ⌊rays/2⌋ rays and over the first
    ⌊rays/4⌋ rays alone: luminance of R·ρ, escaped rays (for the split error estimate, see
    ``Terms.rmse``).

    primitive/distance: (k·rays,) Embree's primID (−1: no hit within d_max) and tfar.
    table/varying: ``surface.triangle_albedo``; ray_albedo (k·rays, 3): the albedo at each
    hit of a ``varying`` triangle (may be (0, 3) when the chunk hits none).
    """
    half, quarter = rays // 2, rays // 4
    for i in range(len(sums)):
        red = green = blue = square = half_hit = quarter_hit = 0.0
        missed = half_missed = quarter_missed = 0
        for s in range(rays):
            r = i * rays + s
            t = primitive[r]
            if t < 0:
                missed += 1
                if s < half:
                    half_missed += 1
                if s < quarter:
                    quarter_missed += 1
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
            if s < half:
                half_hit += lum
            if s < quarter:
                quarter_hit += lum
        sums[i, 0], sums[i, 1], sums[i, 2] = red, green, blue
        sums[i, 3], sums[i, 4] = missed, square
        sums[i, 5], sums[i, 6] = half_hit, half_missed
        sums[i, 7], sums[i, 8] = quarter_hit, quarter_missed


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


def _chunk_sums(surfaces: _Surfaces, tracer: Tracer, texels: Texels, rows: np.ndarray,
                first: int, rays: int, settings: Resolved) -> np.ndarray:
    """(k, 7) sums over samples ``first`` … ``first + rays − 1`` of the texels ``rows``, as
    ``_accumulate_kernel`` lays them out."""
    origins, directions = hemisphere_rays(texels, rows, rays, settings.seed, tracer.center,
                                          settings.sampling, first, _grid_size(settings))
    hits = tracer.cast_local(origins, directions, np.full(len(origins), settings.d_max, np.float32))
    primitive = hits["primID"]
    if settings.rho in UNIT_REFLECTIVITY or not surfaces.varying.any():
        ray_albedo = np.zeros((0, 3))
    else:
        ray_albedo = surfaces.varying_albedo(primitive, hits["u"], hits["v"])
    varying = surfaces.varying if len(ray_albedo) else np.zeros_like(surfaces.varying)
    sums = np.empty((len(rows), _COLUMNS))
    _accumulate_kernel(rays, primitive, hits["tfar"], np.float32(settings.d_max),
                       RHO_KINDS[settings.rho], surfaces.table, varying, ray_albedo, LUMINANCE,
                       sums)
    return sums


def _grid_size(settings: Resolved) -> int:
    """Samples per texel the stratified grid is laid out for: the most a texel may get."""
    return settings.max_rays if settings.target_error is not None else settings.rays


def integrate(scene: Scene, world: World, tracer: Tracer, texels: Texels, settings: Resolved,
              progress: Callable[[int], None] | None = None, rows: np.ndarray | None = None,
              error_scale: tuple[np.ndarray, float] | None = None) -> Terms:
    """Estimate the obscurance terms of the texels ``rows`` (default: all), in that order.

    Without ``settings.target_error`` every texel gets ``settings.rays`` rays. With it, rays come
    in rounds — ``rays``, then doubling each texel's count while it stays within ``max_rays``
    (so counts are rays·2^k, and halves of a count are whole nets) — and a texel stops
    once the standard error of its lightmap luminance, ``error_scale[1]`` × the standard error
    of W's luminance with R_ave = ``error_scale[0]``, is at most ``target_error``. The rounds
    are the same whatever the chunking, so the result is too. ``progress`` is told how many
    texels each chunk of the first round finished.
    """
    rows = np.arange(len(texels)) if rows is None else np.asarray(rows, np.int64)
    table, varying = triangle_albedo(scene, world)
    surfaces = _Surfaces(scene, world, table, varying)
    sums = np.zeros((len(rows), _COLUMNS))
    counts = np.zeros(len(rows), np.int64)
    active = np.arange(len(rows))
    first, batch = 0, settings.rays
    while len(active):
        if first:  # doubling: the samples so far become the first half, their half the quarter
            sums[active, _QUARTER] = sums[active, _HALF]
            sums[active, _HALF] = _luminance_and_escaped(sums[active])

        def work(chunk: np.ndarray, first=first, batch=batch) -> None:
            round_sums = _chunk_sums(surfaces, tracer, texels, rows[chunk], first, batch, settings)
            if first:
                round_sums[:, _HALF.start:] = 0.0
            sums[chunk] += round_sums
            if progress is not None and first == 0:
                progress(len(chunk))

        run_chunks(work, [active[start:start + settings.chunk_texels]
                          for start in range(0, len(active), settings.chunk_texels)],
                   settings.threads)
        counts[active] += batch
        first += batch
        if settings.target_error is None or 2 * first > settings.max_rays:
            break
        terms = _means(sums[active], counts[active])
        r_ave, scale = error_scale if error_scale is not None else (np.ones(3), 1.0)
        active = active[terms.standard_error(r_ave) * scale > settings.target_error]
        batch = first
    return _means(sums, counts)


def _luminance_and_escaped(sums: np.ndarray) -> np.ndarray:
    """(k, 2) summed luminance of R·ρ and escaped rays, from sums (k, 9)."""
    return np.column_stack([sums[:, _RGB] @ LUMINANCE, sums[:, _ESCAPED]])


def _split(part: np.ndarray, part_count: np.ndarray, whole: np.ndarray,
           whole_count: np.ndarray) -> np.ndarray:
    """(k, 2) mean over a first part of the rays minus the mean over the rest of ``whole``."""
    rest = np.maximum(whole_count - part_count, 1)[:, None]
    split = part / np.maximum(part_count, 1)[:, None] - (whole - part) / rest
    return np.where((part_count >= 1)[:, None] & (whole_count > part_count)[:, None], split, 0.0)


def _means(sums: np.ndarray, counts: np.ndarray) -> Terms:
    """Terms from per-texel sums (k, 9) over ``counts`` (k,) rays."""
    means = sums[:, :_HALF.start] / np.maximum(counts, 1)[:, None]
    half, quarter = counts // 2, counts // 4
    first_half = _split(sums[:, _HALF], half, _luminance_and_escaped(sums), counts)
    first_quarter = _split(sums[:, _QUARTER], quarter, sums[:, _HALF], half)
    return Terms(w_hit=means[:, _RGB], escaped=means[:, _ESCAPED], hit_sq=means[:, _SQUARE],
                 counts=counts, half_split=first_half, quarter_split=first_quarter)
