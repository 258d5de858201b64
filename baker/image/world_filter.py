"""A world-space smoothing of per-texel estimates, its width chosen by its own estimated error.

The per-chart denoiser (``denoise.py``) cannot help a chart of a few texels: it sees nothing
around it. Here a texel's neighbours are the texels near it in the world, whatever chart or
instance they belong to: those within ``REACH`` widths of its position, on its side of its
plane (within ``PLANE`` texel sides of it) and facing within ``FACING`` of its normal, so no
light crosses a crease, a wall or a gap between objects. Each texel's value becomes the
Gaussian-weighted mean of its neighbours' (itself included): a linear filter ``F`` whose
weights depend on the geometry alone.

For a linear filter of noisy values y = x + n (independent noise of variance σ²ᵢ per texel),
Stein's unbiased risk estimate of the filtered texel's squared error is

    SURE_i = ((F y)_i − y_i)² + (2 F_ii − 1) σ²_i

(E[SURE_i] = E[((F y)_i − x_i)²]: the squared bias and the filtered noise together). With σ²_i
replaced by an unbiased estimate from the texel's own rays (e², e half the difference of its
two independent halves' means; not ``hemisphere.Terms.split_errors``, whose floor for texels
whose rays all agree is no unbiased estimate: SURE subtracts it), the mean of SURE over the
texels estimates the filtered map's mean squared error without knowing x. But that mean is a
difference of two sums of the size of the raw noise: where smoothing leaves far less error than
the noise (a wide width on a smooth wall at few rays), its own noise is as large as what it
measures, and the least of several such means is low by chance. So each width is judged by an
upper bound, the mean SURE plus ``BOUND`` of its standard errors (from the spread of the
texels' SURE), and the width (in texel sides, one for the whole map) is the one of ``WIDTHS``
whose bound is least (the wider ``STAGES`` tried only when the narrower's widest is), judged on
every k-th texel (``PROBES`` at most: the search's cost); the chosen width is then applied to
every texel, and the same bound over all of them is the estimate of the filtered map's mean
squared error (``Filtered.error``, the bake's ``rmse_estimate`` with ``--smooth``). Width 0
leaves the values as they are (its SURE is σ², today's estimate, taken as it is), so the filter
is used only where even its bound is lower. ``smooth_pages`` applies it to a bake's composed
pages (``--smooth``, docs/denoise.md). Stein, "Estimation of the mean of a multivariate
normal distribution" (1981); Li, Wu and Chuang, "SURE-based optimization for adaptive sampling
and reconstruction" (2012).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from baker.atlas.rasterise import Texels, flat_pages
from baker.geometry.surface import luminance
from baker.image.compose import Lightmaps
from baker.jit import jit
from baker.run.parallel import cores, even_slices, run_chunks

STAGES = ((0.0, 0.5, 0.75, 1.0, 1.5), (2.0, 3.0))  # Gaussian σ tried, texel sides: a
# neighbour search costs as the square of the widest, so the wider are tried only when needed
WIDTHS = sum(STAGES, ())
REACH = 2.0  # neighbours within this many σ
PLANE = 0.5  # texel sides: a neighbour off the texel's plane by more is not on its surface
FACING = 0.9  # least cosine between the two texels' normals
BOUND = 2.0  # standard errors of the mean SURE added to it (``Filtered.error``)
_CHUNK = 1 << 14  # texels per work unit
# Texels at most whose SURE picks the width (``smooth``): 32,768 picked the same width as
# 131,072 in 12 of 12 bakes (the Cornell room and the boxes at 4, 16, 64 rays, two seeds, a
# 1024 page), at 0.1-0.3 s less; 16,384 once picked another.
PROBES = 1 << 15


@dataclass(frozen=True)
class Filtered:
    """values: (N, C) the filtered values (the input itself at width 0); width: the width
    chosen, texel sides; sure: (N,) each texel's SURE at that width; bound_by_width: the
    upper bound (mean SURE + ``BOUND`` standard errors; at width 0 the mean of σ²) of every
    width tried."""

    values: np.ndarray
    width: float
    sure: np.ndarray
    bound_by_width: dict[float, float]
    bound: float

    @property
    def error(self) -> float:
        """The estimated RMSE of ``values``: √ of ``bound``, the mean of ``sure`` over every
        texel plus ``BOUND`` of its standard errors."""
        return float(np.sqrt(max(self.bound, 0.0)))


def smooth(position: np.ndarray, normal: np.ndarray, size: np.ndarray, values: np.ndarray,
           luminance: np.ndarray, variance: np.ndarray) -> Filtered:
    """The values (N, C) of texels at world ``position`` (N, 3) with unit ``normal`` (N, 3) and
    side ``size`` (N,) (world units), smoothed at the width of least bound on its mean SURE.

    luminance: (N,) what the error is measured in (the values' luminance, or the values
    themselves for one channel); variance: (N,) an unbiased estimate of each texel's noise
    variance in those units (independent between texels). The widths are judged on every
    k-th texel (``PROBES`` of them at most, their neighbours all texels), then the chosen one
    applied to every texel and its SURE computed for every texel: the figure reported
    (``Filtered.error``) is not the one the width was picked by."""
    count = len(position)
    probe = np.full(count, -1, np.int64)
    probes = np.arange(0, count, max(1, -(-count // PROBES)))
    probe[probes] = np.arange(len(probes))
    tried = {}
    for stage in STAGES:  # the wider stage only when the narrower's widest was best
        widths = np.array(stage)
        grid = _grid(position, size, float(widths.max()))
        smoothed, self_weight = _apply(position, normal, size, luminance[:, None], widths, grid,
                                       probe, len(probes))
        for w, mean, weight in zip(stage, smoothed[:, :, 0], self_weight):
            tried[w] = _bound(_sure(mean, weight, luminance[probes], variance[probes]), w)
        width = min(tried, key=lambda w: (tried[w], w))
        if width < max(stage):
            break
    if width == 0.0:
        return Filtered(values, width, variance, tried, _bound(variance, width))
    grid = _grid(position, size, width)  # cells as small as the width allows
    smoothed, self_weight = _apply(position, normal, size, np.hstack([values, luminance[:, None]]),
                                   np.array([width]), grid, np.arange(count), count)
    sure = _sure(smoothed[0, :, -1], self_weight[0], luminance, variance)
    return Filtered(smoothed[0, :, :-1], width, sure, tried, _bound(sure, width))


def _sure(smoothed: np.ndarray, self_weight: np.ndarray, raw: np.ndarray,
          variance: np.ndarray) -> np.ndarray:
    """(k,) Stein's unbiased risk estimate of each texel's ``smoothed`` value (k,), from its
    ``raw`` value, its weight in its own mean (F_ii) and its noise's ``variance``."""
    return (smoothed - raw) ** 2 + (2.0 * self_weight - 1.0) * variance


@dataclass(frozen=True)
class Smoothed:
    """What ``smooth_pages`` did, for the report and the error estimates.

    width: the width chosen, texel sides (0: the light left as composed); sure: (N,) each
    baked texel's Stein risk estimate of its smoothed luminance at that width, lightmap
    units² (a texel the filter does not see — invalid, enclosed — its own variance as given:
    what ``errormap`` pools); error: the estimated RMSE of the smoothed luminance over the
    texels it saw (``Filtered.error``: the mean SURE plus ``BOUND`` standard errors); raw: the
    estimated RMSE before (√ of the mean variance); tried: each width tried → √ of the bound
    it was judged by (``Filtered.bound_by_width``); texels: the texels it saw; seconds: its
    wall time."""

    width: float
    sure: np.ndarray
    error: float
    raw: float
    tried: dict[float, float]
    texels: int
    seconds: float

    def as_dict(self) -> dict:
        """JSON-able, for the report's ``smooth`` entry."""
        return {"smoothed": True, "width_texels": self.width, "rmse_before": self.raw,
                "rmse_after": self.error,
                "rmse_bound_by_width": {f"{w:g}": bound for w, bound in self.tried.items()},
                "texels": self.texels, "seconds": self.seconds}


def smooth_pages(lightmaps: Lightmaps, texels: Texels, variance: np.ndarray,
                 exact: np.ndarray, invalid: np.ndarray,
                 enclosed: np.ndarray) -> tuple[Lightmaps, Smoothed]:
    """``lightmaps`` (composed, before post-processing) with the light of their valid texels
    smoothed in world space (``smooth``, the width of least bound on the error of its
    luminance) but for its ``exact`` part, and their visibility, when kept, at that same width.

    texels: the baked texels (N); variance: (N,) an unbiased estimate of each one's noise
    variance in luminance (``errormap.light_variance`` without its floor); exact: (N, 3) the
    part of each texel's light that has no noise (``Sources.exact``: the hard lights', whose
    shadow edges smoothing would only blur; the rest is smoothed, and its blur alone counted
    in the width's risk); invalid, enclosed:
    (P, H, W) bool masks (``validity.Validity.page_masks``): those texels neither feed
    the filter nor take its output (the post-process fills them from their valid neighbours,
    as it does after ``denoise``)."""
    started = time.perf_counter()
    pixels = texels.pixel_index()
    rows = np.flatnonzero(~(flat_pages(invalid)[pixels] | flat_pages(enclosed)[pixels]))
    index = pixels[rows]
    exact_part = exact[rows]
    light = flat_pages(lightmaps.light)[index] - exact_part
    kept = len(lightmaps.visibility) > 0  # grey: one channel of it smoothed, then copied
    values = np.hstack([light, flat_pages(lightmaps.visibility)[index][:, :1]]) if kept else light
    seen = variance[rows]
    done = smooth(texels.position[rows], texels.geometric_normal(rows), texels.size(rows),
                  values, luminance(light), seen)
    sure = variance.copy()
    sure[rows] = done.sure
    out = lightmaps
    if done.width > 0.0:
        out = replace(out, light=_written(lightmaps.light, index,
                                          done.values[:, :3] + exact_part))
        if kept:
            out = replace(out, visibility=_written(lightmaps.visibility, index,
                                                   np.repeat(done.values[:, 3:], 3, axis=1)))
    raw = float(np.sqrt(seen.mean())) if len(seen) else 0.0
    tried = {w: float(np.sqrt(max(bound, 0.0))) for w, bound in done.bound_by_width.items()}
    return out, Smoothed(done.width, sure, done.error, raw, tried, len(rows),
                         time.perf_counter() - started)


def _written(pages: np.ndarray, index: np.ndarray, values: np.ndarray) -> np.ndarray:
    """A copy of ``pages`` (P, H, W, C) with ``values`` (k, C) at the pixels ``index`` (k,)."""
    out = pages.copy()
    flat_pages(out)[index] = values
    return out


def _bound(sure: np.ndarray, width: float) -> float:
    """The mean of ``sure`` (N,) plus ``BOUND`` standard errors of it; at width 0 the mean."""
    if not len(sure):
        return 0.0
    spread = 0.0 if width == 0.0 else BOUND * float(sure.std()) / np.sqrt(len(sure))
    return float(sure.mean()) + spread


def _grid(position: np.ndarray, size: np.ndarray, width: float
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The texels sorted by grid cell, for a filter ``width`` texel sides wide: (order (N,),
    starts (M + 1,) of each occupied cell's run in ``order``, cells (M, 3) int64 those cells'
    coordinates, sorted, and the cells' side). The side is ``REACH`` × ``width`` × the 99th
    percentile of the texels' sizes: the 27 cells about a texel hold all it reaches but for the
    largest 1 % (a chart of few texels grows its texels: on LightsPunctualLamp the largest is
    2.9× the median, and cells sized for it held 8× the candidates), which look further
    (``_filter_kernel``)."""
    cell = REACH * width * float(np.percentile(size, 99)) if len(size) else 0.0
    cell = cell if cell > 0 else 1.0  # texels of no size: every neighbour in one cell's reach
    coords = np.floor(position / cell).astype(np.int64)
    order = np.lexsort((coords[:, 2], coords[:, 1], coords[:, 0]))
    sorted_coords = coords[order]
    new = np.ones(len(order), bool)
    new[1:] = (sorted_coords[1:] != sorted_coords[:-1]).any(axis=1)
    first = np.flatnonzero(new)
    return order, np.append(first, len(order)), sorted_coords[first], cell


def _apply(position, normal, size, values, widths, grid, slot, slots):
    """(F values (W, K, C), F_ii (W, K)) of the filter at each of ``widths`` (W,) texel sides
    (width 0: the values themselves) for the texels i whose ``slot`` (N,) is ≥ 0, in row
    slot[i] of K = ``slots``, from one search for their neighbours (every texel) in ``grid``
    (``_grid``'s for the widest width), a run of cells at a time (each cell's 27 neighbour
    cells looked up once for all its texels)."""
    order, starts, cells, cell = grid
    out = np.empty((len(widths), slots, values.shape[1]))
    self_weight = np.empty((len(widths), slots))
    values, widths = np.ascontiguousarray(values, np.float64), np.asarray(widths, np.float64)
    per_cell = max(1, _CHUNK * len(cells) // max(len(position), 1))

    def work(run: slice) -> None:
        _filter_kernel(position, normal, size, values, widths, REACH, PLANE, FACING, order,
                       starts, cells, cell, slot, run.start, run.stop, out, self_weight)

    run_chunks(work, even_slices(len(cells), per_cell, 2 * cores()))
    return out, self_weight


@jit
def _find_cell(cells, x, y, z):
    """Index of cell (x, y, z) in the sorted (M, 3) ``cells``, −1 if it holds no texel."""
    lo, hi = 0, len(cells)
    while lo < hi:
        mid = (lo + hi) // 2
        cx, cy, cz = cells[mid, 0], cells[mid, 1], cells[mid, 2]
        if cx < x or (cx == x and (cy < y or (cy == y and cz < z))):
            lo = mid + 1
        else:
            hi = mid
    if lo < len(cells) and cells[lo, 0] == x and cells[lo, 1] == y and cells[lo, 2] == z:
        return lo
    return -1


@jit
def _cells_about(cells, c, span, into):
    """The indices of the occupied cells within ``span`` cells each way of cell ``c`` (dx, dy,
    dz from −span to span, in that nesting) written to ``into``; how many."""
    found = 0
    for dx in range(-span, span + 1):
        for dy in range(-span, span + 1):
            for dz in range(-span, span + 1):
                other = _find_cell(cells, cells[c, 0] + dx, cells[c, 1] + dy, cells[c, 2] + dz)
                if other >= 0:
                    into[found] = other
                    found += 1
    return found


@jit
def _filter_kernel(position, normal, size, values, widths, reach, plane, facing, order, starts,
                   cells, cell, slot, first, last, out, self_weight):
    """For every texel i of the cells ``first`` … ``last`` − 1 with s = slot[i] ≥ 0 and width
    σ_w = widths[w] × size[i]: out[w, s] = Σ_j w_ij values[j] / Σ_j w_ij over its neighbours
    j (the texels within ``reach`` σ_w, within ``plane`` texel sides of i's plane, normals
    within ``facing``: found in the 27 grid cells of side ``cell`` about its own, or as many
    more cells each way as its reach needs), w_ij = exp(−d²/2σ_w²), w_ii = 1;
    self_weight[w, s] = 1 / Σ_j w_ij. Width 0: values[i], 1. Each texel's sums run over the
    same neighbours in the same order however the cells are split into runs."""
    channels = values.shape[1]
    count = len(widths)
    total = np.empty((count, channels))
    weights = np.empty(count)
    around = np.empty(27, np.int64)
    widest = 0.0
    for w in range(count):
        widest = max(widest, widths[w])
    for c in range(first, last):
        near = _cells_about(cells, c, 1, around)
        for t in range(starts[c], starts[c + 1]):
            i = order[t]
            s = slot[i]
            if s < 0:
                continue
            px, py, pz = position[i, 0], position[i, 1], position[i, 2]
            nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
            limit = (reach * widest * size[i]) ** 2
            off_plane = plane * size[i]
            span = max(1, int(np.ceil(np.sqrt(limit) / cell)))  # cells each way it reaches
            visit, found = around, near
            if span > 1:  # a texel larger than the cells were sized for
                visit = np.empty((2 * span + 1) ** 3, np.int64)
                found = _cells_about(cells, c, span, visit)
            total[:] = 0.0
            weights[:] = 0.0
            for a in range(found):
                for k in range(starts[visit[a]], starts[visit[a] + 1]):
                    j = order[k]
                    ex, ey, ez = position[j, 0] - px, position[j, 1] - py, position[j, 2] - pz
                    d2 = ex * ex + ey * ey + ez * ez
                    if d2 > limit or abs(ex * nx + ey * ny + ez * nz) > off_plane:
                        continue
                    if normal[j, 0] * nx + normal[j, 1] * ny + normal[j, 2] * nz < facing:
                        continue
                    for w in range(count):
                        sigma = widths[w] * size[i]
                        if sigma == 0.0 or d2 > (reach * sigma) ** 2:
                            continue
                        weight = np.exp(-0.5 * d2 / (sigma * sigma))
                        weights[w] += weight
                        for ch in range(channels):
                            total[w, ch] += weight * values[j, ch]
            for w in range(count):
                if weights[w] == 0.0:  # width 0, or no normal (a texel of no area): as it is
                    weights[w] = 1.0
                    for ch in range(channels):
                        total[w, ch] = values[i, ch]
                for ch in range(channels):
                    out[w, s, ch] = total[w, ch] / weights[w]
                self_weight[w, s] = 1.0 / weights[w]
