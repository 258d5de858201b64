"""Chart a mesh's many small flat loose parts (leaves, grass blades, decals) without xatlas.

A crown of 100,000 alpha-cut leaf quads is 100,000 charts: xatlas charts and packs them one by
one, 696 s for 100k leaves on this machine, and pads each to about seven texels a side. A loose
part (triangles joined by shared vertices, none shared with the rest) that is flat and a few
texels across needs no charting: its projection onto its own plane is a chart without
distortion. ``flat_parts`` finds such parts, turns each so that its bounding rectangle is the
smallest one an edge of it gives, and ``shelves`` packs their rectangles row by row into
blocks of at most ``BLOCK`` texels a side; ``unwrap.py`` hands xatlas one rectangle per block to
place among the other charts, and moves each block's parts to where its rectangle went.

Everything here works in the instance's rigid-free frame in texel units (``unwrap.xatlas_meshes``),
so the charts are a pure function of the mesh and the settings, unchanged by a rigid move.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from baker.jit import inline, jit

MIN_PARTS = 64  # a mesh with fewer small flat loose parts leaves them all to xatlas
MAX_SIDE = 16.0  # texels: a larger part is left to xatlas
MAX_TRIANGLES = 64  # a loose part of more triangles is left to xatlas
BLOCK = 64  # texels: the largest side of a block of parts (at most the page's room)
_FLAT_COS = 0.9998  # every triangle's normal within about 1.1° of its part's
_FLAT_DISTANCE = 0.02  # texels: every vertex this close to its part's plane
_MARGIN = 0.01  # texels: a part's rectangle is kept this far inside its cell's texels
# Everything besides a mesh and the padding that decides its flat charts, for the unwrap
# cache's key; the first entry is bumped when the method changes.
KEY = ("planar", 1, MIN_PARTS, MAX_SIDE, MAX_TRIANGLES, BLOCK, _FLAT_COS, _FLAT_DISTANCE, _MARGIN)


@dataclass(frozen=True)
class FlatParts:
    """A mesh's small flat loose parts, charted and packed into blocks (texel units).

    faces: (f,) int64 the mesh's triangles that belong to the parts, ascending.
    vertices: (k,) int64 the mesh vertices of those triangles, each once.
    triangles: (f, 3) int64 the faces' corners as indices into ``vertices``.
    uv: (k, 2) float64 each vertex's place in its block, in texels from the block's corner.
    block: (k,) int64 the block of each vertex.
    sizes: (b, 2) int64 each block's width and height in texels: its parts' texels and the
    padding between them, none around the outside (xatlas pads the block as a chart).
    parts: how many parts.
    """

    faces: np.ndarray
    vertices: np.ndarray
    triangles: np.ndarray
    uv: np.ndarray
    block: np.ndarray
    sizes: np.ndarray
    parts: int


def least_texels(parts: int, padding: int) -> int:
    """Texels of page that ``parts`` charts need at any density: each touches at least one
    texel and keeps ``padding`` free around it."""
    return parts * (1 + 2 * int(padding)) ** 2


def flat_parts(positions: np.ndarray, triangles: np.ndarray, padding: int, room: int
               ) -> FlatParts | None:
    """The small flat loose parts of a mesh, charted by projection and packed (``FlatParts``),
    or None when it has fewer than ``MIN_PARTS``.

    positions (n, 3) and triangles (m, 3) as xatlas takes them (texel units); ``padding``: the
    free texels every part keeps around it (two parts' texels are 2·padding apart, as xatlas
    spaces its charts); ``room``: texels a block may span (a page less its padding)."""
    p = positions.astype(np.float64)
    t = triangles.astype(np.int64)
    if len(t) < MIN_PARTS:
        return None
    found = _small_flat(p, t, _loose_parts(t, len(p)))
    if found is None:
        return None
    faces, part = found
    vertices, corners = np.unique(t[faces], return_inverse=True)
    corners = corners.reshape(-1, 3)
    owner = np.empty(len(vertices), np.int64)
    owner[corners.ravel()] = np.repeat(part, 3)
    local, extent = _projected(p[vertices], corners, owner, int(part.max()) + 1)
    cells = np.floor(extent + 2 * _MARGIN).astype(np.int64) + 1  # texels each part touches
    block, at, sizes = shelves(cells, 2 * int(padding), min(BLOCK, int(room)))
    centred = at[owner] + (cells[owner] - extent[owner]) / 2  # the rectangle mid-cell
    return FlatParts(faces=faces, vertices=vertices, triangles=corners,
                     uv=local + centred, block=block[owner], sizes=sizes,
                     parts=len(cells))


def _loose_parts(triangles: np.ndarray, vertex_count: int) -> np.ndarray:
    """(m,) int64 label of each triangle's loose part (triangles joined by shared vertices):
    the least vertex index in the part."""
    if not len(triangles):
        return np.zeros(0, np.int64)
    return _least_vertex(triangles, vertex_count)[triangles[:, 0]]


@jit
def _least_vertex(triangles, vertex_count):
    """Union–find over the triangles' corners: (n,) the least vertex index joined to each."""
    parent = np.arange(vertex_count)
    for t in range(len(triangles)):
        for k in range(1, 3):
            a, b = triangles[t, 0], triangles[t, k]
            while parent[a] != a:  # roots, halving the paths on the way
                parent[a] = parent[parent[a]]
                a = parent[a]
            while parent[b] != b:
                parent[b] = parent[parent[b]]
                b = parent[b]
            if a < b:
                parent[b] = a
            elif b < a:
                parent[a] = b
    for v in range(vertex_count):  # ascending: a vertex's root is final before it is read
        parent[v] = parent[parent[v]]
    return parent


def _small_flat(p: np.ndarray, t: np.ndarray, part: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray] | None:
    """The triangles (ascending) of the loose parts that are flat, at most ``MAX_TRIANGLES``
    and ``MAX_SIDE`` texels across, and their parts renumbered 0…; None when fewer than
    ``MIN_PARTS`` parts are."""
    _labels, part, size = np.unique(part, return_inverse=True, return_counts=True)
    keep = (size <= MAX_TRIANGLES)[part]
    if np.count_nonzero(size <= MAX_TRIANGLES) < MIN_PARTS:
        return None
    labels, part = np.unique(part[keep], return_inverse=True)
    faces = np.flatnonzero(keep)
    a, b, c = (p[t[faces, k]] for k in range(3))
    cross = np.cross(b - a, c - a)
    area = np.linalg.norm(cross, axis=1)
    count = len(labels)
    normal = _unit(np.stack([np.bincount(part, cross[:, k], count) for k in range(3)], axis=1))
    facing = np.einsum("ij,ij->i", cross, normal[part])
    low = np.full(count, np.inf)
    high = np.full(count, -np.inf)
    for q in (a, b, c):
        height = np.einsum("ij,ij->i", q, normal[part])
        np.minimum.at(low, part, height)
        np.maximum.at(high, part, height)
    span = np.zeros(count)
    anchor = a[_first_of(part, count)]
    for q in (a, b, c):  # an upper bound of the part's size: its corners' distances to one
        np.maximum.at(span, part, np.linalg.norm(q - anchor, axis=1))
    bad = ~(facing >= _FLAT_COS * area) | ~(area > 0)  # NaN positions are bad too
    ok = (np.bincount(part, bad, count) == 0) & (high - low <= _FLAT_DISTANCE) & (span <= MAX_SIDE)
    if ok.sum() < MIN_PARTS:
        return None
    chosen = ok[part]
    renumber = np.cumsum(ok) - 1
    return faces[chosen], renumber[part[chosen]]


def _first_of(part: np.ndarray, count: int) -> np.ndarray:
    """(m,) index of the first triangle of each triangle's part (parts numbered 0…count-1)."""
    first = np.full(count, len(part), np.int64)
    np.minimum.at(first, part, np.arange(len(part)))
    return first[part]


def _unit(v: np.ndarray) -> np.ndarray:
    """Rows of ``v`` scaled to unit length (zero rows stay zero)."""
    length = np.linalg.norm(v, axis=1, keepdims=True)
    return np.divide(v, length, out=np.zeros(v.shape), where=length > 0)


def _projected(p: np.ndarray, corners: np.ndarray, owner: np.ndarray, count: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """Each part's vertices in its plane, turned so that its bounding rectangle is the least
    of those aligned with one of its edges, and moved to start at 0: (k, 2) per vertex and the
    (parts, 2) rectangles' sides, texels. A rectangle's least-area bounding box has a side along
    the convex hull, which for a leaf quad or a blade is one of its edges.

    p (k, 3) the parts' vertices, corners (f, 3) their triangles into p, owner (k,) the part of
    each vertex (0…count-1)."""
    vertex_order = np.argsort(owner, kind="stable")
    triangle_order = np.argsort(owner[corners[:, 0]], kind="stable")
    vertex_start = np.searchsorted(owner[vertex_order], np.arange(count + 1))
    triangle_start = np.searchsorted(owner[corners[triangle_order, 0]], np.arange(count + 1))
    return _project_parts(p, corners, vertex_order, vertex_start, triangle_order,
                          triangle_start)


@inline
def _dot(a, b):
    """a · b of two 3-vectors, summed by hand: numba's ``np.dot`` calls BLAS through scipy,
    which is not one of baker's dependencies."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@jit
def _project_parts(p, corners, vertex_order, vertex_start, triangle_order, triangle_start):
    """``_projected``'s work, a part at a time: its normal (the sum of its triangles' area
    vectors), each edge's direction in the plane as a candidate axis, the first of least
    bounding area kept."""
    count = len(vertex_start) - 1
    flat = np.zeros((len(p), 2))
    sides = np.zeros((count, 2))
    for part in range(count):
        n = np.zeros(3)
        for j in range(triangle_start[part], triangle_start[part + 1]):
            a, b, c = corners[triangle_order[j]]
            n += np.cross(p[b] - p[a], p[c] - p[a])
        n /= np.sqrt(_dot(n, n))
        best, best_u, best_v = np.inf, np.zeros(3), np.zeros(3)
        for j in range(triangle_start[part], triangle_start[part + 1]):
            t = triangle_order[j]
            for k in range(3):
                e = p[corners[t, (k + 1) % 3]] - p[corners[t, k]]
                e -= _dot(e, n) * n
                length = np.sqrt(_dot(e, e))
                if length == 0:
                    continue
                e /= length
                v = np.cross(n, e)
                lo_u, hi_u, lo_v, hi_v = np.inf, -np.inf, np.inf, -np.inf
                for i in range(vertex_start[part], vertex_start[part + 1]):
                    q = p[vertex_order[i]]
                    x, y = _dot(q, e), _dot(q, v)
                    lo_u, hi_u = min(lo_u, x), max(hi_u, x)
                    lo_v, hi_v = min(lo_v, y), max(hi_v, y)
                if (hi_u - lo_u) * (hi_v - lo_v) < best:
                    best = (hi_u - lo_u) * (hi_v - lo_v)
                    best_u, best_v = e, v
                    sides[part, 0], sides[part, 1] = hi_u - lo_u, hi_v - lo_v
        lo_u, lo_v = np.inf, np.inf
        for i in range(vertex_start[part], vertex_start[part + 1]):
            q = p[vertex_order[i]]
            lo_u, lo_v = min(lo_u, _dot(q, best_u)), min(lo_v, _dot(q, best_v))
        for i in range(vertex_start[part], vertex_start[part + 1]):
            q = p[vertex_order[i]]
            flat[vertex_order[i], 0] = _dot(q, best_u) - lo_u
            flat[vertex_order[i], 1] = _dot(q, best_v) - lo_v
    return flat, sides


def shelves(cells: np.ndarray, gap: int, side: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pack rectangles of ``cells`` (n, 2) int64 texels into blocks of at most ``side`` a side,
    ``gap`` texels apart: tallest first (ties by index), left to right in rows, rows top to
    bottom, a new block when a row does not fit. Returns each rectangle's block (n,) and corner
    in it (n, 2), and the blocks' sizes (b, 2): a pure function of its input."""
    order = np.lexsort((np.arange(len(cells)), -cells[:, 1]))
    block, at, sizes = _shelves(cells[order], int(gap), int(max(side, cells.max(initial=1))))
    out_block = np.empty_like(block)
    out_at = np.empty_like(at)
    out_block[order], out_at[order] = block, at
    return out_block, out_at, sizes


@jit
def _shelves(cells, gap, side):
    """``shelves`` on rectangles sorted tallest first."""
    n = len(cells)
    block = np.zeros(n, np.int64)
    at = np.zeros((n, 2), np.int64)
    sizes = np.zeros((n, 2), np.int64)
    b, x, y, row = 0, 0, 0, 0
    for i in range(n):
        w, h = cells[i, 0], cells[i, 1]
        if x > 0 and x + w > side:  # the row is full: the next one under it
            y += row + gap
            x, row = 0, 0
        if y > 0 and y + h > side:  # the block is full: a new one
            b += 1
            x, y, row = 0, 0, 0
        block[i] = b
        at[i, 0], at[i, 1] = x, y
        row = max(row, h)
        sizes[b, 0] = max(sizes[b, 0], x + w)
        sizes[b, 1] = max(sizes[b, 1], y + h)
        x += w + gap
    return block, at, sizes[: b + 1]
