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
from baker.geometry.rows import joined_roots, row_groups
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
    """The edges of triangles ``tris`` (m,) (world triangle ids) in 3D, as ``_cut_edges``
    takes them: (3m,) each edge's key, the same for the edges of two triangles that have the
    same two end points, whichever instance each belongs to (edge 3t + c of triangle t runs
    from its corner c to corner c + 1 mod 3), and the edges' order by key, stable.

    Same 3D point ⇔ same position rounded to 1e-7 of the largest coordinate (meshes split
    vertices at their own seams; touching objects have vertices of their own)."""
    corners = world.triangles[tris]  # (m, 3) world vertex ids
    used = np.zeros(len(world.positions), bool)
    used[corners.ravel()] = True  # each vertex once (np.unique's, without its sort)
    points = world.positions[used]
    extent = max(float(np.abs(points).max()), 1e-30)
    _first, ranks = row_groups(np.round(points / (extent * 1e-7)).astype(np.int64))
    point_id = ranks[(np.cumsum(used) - 1)[corners]]  # (m, 3)
    key = np.empty(point_id.size, np.int64)
    _edge_keys(point_id, key)
    return point_id, key, np.argsort(key, kind="stable")


@jit
def _edge_keys(point_id: np.ndarray, key: np.ndarray) -> None:
    """``key`` (3m,): of edge 3t + c, from corner c of triangle t to corner c + 1 mod 3 with
    end points ``point_id`` (m, 3), lower id × (largest id + 1) + higher id."""
    width = point_id.max() + 1
    for t in range(len(point_id)):
        for c in range(3):
            a, b = point_id[t, c], point_id[t, (c + 1) % 3]
            key[3 * t + c] = min(a, b) * width + max(a, b)


@jit
def _cut_edges(point_id: np.ndarray, key: np.ndarray, order: np.ndarray, uv: np.ndarray,
               page: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                          np.ndarray, np.ndarray]:
    """The edges that exactly two triangles share in 3D (``_shared_edges``' ``key`` and
    ``order``) and that the atlas cuts: both triangles placed (``page`` (m,) ≥ 0) and on two
    pages, or an end point at UVs (``uv`` (m, 3, 2)) more than 1e-9 apart on the two sides.
    An edge used by three or more triangles (a fin, two objects overlapping) is left out.
    Returns, per edge in key order, the two triangles (first, second in ``order``) and the
    corners (0–2) of its lower and higher end point in each (lo_a, hi_a, lo_b, hi_b): ends
    matched, whatever the windings. One pass: most shared edges lie inside a chart."""
    n = len(order)
    found = np.empty((6, n // 2), np.int64)
    k = 0
    for j in range(n - 1):
        if (key[order[j]] != key[order[j + 1]] or (j > 0 and key[order[j - 1]] == key[order[j]])
                or (j + 2 < n and key[order[j + 2]] == key[order[j]])):
            continue
        ta, tb = order[j] // 3, order[j + 1] // 3
        if page[ta] < 0 or page[tb] < 0:
            continue
        lo_a, hi_a = _ends(point_id, order[j])
        lo_b, hi_b = _ends(point_id, order[j + 1])
        split = page[ta] != page[tb]
        for axis in range(2):
            split |= abs(uv[ta, lo_a, axis] - uv[tb, lo_b, axis]) > 1e-9
            split |= abs(uv[ta, hi_a, axis] - uv[tb, hi_b, axis]) > 1e-9
        if split:
            found[0, k], found[1, k], found[2, k] = ta, tb, lo_a
            found[3, k], found[4, k], found[5, k] = hi_a, lo_b, hi_b
            k += 1
    return found[0, :k], found[1, :k], found[2, :k], found[3, :k], found[4, :k], found[5, :k]


@inline
def _ends(point_id: np.ndarray, edge: int) -> tuple[int, int]:
    """The corners (lower, higher) of edge ``edge`` (3t + c) of its triangle t by end point id:
    c and c + 1 mod 3, swapped where c's point id is the higher."""
    t, c = edge // 3, edge % 3
    d = (c + 1) % 3
    return (d, c) if point_id[t, c] > point_id[t, d] else (c, d)


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
