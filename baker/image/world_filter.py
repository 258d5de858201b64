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
whose bound is least (the wider ``STAGES`` tried only when the narrower's widest is); that
bound is the estimate of the filtered map's mean squared error (``Filtered.error``). Width 0
leaves the values as they are (its SURE is σ², today's estimate, taken as it is), so the filter
is used only where even its bound is lower. Stein, "Estimation of the mean of a multivariate
normal distribution" (1981); Li, Wu and Chuang, "SURE-based optimization for adaptive sampling
and reconstruction" (2012).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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

    @property
    def error(self) -> float:
        """The estimated RMSE of ``values``: √ of the chosen width's bound."""
        return float(np.sqrt(max(self.bound_by_width[self.width], 0.0)))


def smooth(position: np.ndarray, normal: np.ndarray, size: np.ndarray, values: np.ndarray,
           luminance: np.ndarray, variance: np.ndarray) -> Filtered:
    """The values (N, C) of texels at world ``position`` (N, 3) with unit ``normal`` (N, 3) and
    side ``size`` (N,) (world units), smoothed at the width of least mean SURE.

    luminance: (N,) what the error is measured in (the values' luminance, or the values
    themselves for one channel); variance: (N,) an unbiased estimate of each texel's noise
    variance in those units (independent between texels)."""
    tried, sures = {}, {}
    for stage in STAGES:  # the wider stage only when the narrower's widest was best
        widths = np.array(stage)
        grid = _grid(position, REACH * float(widths.max()) * float(size.max())
                     if len(size) else 1.0)
        smoothed, self_weight = _apply(position, normal, size, luminance[:, None], widths, grid)
        for w, mean, weight in zip(stage, smoothed[:, :, 0], self_weight):
            sures[w] = (mean - luminance) ** 2 + (2.0 * weight - 1.0) * variance
            tried[w] = _bound(sures[w], w)
        width = min(tried, key=lambda w: (tried[w], w))
        if width < max(stage):
            break
    out = values if width == 0.0 else _apply(position, normal, size, values,
                                             np.array([width]), grid)[0][0]
    return Filtered(out, width, sures[width], tried)


def _bound(sure: np.ndarray, width: float) -> float:
    """The mean of ``sure`` (N,) plus ``BOUND`` standard errors of it; at width 0 the mean."""
    if not len(sure):
        return 0.0
    spread = 0.0 if width == 0.0 else BOUND * float(sure.std()) / np.sqrt(len(sure))
    return float(sure.mean()) + spread


def _grid(position: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The texels sorted by grid cell of side ``cell``: (order (N,), starts (M + 1,) of each
    occupied cell's run in ``order``, cells (M, 3) int64 those cells' coordinates, sorted,
    and ``cell``)."""
    coords = np.floor(position / cell).astype(np.int64)
    order = np.lexsort((coords[:, 2], coords[:, 1], coords[:, 0]))
    sorted_coords = coords[order]
    new = np.ones(len(order), bool)
    new[1:] = (sorted_coords[1:] != sorted_coords[:-1]).any(axis=1)
    first = np.flatnonzero(new)
    return order, np.append(first, len(order)), sorted_coords[first], cell


def _apply(position, normal, size, values, widths, grid):
    """(F values (W, N, C), F_ii (W, N)) of the filter at each of ``widths`` (W,) texel sides
    (width 0: the values themselves), from one search for every texel's neighbours in
    ``grid`` (``_grid``'s, cells of at least ``REACH`` × the widest width)."""
    order, starts, cells, cell = grid
    out = np.empty((len(widths), len(position), values.shape[1]))
    self_weight = np.empty((len(widths), len(position)))
    values, widths = np.ascontiguousarray(values, np.float64), np.asarray(widths, np.float64)

    def work(rows: slice) -> None:
        _filter_kernel(position, normal, size, values, widths, REACH, PLANE, FACING, order,
                       starts, cells, cell, rows.start, rows.stop, out, self_weight)

    run_chunks(work, even_slices(len(position), _CHUNK, 2 * cores()))
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
def _filter_kernel(position, normal, size, values, widths, reach, plane, facing, order, starts,
                   cells, cell, first, last, out, self_weight):
    """For every texel i of ``first`` … ``last`` − 1 and width σ_w = widths[w] × size[i]:
    out[w, i] = Σ_j w_ij values[j] / Σ_j w_ij over its neighbours j (the texels of the 27 grid
    cells around it within ``reach`` σ_w, within ``plane`` texel sides of i's plane, normals
    within ``facing``), w_ij = exp(−d²/2σ_w²), w_ii = 1; self_weight[w, i] = 1 / Σ_j w_ij.
    Width 0: values[i], 1."""
    channels = values.shape[1]
    count = len(widths)
    total = np.empty((count, channels))
    weights = np.empty(count)
    widest = 0.0
    for w in range(count):
        widest = max(widest, widths[w])
    for i in range(first, last):
        px, py, pz = position[i, 0], position[i, 1], position[i, 2]
        nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
        limit = (reach * widest * size[i]) ** 2
        off_plane = plane * size[i]
        gx, gy, gz = np.floor(px / cell), np.floor(py / cell), np.floor(pz / cell)
        total[:] = 0.0
        weights[:] = 0.0
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for dz in range(-1, 2):
                    c = _find_cell(cells, np.int64(gx) + dx, np.int64(gy) + dy,
                                   np.int64(gz) + dz)
                    if c < 0:
                        continue
                    for k in range(starts[c], starts[c + 1]):
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
                out[w, i, ch] = total[w, ch] / weights[w]
            self_weight[w, i] = 1.0 / weights[w]
