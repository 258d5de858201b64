"""Seams: make both sides of a UV seam show the same light.

An edge that is one edge in 3D but two in the atlas (xatlas cut the surface there into two
charts, or the mesh's own UV seam) is drawn twice, each side reading its own chart with bilinear
filtering. Baked independently (and with noise), the two sides disagree and the seam shows as a
line. This module finds those edges and solves, in the linear least squares sense, for texel
values that make the bilinear lookups on both sides agree at samples along every seam edge,
while staying close to the baked values ("Fixing texture seams with linear least squares",
Sloan & al.; the ands/seamoptimizer approach):

    minimise  Σ_samples (bilinear_A(x) − bilinear_B(x))²  +  Σ_texels λ_i (x_i − x0_i)²

λ is ``DATA_WEIGHT`` for covered texels and ``PADDING_WEIGHT`` for the padding texels the
lookups also read (their values are only dilated filler). The normal equations are solved by
conjugate gradients preconditioned by their diagonal, in one compiled kernel: no scipy needed.

Only *smooth* seams are stitched: both sides must have the same shading normals at the edge's
ends. At a crease (a box's edge) the light really differs on either side; blending it would
blur a true edge. Seams are found within each instance (an object) and between instances that
touch along a whole edge (two floor tiles side by side): an edge of one whose two end points
are those of an edge of the other, smooth across, is a seam like any other. Objects that touch
only partly (a T-junction: one long edge against two short ones) or where more than two
triangles meet at an edge are left apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from baker.atlas.layout import Atlas
from baker.geometry.rows import joined_roots
from baker.geometry.world import World
from baker.jit import inline, jit
from baker.run.parallel import run_chunks

DATA_WEIGHT = 0.02  # λ of a covered texel: how strongly it keeps its baked value
PADDING_WEIGHT = 0.002  # λ of a padding texel the seam lookups read
SAMPLES_PER_TEXEL = 2  # seam samples per texel of edge length (on the longer side)
_SMOOTH_COS = 0.999  # shading normals this close count as the same (about 2.6°)
_ITERATIONS = 100  # the most a piece of the seams takes (``_solve``); most converge in far fewer
_RUNS = 16  # runs of pieces dealt to the threads


@dataclass(frozen=True)
class Seams:
    """S sample points along the seam edges of an atlas, each seen from both sides.

    page_a, page_b: (S,) int64 page of each side. uv_a, uv_b: (S, 2) float64 glTF UVs of the
    same 3D point in side A's and side B's chart. edges: how many seam edges were found.
    """

    page_a: np.ndarray
    uv_a: np.ndarray
    page_b: np.ndarray
    uv_b: np.ndarray
    edges: int

    def __len__(self) -> int:
        return len(self.page_a)


def _empty() -> Seams:
    z = np.zeros(0, np.int64)
    return Seams(z, np.zeros((0, 2)), z, np.zeros((0, 2)), 0)


def find_seams(atlas: Atlas, world: World) -> Seams:
    """Every smooth seam edge of the baked instances, sampled ``SAMPLES_PER_TEXEL`` per texel:
    within each instance, and between instances that touch along a whole edge."""
    baked = [u for u in atlas.instances if len(world.instance_triangles(u.instance))]
    if not baked:
        return _empty()
    tris = np.concatenate([world.instance_triangles(u.instance) for u in baked])
    uv = np.concatenate([u.uv[u.triangles] for u in baked])  # (m, 3, 2), world corner order
    page = np.concatenate([u.pages for u in baked])
    ta, tb, lo_a, hi_a, lo_b, hi_b = _cut_edges(*_shared_edges(world, tris), uv, page)
    uv_a0, uv_a1 = uv[ta, lo_a], uv[ta, hi_a]
    uv_b0, uv_b1 = uv[tb, lo_b], uv[tb, hi_b]
    vertices = world.triangles[tris]  # (m, 3) world vertex ids
    ends = [vertices[t, corner] for t, corner in ((ta, lo_a), (tb, lo_b), (ta, hi_a), (tb, hi_b))]
    normal = [world.normals[v] for v in ends]  # (k, 3) each: A's and B's at either end
    same_normals = ((np.einsum("ij,ij->i", normal[0], normal[1]) > _SMOOTH_COS)
                    & (np.einsum("ij,ij->i", normal[2], normal[3]) > _SMOOTH_COS))
    is_smooth = np.logical_and.reduce([world.smooth[v] for v in ends])
    seam = same_normals & is_smooth
    if not seam.any():
        return _empty()
    uv_a0, uv_a1, uv_b0, uv_b1 = uv_a0[seam], uv_a1[seam], uv_b0[seam], uv_b1[seam]
    ta, tb = ta[seam], tb[seam]
    scale = np.array([atlas.width, atlas.height], np.float64)
    length = np.maximum(np.linalg.norm((uv_a1 - uv_a0) * scale, axis=1),
                        np.linalg.norm((uv_b1 - uv_b0) * scale, axis=1))
    count = np.maximum(2, np.ceil(length * SAMPLES_PER_TEXEL)).astype(np.int64)
    edge = np.repeat(np.arange(len(count)), count)
    start = np.cumsum(count) - count
    t = (((np.arange(count.sum()) - start[edge]) + 0.5) / count[edge])[:, None]
    return Seams(page[ta][edge], uv_a0[edge] + t * (uv_a1 - uv_a0)[edge], page[tb][edge],
                 uv_b0[edge] + t * (uv_b1 - uv_b0)[edge], len(count))


def _shared_edges(world: World, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The corners of triangles ``tris`` (m,) (world triangle ids) as points in 3D, as
    ``_cut_edges`` takes them: (m, 3) each corner's point, a row of (p, 3) int64 quantised
    positions; corners at the same point share its row, whichever instance each belongs to.

    Same 3D point ⇔ same position rounded to 1e-7 of the largest coordinate (meshes split
    vertices at their own seams; touching objects have vertices of their own)."""
    corners = world.triangles[tris]  # (m, 3) world vertex ids
    used = np.zeros(len(world.positions), bool)
    used[corners.ravel()] = True  # each vertex once (np.unique's, without its sort)
    points = world.positions[used]
    extent = max(float(np.abs(points).max()), 1e-30)
    quantised = np.round(points / (extent * 1e-7)).astype(np.int64)
    row = _point_rows(quantised)
    return row[(np.cumsum(used) - 1)[corners]], quantised


def _cut_edges(point: np.ndarray, quantised: np.ndarray, uv: np.ndarray, page: np.ndarray
               ) -> tuple[np.ndarray, ...]:
    """The edges that exactly two triangles share in 3D (corners at points ``point`` (m, 3),
    rows of ``quantised`` (p, 3): ``_shared_edges``) and that the atlas cuts: both triangles
    placed (``page`` (m,) ≥ 0) and on two pages, or an end point at UVs (``uv`` (m, 3, 2))
    more than 1e-9 apart on the two sides. An edge used by three or more triangles (a fin, two
    objects overlapping) is left out. Edge 3t + c of triangle t runs from its corner c to
    corner c + 1 mod 3. Returns, per edge, the two triangles (a: the one whose edge comes
    first) and the corners (0–2) of its lower and higher end point in each (lo_a, hi_a, lo_b,
    hi_b; lower: the lexicographically smaller quantised position), ends matched whatever the
    windings; the edges in the order of their end points (lower, then higher)."""
    found = _shared_pairs(point, quantised, uv, page)
    ta, tb, lo_a, hi_a = found[0], found[1], found[2], found[3]
    low, high = quantised[point[ta, lo_a]], quantised[point[ta, hi_a]]
    order = np.lexsort((high[:, 2], high[:, 1], high[:, 0], low[:, 2], low[:, 1], low[:, 0]))
    return tuple(found[:, order])


@inline
def _hashed(x: int, y: int, z: int, size: int) -> int:
    """A slot of a table of ``size`` for the integers (x, y, z) (multiplicative hashing)."""
    h = x * 0x1E3779B97F4A7C15 + y * 0x632BE59BD9B4E019 + z * 0x05EBCA77C2B2AE63
    return ((h ^ (h >> 29)) & 0x7FFFFFFFFFFFFFFF) % size


@jit
def _point_rows(quantised: np.ndarray) -> np.ndarray:
    """(p,) for each row of ``quantised`` (p, 3) int64 the first row equal to it: the same
    value for the same point (a hash table of the rows, in one pass)."""
    size = 2 * len(quantised) + 1
    table = np.full(size, -1, np.int64)
    first = np.empty(len(quantised), np.int64)
    for i in range(len(quantised)):
        x, y, z = quantised[i, 0], quantised[i, 1], quantised[i, 2]
        h = _hashed(x, y, z, size)
        while True:
            r = table[h]
            if r < 0:
                table[h] = i
                first[i] = i
                break
            if quantised[r, 0] == x and quantised[r, 1] == y and quantised[r, 2] == z:
                first[i] = r
                break
            h = h + 1 if h + 1 < size else 0
    return first


@jit
def _shared_pairs(point: np.ndarray, quantised: np.ndarray, uv: np.ndarray, page: np.ndarray
                  ) -> np.ndarray:
    """``_cut_edges``' edges in no particular order, (6, k): ta, tb, lo_a, hi_a, lo_b, hi_b.
    The 3m edges are bucketed by their lower end point's row (a counting sort) and each
    bucket sorted by the higher end's (insertion sort; numpy's merge sort for a bucket past
    ``_SMALL_BUCKET``: a fan's apex): a sort of all the edges' keys, the points' ranks by a sort
    and a pass in key order took 0.7 s of a level of a million triangles."""
    n, rows = 3 * len(point), len(quantised)
    start = np.zeros(rows + 1, np.int64)
    for e in range(n):
        start[_low_end(point, e) + 1] += 1
    for r in range(rows):
        start[r + 1] += start[r]
    edges, fill = np.empty(n, np.int64), start[:-1].copy()
    for e in range(n):  # each bucket's edges in increasing order
        r = _low_end(point, e)
        edges[fill[r]] = e
        fill[r] += 1
    found = np.empty((6, n // 2), np.int64)
    k = 0
    for r in range(rows):
        bucket = edges[start[r]:start[r + 1]]
        _sort_by_high_end(point, bucket)
        for i in range(len(bucket) - 1):
            a, b = bucket[i], bucket[i + 1]
            high = _high_end(point, a)
            if (high != _high_end(point, b) or (i > 0 and _high_end(point, bucket[i - 1]) == high)
                    or (i + 2 < len(bucket) and _high_end(point, bucket[i + 2]) == high)):
                continue  # not shared, or shared by three or more triangles
            k = _cut_pair(point, quantised, uv, page, a, b, found, k)
    return found[:, :k]


_SMALL_BUCKET = 32  # edges a bucket sorts by insertion (``_sort_by_high_end``)


@inline
def _low_end(point: np.ndarray, edge: int) -> int:
    """The row of edge ``edge`` (3t + c)'s end point of the lower row."""
    t, c = edge // 3, edge % 3
    return min(point[t, c], point[t, (c + 1) % 3])


@inline
def _high_end(point: np.ndarray, edge: int) -> int:
    """The row of edge ``edge`` (3t + c)'s end point of the higher row."""
    t, c = edge // 3, edge % 3
    return max(point[t, c], point[t, (c + 1) % 3])


@jit
def _sort_by_high_end(point: np.ndarray, bucket: np.ndarray) -> None:
    """Sort ``bucket`` (edges, in increasing order) by their higher end's row, in place and
    stably: equal ends keep the lower edge first."""
    if len(bucket) > _SMALL_BUCKET:  # (its own names: numba may type a name once a kernel)
        ends = np.array([_high_end(point, e) for e in bucket])
        bucket[:] = bucket[np.argsort(ends, kind="mergesort")]
        return
    for i in range(1, len(bucket)):
        e, high, j = bucket[i], _high_end(point, bucket[i]), i
        while j > 0 and _high_end(point, bucket[j - 1]) > high:
            bucket[j] = bucket[j - 1]
            j -= 1
        bucket[j] = e


@inline
def _cut_pair(point: np.ndarray, quantised: np.ndarray, uv: np.ndarray, page: np.ndarray,
              a: int, b: int, found: np.ndarray, k: int) -> int:
    """Put the shared edges ``a`` < ``b`` in ``found[:, k]`` where the atlas cuts them (as
    ``_cut_edges`` says); the count of ``found`` after."""
    ta, tb = a // 3, b // 3
    if page[ta] < 0 or page[tb] < 0:
        return k
    lo_a, hi_a = _ends(point, quantised, a)
    lo_b, hi_b = _ends(point, quantised, b)
    split = page[ta] != page[tb]
    for axis in range(2):
        split |= abs(uv[ta, lo_a, axis] - uv[tb, lo_b, axis]) > 1e-9
        split |= abs(uv[ta, hi_a, axis] - uv[tb, hi_b, axis]) > 1e-9
    if split:
        found[0, k], found[1, k], found[2, k] = ta, tb, lo_a
        found[3, k], found[4, k], found[5, k] = hi_a, lo_b, hi_b
        k += 1
    return k


@inline
def _ends(point: np.ndarray, quantised: np.ndarray, edge: int) -> tuple[int, int]:
    """The corners (lower, higher) of edge ``edge`` (3t + c) of its triangle t by end point:
    c and c + 1 mod 3, swapped where c's quantised position is lexicographically the higher."""
    t, c = edge // 3, edge % 3
    d = (c + 1) % 3
    p, q = point[t, c], point[t, d]
    for axis in range(3):
        if quantised[p, axis] != quantised[q, axis]:
            return (d, c) if quantised[p, axis] > quantised[q, axis] else (c, d)
    return c, d


def _taps(page: np.ndarray, uv: np.ndarray, shape: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Flat texel indices (S, 4) and weights (S, 4) of clamped bilinear lookups at ``uv``."""
    _, h, w = shape
    x = uv[:, 0] * w - 0.5
    y = uv[:, 1] * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    xs = np.stack([x0, x0 + 1, x0, x0 + 1], axis=1).clip(0, w - 1)
    ys = np.stack([y0, y0, y0 + 1, y0 + 1], axis=1).clip(0, h - 1)
    weights = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], axis=1)
    return (page[:, None] * h + ys) * w + xs, weights


@jit
def _normal_product(weight: np.ndarray, local: np.ndarray, lam: np.ndarray, x: np.ndarray,
                    out: np.ndarray) -> np.ndarray:
    """``out`` (n, C) = (MᵀM + diag(lam)) x: M the seam rows, row s having ``weight[s, k]`` at
    column ``local[s, k]`` (S, K); one compiled pass over the rows, scattered in row order."""
    out[:] = 0.0
    for s in range(weight.shape[0]):
        for c in range(x.shape[1]):
            row = 0.0
            for k in range(weight.shape[1]):
                row += weight[s, k] * x[local[s, k], c]
            for k in range(weight.shape[1]):
                out[local[s, k], c] += weight[s, k] * row
    for i in range(x.shape[0]):
        for c in range(x.shape[1]):
            out[i, c] += lam[i] * x[i, c]
    return out


@jit
def _solve(weight: np.ndarray, local: np.ndarray, lam: np.ndarray, x0: np.ndarray,
           iterations: int) -> np.ndarray:
    """x (n, C) minimising |M x|² + Σ lam·|x − x0|² (M the seam rows, ``_normal_product``):
    conjugate gradients on (MᵀM + Λ) x = Λ x0, every channel at once (they share the matrix),
    preconditioned by its diagonal (Jacobi: Σ of a texel's squared weights + its λ, which
    differ 10× between baked and padding texels and grow with the seam samples a texel
    meets), until the residual's square falls under 1e-20 of |Λ x0|² or after
    ``iterations``."""
    n, channels = x0.shape
    diagonal = lam.copy()
    for s in range(weight.shape[0]):
        for k in range(weight.shape[1]):
            diagonal[local[s, k]] += weight[s, k] * weight[s, k]
    x = x0.copy()
    q = np.empty_like(x0)
    _normal_product(weight, local, lam, x, q)
    r = np.empty_like(x0)
    z = np.empty_like(x0)
    rr, rz = np.zeros(channels), np.zeros(channels)
    norm = 0.0
    for i in range(n):
        for c in range(channels):
            b = lam[i] * x0[i, c]
            r[i, c] = b - q[i, c]
            z[i, c] = r[i, c] / diagonal[i]
            rr[c] += r[i, c] * r[i, c]
            rz[c] += r[i, c] * z[i, c]
            norm += b * b
    p = z.copy()
    target = 1e-20 * max(norm, 1e-300)
    alpha, beta, pq, rz_new = (np.empty(channels), np.empty(channels), np.empty(channels),
                               np.empty(channels))
    for _ in range(iterations):
        if rr.sum() <= target:
            break
        _normal_product(weight, local, lam, p, q)
        pq[:] = 0.0
        for i in range(n):
            for c in range(channels):
                pq[c] += p[i, c] * q[i, c]
        for c in range(channels):
            alpha[c] = rz[c] / max(pq[c], 1e-300)
        rr[:] = 0.0
        rz_new[:] = 0.0
        for i in range(n):
            for c in range(channels):
                x[i, c] += alpha[c] * p[i, c]
                r[i, c] -= alpha[c] * q[i, c]
                z[i, c] = r[i, c] / diagonal[i]
                rr[c] += r[i, c] * r[i, c]
                rz_new[c] += r[i, c] * z[i, c]
        for c in range(channels):
            beta[c] = rz_new[c] / max(rz[c], 1e-300)
        for i in range(n):
            for c in range(channels):
                p[i, c] = z[i, c] + beta[c] * p[i, c]
        rz[:] = rz_new
    return x


def stitch(values: np.ndarray, covered: np.ndarray, seams: Seams) -> np.ndarray:
    """``values`` (P, H, W, C) with the texels the seam lookups read re-solved so that both
    sides of every seam agree (least squares, see the module's docstring); others unchanged.
    In place when ``values`` is C-contiguous (a copy of a 4096² page pair would be 800 MB).

    The system falls apart into the seams that share no texel (``rows.joined_roots``: a box's own
    seam, a wall's with the floor): each is solved on its own, to its own tolerance, the
    pieces shared between threads; a piece's solution does not depend on the others or on the
    threads."""
    if not len(seams):
        return values
    shape = values.shape[:3]
    ia, wa = _taps(seams.page_a, seams.uv_a, shape)
    ib, wb = _taps(seams.page_b, seams.uv_b, shape)
    index = np.concatenate([ia, ib], axis=1)  # (S, 8) flat texels of each seam row
    weight = np.concatenate([wa, -wb], axis=1)  # row · x = lookup A − lookup B
    used, local = np.unique(index, return_inverse=True)
    local = local.reshape(index.shape)
    flat = values.reshape(-1, values.shape[-1])
    x0 = flat[used]
    lam = np.where(covered.reshape(-1)[used], DATA_WEIGHT, PADDING_WEIGHT)
    x = _solve_pieces(weight, local, lam, np.ascontiguousarray(x0))
    values = np.ascontiguousarray(values)
    values.reshape(-1, values.shape[-1])[used] = x
    return values


def _solve_pieces(weight: np.ndarray, local: np.ndarray, lam: np.ndarray,
                  x0: np.ndarray) -> np.ndarray:
    """``_solve`` of each connected piece of the seam rows (``weight``, ``local`` (S, K)) apart:
    x (n, C). The pieces are sorted by their first texel, rows and texels by piece (stable),
    and dealt to the threads in runs of about equal rows."""
    _, piece = np.unique(joined_roots(local, len(x0)), return_inverse=True)  # by first texel
    nodes = np.argsort(piece, kind="stable")
    node_start = np.searchsorted(piece[nodes], np.arange(piece.max() + 2))
    position = np.empty(len(x0), np.int64)  # a texel's place within its piece
    position[nodes] = np.arange(len(x0)) - node_start[piece[nodes]]
    rows = np.argsort(piece[local[:, 0]], kind="stable")
    row_start = np.searchsorted(piece[local[rows, 0]], np.arange(piece.max() + 2))
    sorted_weight = np.ascontiguousarray(weight[rows])
    sorted_local = position[local[rows]]
    sorted_lam, sorted_x0 = lam[nodes], np.ascontiguousarray(x0[nodes])
    out = np.empty_like(sorted_x0)
    bounds = np.searchsorted(row_start, np.linspace(0, len(rows), _RUNS + 1)[1:-1])
    runs = [slice(a, b) for a, b in zip([0, *bounds], [*bounds, len(row_start) - 1]) if b > a]

    def work(pieces: slice) -> None:
        _solve_each(sorted_weight, sorted_local, sorted_lam, sorted_x0, row_start, node_start,
                    pieces.start, pieces.stop, _ITERATIONS, out)

    run_chunks(work, runs)
    x = np.empty_like(out)
    x[nodes] = out
    return x


@jit
def _solve_each(weight: np.ndarray, local: np.ndarray, lam: np.ndarray, x0: np.ndarray,
                row_start: np.ndarray, node_start: np.ndarray, first: int, last: int,
                iterations: int, out: np.ndarray) -> None:
    """``_solve`` of pieces ``first`` to ``last`` − 1 into ``out``: piece p's rows
    row_start[p]:row_start[p + 1] of ``weight`` and ``local`` (texels numbered within the
    piece), its texels node_start[p]:node_start[p + 1]."""
    for p in range(first, last):
        r0, r1, n0, n1 = row_start[p], row_start[p + 1], node_start[p], node_start[p + 1]
        out[n0:n1] = _solve(weight[r0:r1], local[r0:r1], lam[n0:n1], x0[n0:n1], iterations)
