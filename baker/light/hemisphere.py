"""Per-texel estimation of the obscurance with colour bleeding, equation (2) of the paper:

    W(P) = 1/π ∫_Ω R(Q) ρ(d(P, ω)) cosθ dω

With cosine-weighted directions (pdf cosθ / π) the estimator is the mean of R(Q)·ρ(d) over the
texel's rays. The terms are kept apart (docs/design.md §2): ``w_hit`` is the hits' part (RGB) and
``escaped`` the fraction of rays that met nothing closer than d_max, so W = w_hit + escaped·R_ave
and a change of R_ave needs no new ray.

Work is split into chunks of texels run on a thread pool (Embree releases the GIL). Every texel's
rays depend only on its key and the seed (sampling.py), and every chunk writes only its own rows,
so the result is the same bytes for any chunk size, thread count or order.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from baker.atlas.rasterise import Texels
from baker.atlas.supersample import sub_positions
from baker.geometry.surface import (
    LUMINANCE,
    albedo,
    base_colour,
    diffuse_factors,
    luminance,
    triangle_albedo,
)
from baker.context import Context
from baker.geometry.world import World
from baker.jit import inline, jit
from baker.light.adaptive import WITHIN, neighbours_among, pooled_gain
from baker.light.obscurance import RHO_KINDS, UNIT_REFLECTIVITY, rho
from baker.materials import DIFFUSE, SPECULAR, TRANSLUCENT, TRANSPARENT, MaterialTable
from baker.rays.dimensions import OBSCURANCE, material_dimension
from baker.rays.sampling import (
    extend_nets,
    fill_cosine,
    fill_points,
    fold,
    frame,
    hash_u32,
    net_points,
    net_word,
)
from baker.rays.trace import LocalHits, Tracer, ray_lift
from baker.run.parallel import cores, even_slices, run_chunks, texels_per_chunk
from baker.settings import TECHNIQUES, Resolved

_SPLIT_MAX = 1e100  # |halves' differences| beyond this (garbage albedos) are clipped, so
# that their mean square cannot overflow float64: such an estimate is meaningless anyway


@dataclass(frozen=True)
class Terms:
    """The estimated terms of N texels (rows in ``Texels`` order, or of the rows asked for).

    w_hit: (N, 3) mean of R(Q)·ρ(d) over the texel's rays (misses count 0).
    escaped: (N,) fraction of rays with no hit closer than d_max.
    hit_sq: (N,) mean over rays of the squared luminance of R(Q)·ρ(d) (0 for escaped rays),
    for the sample variance. counts: (N,) int64 rays cast per texel (all equal unless adaptive).
    half_split: (N, 2) mean over the first half of the texel's rays minus the mean over the
    second half, in luminance of R·ρ and in escaped fraction (the halves are independent
    estimates: ``sampling.fill_points``; see ``rmse``). chain_rays: (N,)
    int64 rays cast beyond the texel's own, along mirror and glass chains (§3.1–3.2), and for
    leaves and closed translucent objects their back-face and inner rays (§4); capped:
    (N,) int64 of its rays whose chain the depth cap stopped (both empty when not counted).
    With mirrors, glass or translucency, a ray's escaped weight may be a fraction (the mean
    of its chain's RGB throughput), and ``escaped`` the mean of those weights; escaped_tint:
    (N, 3) the mean of what such a chain's RGB throughput adds to its escaped weight in each
    channel (a red mirror's escapes are red: W takes (escaped + escaped_tint) · R_ave, the
    visibility ``escaped`` alone), None when no mirror or glass is in the scene.
    through_hit, through_ave: (N, 3) light through translucent surfaces (§4, ``inner.py``): the
    part of W independent of R_ave (a leaf's translucency × its back face's hits) and the RGB
    weight of R_ave (× the back face's escaped fraction, + the inner obscurance); None when the
    scene has no leaf or closed translucent material. The error estimates cover the front's
    rays only.
    aim_hit, aim_escaped: (N, 3) with ``directional_pages``, else (0, 3): the means of
    luminance of R(Q)·ρ(d) × the ray's first world direction, and of its escaped weight × that
    direction (``light.directional``: W's first moment is aim_hit + lum R_ave · aim_escaped);
    aim_split: (N, 6) their first half's mean minus the second's (as ``half_split``), or (0, 6).
    """

    w_hit: np.ndarray
    escaped: np.ndarray
    hit_sq: np.ndarray
    counts: np.ndarray
    half_split: np.ndarray
    chain_rays: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    capped: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    through_hit: np.ndarray | None = None
    through_ave: np.ndarray | None = None
    aim_hit: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    aim_escaped: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    aim_split: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    escaped_tint: np.ndarray | None = None

    @property
    def rays(self) -> int:
        """How many obscurance rays were cast in all."""
        return int(self.counts.sum())

    def chain_ray_counts(self) -> np.ndarray:
        """(N,) int64 ``chain_rays``, zeros when they were not counted (a new array)."""
        return self.chain_rays.copy() if len(self.chain_rays) else np.zeros(len(self.counts), np.int64)

    def obscurance(self, r_ave: np.ndarray) -> np.ndarray:
        """W (N, 3) for average reflectivity ``r_ave`` (3,), with the light through
        translucent surfaces (``through_hit``, ``through_ave``) when there is some
        (``obscurance_at``)."""
        out = np.empty((len(self.escaped), 3))
        _obscurance_kernel(*self.w_parts(), np.asarray(r_ave, np.float64), out)
        return out

    def w_parts(self) -> tuple[np.ndarray, ...]:
        """(w_hit, escaped, escaped_tint, through_hit, through_ave) as ``obscurance_at`` takes
        them: the tint and the light through translucent surfaces as (0, 3) arrays when there
        is none."""
        none = np.zeros((0, 3))
        return (self.w_hit, self.escaped,
                none if self.escaped_tint is None else self.escaped_tint,
                none if self.through_hit is None else self.through_hit,
                none if self.through_ave is None else self.through_ave)

    def aim(self, r_ave: np.ndarray) -> np.ndarray:
        """(N, 3) the first moment of W's luminance over the texel's rays, world space
        (``light.directional``), for R_ave ``r_ave`` (3,); (0, 3) without directions."""
        return self.aim_hit + float(luminance(r_ave)) * self.aim_escaped

    def aim_errors(self, r_ave: np.ndarray) -> np.ndarray:
        """(N,) e² per texel of ``aim``'s estimate, summed over its three components, from
        the halves of the texel's rays (as ``split_errors``); (0,) without directions."""
        lum = float(luminance(r_ave))
        e = 0.5 * (self.aim_split[:, :3] + lum * self.aim_split[:, 3:])
        return np.sum(np.clip(e, -_SPLIT_MAX, _SPLIT_MAX) ** 2, axis=1)

    def _front(self, r_ave: np.ndarray) -> np.ndarray:
        """(N, 3) the part of W that the texel's own rays estimate."""
        front = self.w_hit + self.escaped[:, None] * r_ave
        return front if self.escaped_tint is None else front + self.escaped_tint * r_ave

    def standard_error(self, r_ave: np.ndarray) -> np.ndarray:
        """(N,) standard error of the luminance of W, from the rays' sample variance; where
        that is 0 and no ray escaped (every ray hit within d_max with ``--rho step``: W = 0),
        ``binomial_floor``: a fraction p ~ 1/n of the texel's directions may still escape
        unseen, and an error of 0 would claim W exact. (A texel whose every ray escaped, an
        open floor's, keeps 0: there the rays' value R_ave is usually exact.)"""
        variance = self._sample_variance(r_ave)
        n = np.maximum(self.counts, 1)
        return np.where(self._unseen(variance), binomial_floor(self.counts, r_ave),
                        np.sqrt(variance / n))

    def _sample_variance(self, r_ave: np.ndarray) -> np.ndarray:
        """(N,) the rays' sample variance of the luminance of R·ρ (or R_ave when escaped)."""
        mean = luminance(self._front(r_ave))
        second = self.hit_sq + self.escaped * float(luminance(r_ave)) ** 2
        n = np.maximum(self.counts, 1)
        return np.maximum(second - mean * mean, 0.0) * n / np.maximum(n - 1, 1)

    def alike(self, r_ave: np.ndarray) -> np.ndarray:
        """(N,) bool: every ray of the texel gave one value (no sample variance)."""
        return self._sample_variance(r_ave) <= 0

    def _unseen(self, variance: np.ndarray) -> np.ndarray:
        """(N,) bool: every ray gave one value and none escaped (``standard_error``)."""
        return (variance <= 0) & (self.escaped <= 0)

    def split_squares(self, r_ave: np.ndarray) -> np.ndarray:
        """(N,) e² per texel, e = half the difference of the means of its two halves of rays
        in luminance of W (clipped to ±``_SPLIT_MAX``): the halves are independent estimates
        (``sampling.fill_points``), so e² estimates the variance of the texel's W without bias
        (one degree of freedom; see ``rmse``), 0 where every ray agreed."""
        lum = float(luminance(r_ave))
        e = np.clip(0.5 * (self.half_split[:, 0] + lum * self.half_split[:, 1]),
                    -_SPLIT_MAX, _SPLIT_MAX)
        return e * e

    def split_errors(self, r_ave: np.ndarray) -> np.ndarray:
        """(N,) ``split_squares``, and where ``standard_error`` takes the ``binomial_floor``, at
        least its square: a texel whose rays all agreed is not taken to have no error."""
        squares = self.split_squares(r_ave)
        unseen = self._unseen(self._sample_variance(r_ave))
        return np.where(unseen, np.maximum(squares, binomial_floor(self.counts, r_ave) ** 2),
                        squares)

    def rmse(self, r_ave: np.ndarray) -> float:
        """Estimated RMSE over the texels of W's luminance, from the rays alone.

        The sample variance assumes independent samples, so it overstates the error of
        stratified and low-discrepancy points (4–8× for Owen-scrambled Sobol at 64–1024 rays,
        3–6× for stratified, measured by ``baker study``). Instead: e = half the difference of
        the means of the two halves of each texel's rays. Every technique draws the halves
        independently (``sobol`` as two scrambled nets, ``stratified`` as its grid laid twice:
        ``sampling.fill_points``), so with equal halves E[e²] is the variance of the whole
        mean, whatever the points' convergence; a single net's halves are anti-correlated,
        and the correction for it that baker once made from the quarters' split was 3× off
        where the error's fall from one level to the next is uneven (``--rho step`` under a
        ceiling). The mean of e² over the texels (``split_errors``) is the mean squared error.
        """
        return rmse_of(self.split_square(r_ave), len(self.counts))

    def split_square(self, r_ave: np.ndarray) -> float:
        """The sum of ``split_errors``: what ``rmse_of`` needs, added up part by part when a
        bake makes its texels a part at a time."""
        return float(np.sum(self.split_errors(r_ave)))


def binomial_floor(counts: np.ndarray, r_ave: np.ndarray) -> np.ndarray:
    """(N,) the standard error of a mean of ``counts`` rays that all gave one value, their
    values lying in [0, M], M = max(1, lum R_ave) (a ray gives R·ρ or R_ave): M/(n + 2), the
    rule of succession's p̂ = (k + 1)/(n + 2) at k = 0 of n rays giving another value. When
    no ray of n saw an event of probability p, p ≲ 1/n is all they can say, and the texel may
    be off by p·M; one such ray in n gives a sample error of about M/n, so the two meet."""
    bound = max(1.0, float(luminance(r_ave)))
    return bound / (np.asarray(counts, np.float64) + 2.0)


def rmse_of(square: float, count: int) -> float:
    """``Terms.rmse`` of ``count`` texels from their ``Terms.split_square``."""
    return float(np.sqrt(square / count)) if count else 0.0


@inline
def obscurance_at(w_hit, escaped, escaped_tint, through_hit, through_ave, r_ave, i):
    """W (3 floats) of texel i: w_hit + escaped · R_ave, plus escaped_tint · R_ave (escapes
    tinted by mirrors and glass) and the light through translucent surfaces, through_hit +
    through_ave · R_ave, when those have rows (``Terms.w_parts``). Inlined where it is
    called: arrays passed to a call cost reference counts per texel."""
    out = (w_hit[i, 0] + escaped[i] * r_ave[0], w_hit[i, 1] + escaped[i] * r_ave[1],
           w_hit[i, 2] + escaped[i] * r_ave[2])
    if len(escaped_tint):
        out = (out[0] + escaped_tint[i, 0] * r_ave[0], out[1] + escaped_tint[i, 1] * r_ave[1],
               out[2] + escaped_tint[i, 2] * r_ave[2])
    if not len(through_hit):
        return out
    return (out[0] + through_hit[i, 0] + through_ave[i, 0] * r_ave[0],
            out[1] + through_hit[i, 1] + through_ave[i, 1] * r_ave[1],
            out[2] + through_hit[i, 2] + through_ave[i, 2] * r_ave[2])


@jit
def _obscurance_kernel(w_hit, escaped, escaped_tint, through_hit, through_ave, r_ave, out):
    for i in range(len(out)):
        out[i, 0], out[i, 1], out[i, 2] = obscurance_at(w_hit, escaped, escaped_tint,
                                                        through_hit, through_ave, r_ave, i)


def cosine_directions(keys: np.ndarray, rays: int, seed: int, technique: str = "sobol",
                      first: int = 0, start: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The local cosine-distributed directions x, y, z (k·rays,) float64 of samples ``first`` …
    ``first + rays − 1`` of the texels ``keys`` (k,), texel-major, about +z (the normal).

    ``start``: ``sampling.net_points``."""
    k = len(keys)
    u, v = net_points(seed, keys, first, rays, OBSCURANCE, technique, start)
    x, y, z = np.empty(k * rays), np.empty(k * rays), np.empty(k * rays)
    fill_cosine(u, v, x, y, z)
    return x, y, z


def hemisphere_rays(texels: Texels, rows: np.ndarray | slice, rays: int, seed: int,
                    center: np.ndarray, technique: str = "sobol", first: int = 0,
                    sub: np.ndarray | None = None, start: int = 0
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Cosine-distributed rays about each texel's hemisphere normal (its shading normal, or its
    front-face normal on flat surfaces: ``Texels.hemisphere_normal``), those below the front
    face folded above it (``sampling.fold``), ready for Embree.

    rows: the texels (indices or a slice); their samples ``first`` … ``first + rays − 1`` (one
    stratified grid, ``sampling.fill_points``; start: ``cosine_directions``). sub: None (every ray starts at the texel's
    sample point), or (k, S, 3) world sub-positions of the texels (``supersample.sub_positions``,
    on the texel's plane, so the same normals and frame): sample j starts from sub-position
    j mod S. Returns origins and directions,
    each (k·rays, 3) float32 in the tracer's recentred frame (world − ``center``), texel-major
    (texel i's rays are rows i·rays … i·rays + rays − 1). Computed in float64 (points, then
    directions, a texel at a time: ``_rays_kernel``), rounded once at the end.
    """
    keys = texels.key[rows]
    origins = np.empty((len(keys) * rays, 3), np.float32)
    directions = np.empty((len(keys) * rays, 3), np.float32)
    extend = bool(start and first and technique == "sobol")  # as ``net_points`` decides
    _rays_kernel(TECHNIQUES.index(technique), np.uint64(seed), keys, first, rays,
                 np.uint64(OBSCURANCE), extend, net_word(np.uint64(OBSCURANCE), start // 2),
                 texels.position[rows][:, None, :] if sub is None else sub,
                 texels.hemisphere_normal(rows), texels.geometric_normal(rows),
                 ray_lift(texels.position[rows], texels.size(rows), center), center,
                 origins, directions)
    return origins, directions


@jit
def _rays_kernel(technique, seed, keys, first, rays, dimension, extend, second, starts, normals,
                 geometric, offsets, center, origins, directions):
    """``hemisphere_rays`` texel by texel: each texel's points (``sampling.fill_points``, or
    ``extend_nets`` with ``extend``, its second net's word ``second``), their cosine
    directions (``fill_cosine``) and its rays (``_texel_rays``), the same bits as those
    kernels give over all texels at once (``cosine_directions`` then ``world_rays``) without
    their (k·rays,) float64 arrays in between: 45 → 20 ns a ray at 20,000 texels of 64 rays,
    25 → 20 at a chunk's 4096; one origin a texel where it has one start, the kernel alone on
    4096 texels 13.8 → 10.6."""
    u, v = np.empty(rays), np.empty(rays)
    x, y, z = np.empty(rays), np.empty(rays), np.empty(rays)
    for i in range(len(keys)):
        if extend:
            extend_nets(seed, keys[i:i + 1], first // 2, rays // 2, second, dimension, u, v)
        else:
            fill_points(technique, seed, keys[i:i + 1], first, rays, dimension, u, v)
        fill_cosine(u, v, x, y, z)
        _texel_rays(i, rays, first, starts, normals, geometric, offsets, center, x, y, z, 0,
                    origins, directions, i * rays)


@inline
def _texel_rays(i, rays, first, starts, normals, geometric, offsets, center, x, y, z, r0,
                origins, directions, q0):
    """Write texel i's ``rays`` rays, from local directions x, y, z [r0, r0 + rays), to rows
    q0 … q0 + rays − 1 of ``origins`` and ``directions``."""
    count = starts.shape[1]
    gx, gy, gz = geometric[i, 0], geometric[i, 1], geometric[i, 2]
    nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
    tilted = nx != gx or ny != gy or nz != gz
    f = frame(nx, ny, nz)
    ox, oy, oz = _lifted(starts, i, 0, offsets, center, gx, gy, gz)
    for s in range(rays):
        if count > 1:
            ox, oy, oz = _lifted(starts, i, (first + s) % count, offsets, center, gx, gy, gz)
        q = q0 + s
        origins[q, 0], origins[q, 1], origins[q, 2] = ox, oy, oz
        r = r0 + s
        directions[q, 0], directions[q, 1], directions[q, 2] = _world_direction(
            x[r], y[r], z[r], f, nx, ny, nz, tilted, gx, gy, gz)


@inline
def _lifted(starts, i, j, offsets, center, gx, gy, gz):
    """Start j of texel i (``starts`` (k, S, 3) world), lifted by its offset along the
    front-face normal g and recentred on ``center``."""
    return (starts[i, j, 0] - center[0] + offsets[i] * gx,
            starts[i, j, 1] - center[1] + offsets[i] * gy,
            starts[i, j, 2] - center[2] + offsets[i] * gz)


@inline
def _world_direction(x, y, z, f, nx, ny, nz, tilted, gx, gy, gz):
    """The local direction (x, y, z) in the frame (``sampling.frame`` f, normal n), folded
    above the front face g where the frame is tilted from it (``sampling.fold``)."""
    dx = x * f[0] + y * f[3] + z * nx
    dy = x * f[1] + y * f[4] + z * ny
    dz = x * f[2] + y * f[5] + z * nz
    if tilted:
        return fold(dx, dy, dz, gx, gy, gz)
    return dx, dy, dz


def world_rays(texels: Texels, rows: np.ndarray, texel: np.ndarray, x: np.ndarray,
               y: np.ndarray, z: np.ndarray, center: np.ndarray, sample: np.ndarray | None = None,
               sub: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Embree's float32 rays, one per entry of ``texel`` (m,) (an index into ``rows``, texels
    of ``texels``), along the local cosine directions x, y, z (m,) (``cosine_directions``), each
    texel's sample ``sample`` (m,) (None: 0), in any order: the bits of those rays in
    ``hemisphere_rays``, each texel's normals, lift and starts gathered once however many of
    its rays are asked (a rebake's candidate rays, ``reach.rays_meet``). ``sub``: (k, S, 3)
    sub-texel starts of the texels ``rows`` (``supersample.sub_positions``), sample s from
    start s mod S; None: their sample points. (m, 3) float32 origins and directions."""
    origins = np.empty((len(texel), 3), np.float32)
    directions = np.empty((len(texel), 3), np.float32)
    position = texels.position[rows]
    _scattered_kernel(texel, np.zeros(len(texel), np.int64) if sample is None else sample,
                      position[:, None, :] if sub is None else sub,
                      texels.hemisphere_normal(rows), texels.geometric_normal(rows),
                      ray_lift(position, texels.size(rows), center), center, x, y, z, origins,
                      directions)
    return origins, directions


@jit
def _scattered_kernel(texel, sample, starts, normals, geometric, offsets, center, x, y, z,
                      origins, directions):
    """``_texel_rays`` of one ray per entry q of ``texel``: texel ``texel[q]``'s sample
    ``sample[q]``, along local direction q, to row q (``world_rays``)."""
    for q in range(len(texel)):
        _texel_rays(texel[q], 1, sample[q], starts, normals, geometric, offsets, center, x, y,
                    z, q, origins, directions, q)


# Columns of the per-texel sums the kernel accumulates.
RGB, ESCAPED, SQUARE = slice(0, 3), 3, 4
HALF = slice(5, 7)  # (hit luminance, escaped) over the first half of the rays
_HALF_ESCAPED = HALF.stop - 1
COLUMNS = 7
# With directions (``Resolved.directional_pages``): luminance of R·ρ and escaped weight, each
# × the ray's direction, over all rays, then over the first half.
_AIM, _AIM_HALF = slice(7, 13), slice(13, 19)
_AIM_COLUMNS = 19


def columns(directional: bool) -> int:
    """How many sums a texel's rays make (``accumulate_kernel``)."""
    return _AIM_COLUMNS if directional else COLUMNS


_CONSTANT, _VARYING, _SPECIAL = 0, 1, 2  # per-triangle kinds of ``accumulate_kernel``

# Each ray's values are rounded to multiples of 2^-40 before they are summed (``_on_grid``).
# Sums of such values stay exact in float64 while below 2^13, so they do not depend on the
# order of the rays, and a rebake can take a ray's old value out of a texel's sums and put its
# new one in to get the very bits a full bake sums (``rebake.exact_sums.ray_changes``): with
# every value in [0, 1] (``Surfaces.exact_sums``), for up to ``EXACT_RAYS`` rays a texel.
# 2^-40 ≈ 10^-12 is far below float32's output precision.
_SHIFT = 1.5 * 2.0 ** 12  # x + _SHIFT for x in [−2^11, 2^11) has float64 spacing 2^-40
EXACT_RAYS = 1 << 11


def grid_values(x: np.ndarray) -> np.ndarray:
    """``_on_grid`` of an array of values (a new array)."""
    return (x + _SHIFT) - _SHIFT


@inline
def _on_grid(x):
    """x rounded to the nearest multiple of 2^-40 (ties to even), for x in [−2^11, 2^11): the
    same as rint(x · 2^40) · 2^-40, without its overflow for garbage albedos far beyond."""
    return (x + _SHIFT) - _SHIFT


# ``accumulate_kernel``'s (target, sample) for rays laid out texel by texel.
_TEXEL_MAJOR = (np.zeros(0, np.int64), np.zeros(0, np.int64))
NO_DIRECTIONS = np.zeros((0, 3), np.float32)  # its ``directions`` when they are not kept


@jit
def accumulate_kernel(rays, primitive, distance, d_max, rho_kind, table, kind, ray_albedo,
                      luminance, sums, target, sample, sign, directions):
    """Add each ray's values to its texel's sums (k, 7): R(Q)·ρ(d) (RGB), escaped weight (1 for
    a miss), squared luminance of R·ρ; then, for the rays among the first ⌊rays/2⌋ of their
    texel, luminance of R·ρ and escaped weight (for the split error estimate, see
    ``Terms.rmse``). With ``directions`` (one unit world direction per ray, (m, 3); (0, 3):
    none) and sums of ``_AIM_COLUMNS``: also luminance of R·ρ and escaped weight × the
    direction, over all rays and over the first half. Every value is rounded to the grid
    (``_on_grid``) first, so the sums are exact: the same bits in any order.

    primitive/distance: the rays' hit triangle (−1: no hit within d_max) and distance (``LocalHits``), laid
    out texel by texel (k·rays,), ray r being sample r mod rays of texel r // rays, when
    ``target`` and ``sample`` are empty (``_TEXEL_MAJOR``); else ray j is sample ``sample[j]``
    of texel ``target[j]`` (m,) (a rebake's changed rays, added with ``sign`` −1 for their old
    hits and +1 for their new ones: ``rebake.exact_sums.ray_changes``). ``sign``: 1.0 to add each ray's values.
    table: ``surface.triangle_albedo``'s; kind: (T,) uint8 per triangle, ``_CONSTANT`` (albedo
    from ``table``), ``_VARYING`` (ray_albedo[r, :3] is the albedo at the hit) or ``_SPECIAL``
    (a mirror, glass or translucent material, ``_special_hits``: ray_albedo[r, :3] is the ray's
    R·ρ itself and ray_albedo[r, 3] its escaped weight, R_ave·ρ = 1 counting that fraction).
    ray_albedo: one row of 4 per ray, or (0, 4) when every kind is ``_CONSTANT``.
    """
    half = rays // 2
    indexed = len(target) > 0
    aimed = len(directions) > 0
    for r in range(len(primitive)):
        i, s = (target[r], sample[r]) if indexed else (r // rays, r % rays)
        t = primitive[r]
        escape = 0.0
        if t < 0:
            escape = 1.0
            cr = cg = cb = 0.0
        else:
            k = kind[t]
            if k == 2:
                escape = _on_grid(ray_albedo[r, 3])
                weight = 1.0
                cr, cg, cb = ray_albedo[r, 0], ray_albedo[r, 1], ray_albedo[r, 2]
            else:
                weight = rho(rho_kind, distance[r] / d_max)
                if k == 1:
                    cr, cg, cb = ray_albedo[r, 0], ray_albedo[r, 1], ray_albedo[r, 2]
                else:
                    cr, cg, cb = table[t, 0], table[t, 1], table[t, 2]
            cr, cg, cb = _on_grid(cr * weight), _on_grid(cg * weight), _on_grid(cb * weight)
        lum = _on_grid(cr * luminance[0] + cg * luminance[1] + cb * luminance[2])
        sums[i, 0] += sign * cr
        sums[i, 1] += sign * cg
        sums[i, 2] += sign * cb
        sums[i, 3] += sign * escape
        sums[i, 4] += sign * _on_grid(lum * lum)
        if s < half:
            sums[i, 5] += sign * lum
            sums[i, 6] += sign * escape
        if aimed:
            for c in range(3):
                d = float(directions[r, c])
                along, away = _on_grid(lum * d), _on_grid(escape * d)
                sums[i, 7 + c] += sign * along
                sums[i, 10 + c] += sign * away
                if s < half:
                    sums[i, 13 + c] += sign * along
                    sums[i, 16 + c] += sign * away


@dataclass(frozen=True)
class Surfaces:
    """What the shading of obscurance hits needs, built once per bake (``surfaces_of``) and
    passed to ``integrate`` for each part of the texels.

    kind: (T,) uint8 per world triangle for ``accumulate_kernel`` (``_CONSTANT``, ``_VARYING``,
    ``_SPECIAL``); materials: the scene's ``materials.MaterialTable``; normals: (T, 3) unit
    geometric normals, only when some triangle is ``_SPECIAL`` (else (0, 3)); step: world
    units a continued ray starts off its surface, besides 64 float32 ulps.
    """

    scene: object  # the loaded scene, for the albedo lookups (``Context.surfaces``)
    world: World
    table: np.ndarray  # (T, 3) constant albedo per world triangle
    varying: np.ndarray  # (T,) bool: albedo varies over the triangle (texture, vertex colours)
    kind: np.ndarray
    materials: MaterialTable
    normals: np.ndarray
    step: float

    @property
    def special(self) -> bool:
        """Whether any triangle needs ``_special_hits`` (mirrors, glass, translucency)."""
        return len(self.normals) > 0

    @property
    def exact_sums(self) -> bool:
        """Whether every ray's values lie in [0, 1], so that the sums of up to ``EXACT_RAYS``
        rays are exact (``_on_grid``): no special triangle, and albedos within [0, 1] (base
        colours and vertex colours are; textures always are)."""
        colours = self.world.colors[:, :3]
        base = diffuse_factors(self.world)
        return (not self.special and bool(((base >= 0) & (base <= 1)).all())
                and bool(((colours >= 0) & (colours <= 1)).all()))

    def varying_albedo(self, primitive: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(n, 4) albedo at the hits on varying triangles in columns 0–2 (other rows zero)."""
        out = np.zeros((len(primitive), 4))
        where = np.flatnonzero(primitive >= 0)
        where = where[self.kind[primitive[where]] == _VARYING]
        if len(where):
            uu, vv = u[where].astype(np.float64), v[where].astype(np.float64)
            bary = np.stack([1.0 - uu - vv, uu, vv], axis=1)
            out[where, :3] = albedo(self.scene, self.world, primitive[where].astype(np.int64), bary)
        return out


def surfaces_of(context: Context) -> Surfaces:
    """The shading tables of the context's scene: special triangles only where a material has
    a mirror, glass or translucent branch (a scene of diffuse surfaces gets the diffuse kernel
    alone)."""
    scene, world = context.surfaces, context.world
    table, varying = triangle_albedo(scene, world)
    materials = world.materials
    special = materials.special[world.tri_material] if len(world.triangles) else np.zeros(0, bool)
    kind = np.where(special, _SPECIAL, np.where(varying, _VARYING, _CONSTANT)).astype(np.uint8)
    normals = world.geometric_normals() if special.any() else np.zeros((0, 3))
    return Surfaces(scene, world, table, varying, kind, materials, normals, world.scale * 1e-6)


# Russian roulette starts at this bounce of a chain (tests may raise it to switch it off).
_ROULETTE_FROM = 2
_SURVIVAL_CAP = 0.95  # a chain survives roulette with min(this, its max throughput)


def most_escaped(max_depth: int) -> float:
    """The highest escaped weight a texel can hold (``Terms.escaped``, a mean of its rays'):
    1 for diffuse scenes, but a chain through clear glass or a white mirror keeps a throughput
    of 1 and each roulette divides it by ``_SURVIVAL_CAP``: up to max_depth − 1 times."""
    return _SURVIVAL_CAP ** -max(max_depth - 1, 0)


def _uniform(seed: int, keys: np.ndarray, samples: np.ndarray, dimension: int) -> np.ndarray:
    """(n,) uniform in (0, 1): a pure function of (seed, texel key, sample, dimension)."""
    h = hash_u32(np.uint64(seed), keys, samples, np.uint64(dimension))
    return ((h >> np.uint32(8)) + 0.5) * 2.0 ** -24


def _reflect(d: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Mirror directions d (k, 3) about unit normals n (k, 3)."""
    return d - 2.0 * np.einsum("ij,ij->i", d, n)[:, None] * n


def _refract(d: np.ndarray, n: np.ndarray, ior: np.ndarray, thin: np.ndarray,
             u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One path through a dielectric surface, chosen by importance: reflect with the Fresnel
    probability F (unpolarised, exact), else refract by Snell's law; total internal reflection
    always reflects. d, n (k, 3) unit (n either side); ior (k,); thin (k,) bool: a thin wall
    (no KHR_materials_volume thickness) lets the refracted ray go on unbent. Returns the new
    directions (k, 3) and whether each ray was refracted (k,) (the tint applies)."""
    cos_d = np.einsum("ij,ij->i", d, n)
    inside = cos_d > 0.0  # leaving the object through its back face
    facing = np.where(inside[:, None], -n, n)  # normal on the incoming side
    eta = np.where(inside & ~thin, ior, 1.0 / ior)  # n1 / n2
    cos_i = np.abs(cos_d)
    k = 1.0 - eta * eta * (1.0 - cos_i * cos_i)
    cos_t = np.sqrt(np.maximum(k, 0.0))
    r_s = (eta * cos_i - cos_t) / np.maximum(eta * cos_i + cos_t, 1e-300)
    r_p = (cos_i - eta * cos_t) / np.maximum(cos_i + eta * cos_t, 1e-300)
    fresnel = np.where(k <= 0.0, 1.0, 0.5 * (r_s * r_s + r_p * r_p))
    refracted = u >= fresnel
    bent = eta[:, None] * d + (eta * cos_i - cos_t)[:, None] * facing
    through = np.where(thin[:, None], d, bent)
    out = np.where(refracted[:, None], through, _reflect(d, facing))
    return out / np.linalg.norm(out, axis=1, keepdims=True), refracted


@dataclass
class _Chains:
    """What ``_special_hits`` adds up per texel of a chunk: rays cast along chains (k,), chains
    stopped by the depth cap (k,), and the summed tint of the escaped weights (k, 3): each
    ray's RGB throughput × ρ less its escaped weight (their mean), on the grid of
    ``_on_grid``, so exact in any order."""

    rays: np.ndarray
    capped: np.ndarray
    tint: np.ndarray


def _special_hits(surfaces: Surfaces, tracer: Tracer, origins: np.ndarray,
                  directions: np.ndarray, hits: LocalHits, keys: np.ndarray,
                  first: int, rays: int, settings: Resolved, out: np.ndarray,
                  chains: _Chains) -> None:
    """Shade the rays whose first hit is on a mirror, glass or translucent material (§3, §5).

    Vectorised over those rays (only): at each hit one branch is chosen by importance from the
    material's weights (``materials.classify``) — diffuse: R = base colour (the weight cancels),
    ρ of the distance; translucent: R = ``settings.translucent``·R_ave, ρ = 1 (§3.3); specular:
    reflect, tint by the base colour; transparent: Fresnel reflection or refraction (§3.2).
    Reflected/refracted rays are cast from the hit (strategy "b": for what is left of d_max,
    ρ of the summed length; "a": d_max each, ρ of the first distance; "c": none, R_ave and
    ρ = 1). Chains end at a diffuse choice, a miss (escaped: weight R_ave·ρ), Russian roulette
    from bounce ``_ROULETTE_FROM`` on (survival min(0.95, max throughput), throughput divided by
    it: unbiased) or the hard cap ``settings.max_depth`` (nothing counted; ``chains.capped``).
    Escaped weights are scalar, the mean of the RGB throughput (× ρ); what each channel's
    throughput adds to it is summed per texel into ``chains.tint``.

    origins, directions: (k·rays, 3) float32 as cast; hits: their ``LocalHits``; keys: (k,)
    texel keys. Writes ``out`` (k·rays, 4): R·ρ (RGB) and escaped weight of each such ray.
    """
    m = surfaces.materials
    world = surfaces.world
    primitive = hits.triangle
    ray = np.flatnonzero(primitive >= 0)
    ray = ray[surfaces.kind[primitive[ray]] == _SPECIAL]
    if not len(ray):
        return
    unit = settings.rho in UNIT_REFLECTIVITY
    rho_kind, d_max = RHO_KINDS[settings.rho], float(settings.d_max)
    texel = ray // rays
    key, sample = keys[texel], first + ray % rays
    n = len(ray)
    value = np.zeros((n, 3))
    escaped = np.zeros((n, 3))  # each escaped ray's RGB throughput × ρ
    throughput = np.ones((n, 3))
    start = origins[ray].astype(np.float64)
    d = directions[ray].astype(np.float64)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tri = primitive[ray].astype(np.int64)
    dist = hits.distance[ray].astype(np.float64)
    bu, bv = hits.u[ray].astype(np.float64), hits.v[ray].astype(np.float64)
    first_dist = dist.copy()
    total = np.zeros(n)
    live = np.arange(n)
    for depth in range(settings.max_depth + 1):
        total[live] += dist[live]
        mat = world.tri_material[tri[live]]
        weights = m.weights[mat]
        dim = material_dimension(depth)  # + 0 branch, + 1 Fresnel, + 2 roulette
        u = _uniform(settings.seed, key[live], sample[live], dim)
        branch = (u[:, None] >= np.cumsum(weights, axis=1)[:, :3]).sum(axis=1)
        bary = np.stack([1.0 - bu[live] - bv[live], bu[live], bv[live]], axis=1)
        colour = (np.ones((len(live), 3)) if unit else
                  base_colour(surfaces.scene, world, tri[live], bary))
        measured = first_dist[live] if settings.specular == "a" else total[live]
        fade = _rho(rho_kind, measured / d_max)
        diffuse = branch == DIFFUSE
        value[live[diffuse]] = throughput[live[diffuse]] * colour[diffuse] * fade[diffuse, None]
        translucent = branch == TRANSLUCENT
        escaped[live[translucent]] = throughput[live[translucent]] * settings.translucent
        onward = (branch == SPECULAR) | (branch == TRANSPARENT)
        if settings.specular == "c":  # R_ave, ρ = 1, no ray
            escaped[live[onward]] = throughput[live[onward]]
            break
        live, mat, colour, branch = live[onward], mat[onward], colour[onward], branch[onward]
        if not len(live) or depth == settings.max_depth:
            chains.capped += np.bincount(texel[live], minlength=len(chains.capped))
            break
        normal = surfaces.normals[tri[live]]
        dirs = d[live]
        hit_point = start[live] + dist[live, None] * dirs
        specular = branch == SPECULAR
        new = _reflect(dirs, normal)
        tint = colour.copy()  # a mirror tints by its base colour (a metal's F0)
        glass = ~specular
        if glass.any():
            thin = m.thin[mat[glass]]
            bent, refracted = _refract(dirs[glass], normal[glass], m.ior[mat[glass]], thin,
                                       _uniform(settings.seed, key[live[glass]],
                                                sample[live[glass]], dim + 1))
            new[glass] = bent
            tint[glass] = np.where(refracted[:, None], colour[glass], 1.0)
        throughput[live] *= tint
        if depth + 1 >= _ROULETTE_FROM:
            survive = np.minimum(_SURVIVAL_CAP, throughput[live].max(axis=1))
            kept = _uniform(settings.seed, key[live], sample[live], dim + 2) < survive
            throughput[live[kept]] /= survive[kept, None]
            live, hit_point, new, normal = live[kept], hit_point[kept], new[kept], normal[kept]
        if not len(live):
            break
        side = np.where(np.einsum("ij,ij->i", new, normal) >= 0.0, 1.0, -1.0)
        lift = np.maximum(surfaces.step, 64 * 2.0 ** -23 * np.abs(hit_point).max(axis=1))
        start[live] = hit_point + (side * lift)[:, None] * normal
        d[live] = new
        length = d_max - total[live] if settings.specular == "b" else np.full(len(live), d_max)
        going = length > 0
        escaped[live[~going]] = throughput[live[~going]]  # past d_max: ρ = 1
        live = live[going]
        if not len(live):
            break
        sub = tracer.cast_local(start[live].astype(np.float32), d[live].astype(np.float32),
                                length[going].astype(np.float32))
        chains.rays += np.bincount(texel[live], minlength=len(chains.rays))
        hit = sub.triangle >= 0
        missed = live[~hit]
        fade = (_rho(rho_kind, first_dist[missed] / d_max) if settings.specular == "a"
                else np.ones(len(missed)))
        escaped[missed] = throughput[missed] * fade[:, None]
        live = live[hit]
        tri[live] = sub.triangle[hit]
        dist[live] = sub.distance[hit]
        bu[live], bv[live] = sub.u[hit], sub.v[hit]
    escape = escaped.mean(axis=1)
    out[ray, :3] = value
    out[ray, 3] = escape
    grid = grid_values(escaped - escape[:, None])
    for c in range(3):
        chains.tint[:, c] += np.bincount(texel, grid[:, c], minlength=len(chains.tint))


def _rho(kind: int, x: np.ndarray) -> np.ndarray:
    """ρ (k,) at x = d / d_max (k,), as ``obscurance.rho``."""
    x = np.clip(x, 0.0, 1.0)
    if kind == 0:
        return np.sqrt(x)
    if kind == 1:
        return x
    return np.zeros_like(x)


def hit_shading(surfaces: Surfaces, settings: Resolved, hits: LocalHits
                ) -> tuple[np.ndarray, np.ndarray]:
    """What ``accumulate_kernel`` needs to shade the rays with ``hits``: the
    triangles' kinds (T,) uint8 and ray_albedo, one row of 4 per ray (the albedo at hits on
    varying triangles; rows that ``_special_hits`` fills for special ones), or (0, 4) when
    neither occurs."""
    primitive = hits.triangle
    varying = surfaces.varying.any() and settings.rho not in UNIT_REFLECTIVITY
    if varying:
        ray_albedo = surfaces.varying_albedo(primitive, hits.u, hits.v)
    elif surfaces.special:
        ray_albedo = np.zeros((len(primitive), 4))
    else:
        ray_albedo = np.zeros((0, 4))
    kind = surfaces.kind if len(ray_albedo) else np.zeros_like(surfaces.kind)
    if not varying and len(ray_albedo):
        kind = np.where(kind == _VARYING, _CONSTANT, kind).astype(np.uint8)
    return kind, ray_albedo


def _chunk_sums(surfaces: Surfaces, tracer: Tracer, texels: Texels, rows: np.ndarray,
                first: int, rays: int, settings: Resolved) -> tuple[np.ndarray, _Chains]:
    """(k, 7) sums over samples ``first`` … ``first + rays − 1`` of the texels ``rows``, as
    ``accumulate_kernel`` lays them out, and the chunk's chain counts."""
    sub = (sub_positions(tracer, texels, rows, settings.supersample, settings.seed)
           if settings.supersample > 1 else None)
    origins, directions = hemisphere_rays(texels, rows, rays, settings.seed, tracer.center,
                                          settings.sampling, first, sub, settings.rays)
    lengths = np.full(len(origins), settings.d_max, np.float32)
    chains = _Chains(np.zeros(len(rows), np.int64), np.zeros(len(rows), np.int64),
                     np.zeros((len(rows), 3)))
    sums = np.zeros((len(rows), columns(settings.directional_pages)))
    aims = directions if settings.directional_pages else NO_DIRECTIONS
    if blocking_only(surfaces, settings):
        blocked = tracer.blocked_local(origins, directions, lengths)
        if settings.directional_pages:
            accumulate_kernel(rays, blocked, lengths, np.float32(settings.d_max),
                              RHO_KINDS[settings.rho], *_BLOCKER, LUMINANCE, sums,
                              *_TEXEL_MAJOR, 1.0, aims)
        else:
            _escapes_kernel(rays, blocked, sums)
        return sums, chains
    hits = tracer.cast_local(origins, directions, lengths)
    kind, ray_albedo = hit_shading(surfaces, settings, hits)
    if surfaces.special:
        _special_hits(surfaces, tracer, origins, directions, hits, texels.key[rows], first, rays,
                      settings, ray_albedo, chains)
    accumulate_kernel(rays, hits.triangle, hits.distance, np.float32(settings.d_max),
                      RHO_KINDS[settings.rho], surfaces.table, kind, ray_albedo, LUMINANCE,
                      sums, *_TEXEL_MAJOR, 1.0, aims)
    return sums, chains


# ``accumulate_kernel``'s (table, kind, ray_albedo) for rays whose primitive is
# ``Tracer.blocked_local``'s 0 (blocked) or −1: one triangle, constant, its albedo never read
# but × ρ = 0 (``blocking_only``).
_BLOCKER = (np.zeros((1, 3)), np.zeros(1, np.uint8), np.zeros((0, 4)))


@jit
def _escapes_kernel(rays, blocked, sums):
    """Add to ``sums`` (k, 7) what ``accumulate_kernel`` adds for rays laid out texel by
    texel that are only blocked (0) or not (−1) (``Tracer.blocked_local``, ``blocking_only``:
    an escaped ray's value is 1, a blocked one's R·ρ = 0): the escaped rays counted, over all
    and over the first half, and 0 to every other column. The same bits, without a branch
    per ray."""
    half = rays // 2
    for i in range(len(blocked) // rays):
        first = rest = 0
        for r in range(i * rays, i * rays + half):
            first += blocked[r] < 0
        for r in range(i * rays + half, (i + 1) * rays):
            rest += blocked[r] < 0
        sums[i, ESCAPED] += first + rest
        sums[i, _HALF_ESCAPED] += first


def blocking_only(surfaces: Surfaces, settings: Resolved) -> bool:
    """Whether a ray's value depends only on whether it meets something within d_max: with
    ``--rho step`` a hit's value is R·ρ = 0 whatever R and the distance, a miss's 1, unless
    a mirror, glass or translucent surface sends the ray on (``Surfaces.special``). Such rays
    are cast as occlusion queries (``Tracer.blocked_local``), the same sums as nearest hits
    give (for albedos that are finite: R·0 = 0)."""
    return settings.rho == "step" and not surfaces.special


def hemisphere_terms(context: Context, texels: Texels,
                     progress: Callable[[int, int], None] | None = None,
                     rows: np.ndarray | None = None,
                     error_scale: tuple[np.ndarray, float] | None = None,
                     surfaces: Surfaces | None = None,
                     targets: np.ndarray | None = None) -> Terms:
    """Estimate the obscurance terms of the texels ``rows`` (default: all), in that order,
    with the context's tracer and settings.

    Without ``settings.target_error`` every texel gets ``settings.rays`` rays. With it, rays come
    in rounds — ``rays``, then doubling each texel's count while it stays within ``max_rays``
    (counts are rays·2^k; with ``sobol`` a round grows the texel's two nets, so a texel with n
    rays has what a bake with n rays would: ``cosine_directions``) — and a texel stops once
    its neighbours' predicted error per ray over its own rays (``_stopping_error``) times
    ``adaptive.WITHIN`` is within the target: ``targets`` (one per row:
    ``adaptive.what_is_left``), by default ``settings.target_error``. The rounds are the same
    whatever the chunking, so the result is too (they depend on the rows asked for: the error
    model is pooled over them, and the neighbours are those among them). ``progress(texels,
    rays)`` is told after each chunk how many texels it finished (in the first round; 0 after)
    and the rays it cast, and ``progress(0, 0, coming)`` before a round the rays it will cast
    (``run.progress.Meter``).
    ``surfaces``: ``surfaces_of(context)``, made here when not given. Light through
    translucent surfaces is not in these terms: ``light.integrate.integrate`` adds it
    (``inner.add_translucency``, §4).
    """
    tracer, settings = context.tracer, context.settings
    rows = np.arange(len(texels)) if rows is None else np.asarray(rows, np.int64)
    surfaces = surfaces_of(context) if surfaces is None else surfaces
    sums = np.zeros((len(rows), columns(settings.directional_pages)))
    chaining = surfaces.special  # else no chain is counted: the counts stay empty
    chain_counts = np.zeros((len(rows) if chaining else 0, 2), np.int64)  # rays, capped chains
    tints = np.zeros((len(rows) if chaining else 0, 3))  # the escaped weights' tints, summed
    counts = np.zeros(len(rows), np.int64)
    errors = np.zeros(len(rows))  # each row's predicted error after its last round
    active = np.arange(len(rows))
    first, batch = 0, settings.rays
    while len(active):
        def work(chunk: np.ndarray, first=first, batch=batch) -> None:
            # Each batch's first half of rays is its share of the first net (or layer): the
            # summed halves stay two independent estimates (``Terms.split_errors``).
            round_sums, chains = _chunk_sums(surfaces, tracer, texels, rows[chunk], first, batch,
                                             settings)
            if chaining:
                chain_counts[chunk, 0] += chains.rays
                chain_counts[chunk, 1] += chains.capped
                tints[chunk] += chains.tint
            sums[chunk] += round_sums
            if progress is not None:
                progress(len(chunk) if first == 0 else 0, len(chunk) * batch)

        step = texels_per_chunk(settings.chunk_texels, batch)
        run_chunks(work, [active[rows] for rows in even_slices(len(active), step, 2 * cores())],
                   settings.threads)
        counts[active] += batch
        first += batch
        if settings.target_error is None or 2 * first > settings.max_rays:
            break
        going = terms_of_sums(sums[active], counts[active])
        errors[active] = predicted_error(going, error_scale, texels, rows[active])
        target = settings.target_error if targets is None else targets[active]
        active = active[WITHIN * _stopping_error(errors, counts, texels, rows, active) > target]
        batch = first
        if progress is not None and len(active):
            progress(0, 0, len(active) * batch)
    terms = terms_of_sums(sums, counts)
    if chaining:
        terms = replace(terms, chain_rays=chain_counts[:, 0], capped=chain_counts[:, 1],
                        escaped_tint=tints / np.maximum(counts, 1)[:, None])
    return terms


def predicted_error(terms: Terms, error_scale: tuple[np.ndarray, float] | None, texels: Texels,
                    rows: np.ndarray) -> np.ndarray:
    """(N,) the predicted error σ of each texel of ``terms``, the texels ``rows`` (N,) of
    ``texels``, in lightmap luminance (I_A·W),
    the quantity ``--target-error`` bounds (``adaptive.py``), from the texels' own rays
    (``texel_errors`` adds the neighbours').

    The rays' sample variance assumes independent rays and overstates a scrambled net's error
    4–8×; one texel's split (``Terms.split_errors``) is unbiased but has one degree of freedom.
    The prediction is the sample variance times the gain g = Σ split / Σ sample variance over
    the texels of like variance, by their neighbours' (the nets' measured advantage, pooled:
    ``adaptive.pooled_gain``; it depends on the rows, not on chunks).
    Where no ray escaped and all gave one value, ``binomial_floor`` (``standard_error``): the
    rays cannot tell a texel that is exact from one whose other value has p ≲ 1/n.
    error_scale: (R_ave (3,), lightmap luminance per unit W), default (1, 1).
    """
    r_ave, scale = _unit_or(error_scale)
    variance = terms._sample_variance(r_ave)
    iid = variance / np.maximum(terms.counts, 1)
    alike = terms._unseen(variance)
    split = terms.split_errors(r_ave)
    gain = pooled_gain(iid, split, ~alike, neighbours_among(texels, iid, rows))
    return np.where(alike, binomial_floor(terms.counts, r_ave), np.sqrt(gain * iid)) * scale


def _stopping_error(errors: np.ndarray, counts: np.ndarray, texels: Texels, rows: np.ndarray,
                    active: np.ndarray) -> np.ndarray:
    """(a,) the error σ that the texels ``active`` (a,) of ``rows`` (k,) stop by: sqrt(v / n),
    v the mean of errors² · counts (each texel's predicted variance per ray, (k,) both) over
    their neighbours among ``rows``, themselves left out, n their own counts.

    Stopped by its own prediction, a texel is chosen by its own rays: those whose first rays
    happened to agree stop, those that did not go on, their first rays' error still in their
    mean. Under a ceiling (ρ = sqrt, E = 0.004, a first round of 64) the texels that went to
    256 rays then had an RMSE 11 % above a uniform 256-ray bake's, 94.2 % within E against
    96.5 %; a texel stopped by its neighbours has its count's uniform error (as the direct
    light's and the GI paths' rounds do)."""
    about = np.zeros(len(rows), bool)
    about[active] = True
    per_ray = neighbours_among(texels, errors * errors * counts, rows, about)
    return np.sqrt(per_ray / np.maximum(counts[active], 1))


def texel_errors(terms: Terms, error_scale: tuple[np.ndarray, float] | None, texels: Texels,
                 rows: np.ndarray) -> np.ndarray:
    """(N,) ``predicted_error`` of ``terms``, the texels ``rows`` (N,) of ``texels``, with
    their neighbours' where a texel's rays all gave one value (``neighbours_error``)."""
    return neighbours_error(predicted_error(terms, error_scale, texels, rows), terms.counts,
                            terms.alike(_unit_or(error_scale)[0]), texels, rows)


def _unit_or(error_scale: tuple[np.ndarray, float] | None) -> tuple[np.ndarray, float]:
    """``error_scale`` (R_ave (3,), lightmap luminance per unit W), or (1, 1) without one."""
    return (np.ones(3), 1.0) if error_scale is None else error_scale


def neighbours_error(error: np.ndarray, counts: np.ndarray, blind: np.ndarray, texels: Texels,
                     rows: np.ndarray) -> np.ndarray:
    """(k,) ``error`` (k,) of the texels ``rows`` (k,) of ``texels``, at the ``blind`` ones
    (k,) bool at least σ = sqrt(v / n): v the mean of error² · count over their neighbours
    among ``rows`` (``adaptive.neighbour_mean``), n their own ``counts`` (k,).

    A texel whose rays all gave one value (``Terms.alike``) has no variance of its own to go
    by. Under a ceiling at 0.9 d_max one texel in 30 sees its 16 rays all escape; stopped by
    them it would be 0.19 off, its neighbours' rays say it is not settled. An open floor's
    texels, whose neighbours' rays all escape too, still stop."""
    if not blind.any():
        return error
    prior = neighbours_among(texels, error * error * counts, rows, blind)
    out = error.copy()
    out[blind] = np.maximum(error[blind], np.sqrt(prior / np.maximum(counts[blind], 1)))
    return out


def luminance_and_escaped(sums: np.ndarray) -> np.ndarray:
    """(k, 2) summed luminance of R·ρ and escaped rays, from sums (k, 7)."""
    return np.column_stack([luminance(sums[:, RGB]), sums[:, ESCAPED]])


def _split(part: np.ndarray, part_count: np.ndarray, whole: np.ndarray,
           whole_count: np.ndarray) -> np.ndarray:
    """(k, 2) mean over a first part of the rays minus the mean over the rest of ``whole``."""
    rest = np.maximum(whole_count - part_count, 1)[:, None]
    split = part / np.maximum(part_count, 1)[:, None] - (whole - part) / rest
    return np.where((part_count >= 1)[:, None] & (whole_count > part_count)[:, None], split, 0.0)


_MEAN_ROWS = 1 << 16  # texels ``terms_of_sums`` works on at once


def terms_of_sums(sums: np.ndarray, counts: np.ndarray) -> Terms:
    """Terms from per-texel sums (k, 7 or ``_AIM_COLUMNS``) over ``counts`` (k,) rays, ``_MEAN_ROWS`` rows at a time
    (the split's temporaries for every texel at once would be larger than the terms)."""
    means = np.empty((len(counts), HALF.start))
    first_half = np.empty((len(counts), 2))
    aimed = sums.shape[1] == _AIM_COLUMNS
    aims = np.empty((len(counts) if aimed else 0, 6))
    aim_split = np.empty((len(counts) if aimed else 0, 6))
    for start in range(0, len(counts), _MEAN_ROWS):
        rows = slice(start, start + _MEAN_ROWS)
        part, count = sums[rows], counts[rows]
        means[rows] = part[:, :HALF.start] / np.maximum(count, 1)[:, None]
        first_half[rows] = _split(part[:, HALF], count // 2, luminance_and_escaped(part),
                                  count)
        if aimed:
            aims[rows] = part[:, _AIM] / np.maximum(count, 1)[:, None]
            aim_split[rows] = _split(part[:, _AIM_HALF], count // 2, part[:, _AIM], count)
    return Terms(w_hit=means[:, RGB], escaped=means[:, ESCAPED], hit_sq=means[:, SQUARE],
                 counts=counts, half_split=first_half, aim_hit=aims[:, :3],
                 aim_escaped=aims[:, 3:], aim_split=aim_split)
