"""Chart a mesh by projection: flat and gently curved parts, without xatlas.

A level is mostly flat faces (walls, crates, steps) and gently curved ones (columns, balls,
terrain), and a crown or a lawn is many small flat loose parts (leaves, blades). Such a
surface needs no optimised parameterisation: its projection onto a plane is a chart whose
distortion the plane's choice bounds. xatlas charts each mesh in 0.1–1 s per thousand
triangles (a 12,000-triangle sphere 0.8 s, a crown of 100,000 leaves 696 s); this charts a
million triangles in about a second.

``project``: the triangles are joined across edges (corners at the same position, so that
vertices split for normals or UVs do not cut a chart), and charts grown from the largest
triangle not yet charted across edges while each triangle's normal stays within ``CONE`` of
the seed's. A chart is projected along its area-weighted normal (every normal within 2·CONE <
90° of it, so no triangle turns over), scaled so that its area is its surface's, and turned so that
its bounding rectangle is the least one a side of its convex hull gives. A chart that
overlaps itself once projected (a helical ramp, a fold of a crumpled rock) is grown again from
its own triangles in half the cone, up to ``SPLITS`` times, if ``split`` (``charts.chart_many``:
for a mesh bigger than one of xatlas's pieces, whose time per triangle grows with its size); a
mesh is left to xatlas (None) when a chart still overlaps itself, or when its surface is so
crumpled that the charts average fewer than ``LEAST_TRIANGLES`` triangles (a rock's noise:
xatlas's charts follow it with less seam).

Everything is a pure function of the mesh (positions in its rigid-free frame, world units), so
the charts are the same bits however the meshes are dealt to cores, and after a rigid move.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from baker.atlas.layout import Charts
from baker.geometry.world import triangle_cross
from baker.jit import inline, jit

CONE = 40.0  # degrees: every normal of a chart within this of its seed's (under 45°)
SPLITS = 6  # a chart that overlaps itself is grown again in half the cone, at most this often
LEAST_TRIANGLES = 6.0  # a mesh whose cut charts average fewer triangles is left to xatlas
_OVERLAP = 1e-9  # of a chart's size: triangles closer than this to apart are apart
_EQUAL = 1e-9  # rectangles' areas this close (relative) are equal (``_turned``)
# Everything besides a mesh that decides its charts, for the unwrap cache's key; the first
# entries are bumped when the method changes.
KEY = ("projection", 5, CONE, SPLITS, LEAST_TRIANGLES, _OVERLAP, _EQUAL)


def project(positions: np.ndarray, triangles: np.ndarray, split: bool = True
            ) -> Charts | None:
    """The charts of a mesh by projection (``Charts``), or None where xatlas should chart it.

    positions (n, 3) float64 world units (the instance's rigid-free frame), triangles (m, 3)
    int64. ``split``: a chart that overlaps itself is grown again in narrower cones (else the
    mesh is left to xatlas)."""
    if not len(triangles):
        return None
    return project_many([(positions, triangles)], split)[0]


def project_many(meshes: list[tuple[np.ndarray, np.ndarray]], split: bool = False
                 ) -> list[Charts | None]:
    """``project`` of each of ``meshes`` (positions, triangles; each with a triangle at least),
    the same bits as each alone, from one pass of numpy calls over all of them: a box of 432
    triangles took 1.7 ms alone, nearly all of it numpy's cost per call (``charts.chart_many``).

    The meshes' arrays are joined (``_Joined``); nothing joins across meshes (vertices weld
    within their own mesh only), the seeds go mesh by mesh, and charts keep their numbers mesh
    by mesh (``_regrown``), so each mesh's charts are numbered and made as alone."""
    joined = _Joined.of(meshes)
    p, t, mesh = joined.positions, joined.triangles, joined.triangle_mesh
    cross = triangle_cross(p, t)
    double_area = np.linalg.norm(cross, axis=1)
    valid = np.isfinite(double_area) & (double_area > 0)
    normals = np.divide(cross, double_area[:, None], out=np.zeros_like(cross),
                        where=valid[:, None])
    neighbours = _neighbours(_welded(p, joined.vertex_mesh)[t])
    seeds = np.lexsort((np.arange(len(t)), -np.where(valid, double_area, 0.0), mesh))
    chart = np.full(len(t), -1, np.int64)
    count = _grow(normals, valid, neighbours, seeds, np.cos(np.radians(CONE)), chart, 0)
    declined = _crumpled(chart, count, neighbours, mesh, len(meshes))
    cone = CONE
    while True:
        vertex, owner, corners, flat = _flattened(p, t, cross, valid, double_area, chart, count)
        by_chart = np.argsort(chart, kind="stable")
        start = np.searchsorted(chart[by_chart], np.arange(count + 1))
        chart_mesh = _chart_mesh(chart, count, mesh)
        overlapping = _overlapping(flat, corners, by_chart, start, _OVERLAP)
        overlapping &= ~declined[chart_mesh]
        if not overlapping.any():
            break
        cone /= 2
        if not split or cone < CONE / 2 ** SPLITS:
            declined[chart_mesh[overlapping]] = True
            break
        chart, count = _regrown(chart, count, overlapping, normals, valid, neighbours, seeds,
                                np.cos(np.radians(cone)), mesh)
    hull_order = np.lexsort((flat[:, 1], flat[:, 0], owner))
    vertex_start = np.searchsorted(owner, np.arange(count + 1))
    uv, sides = _turned(flat, hull_order, vertex_start)
    return joined.split(Charts(vertices=vertex, triangles=corners, uv=uv, chart=owner,
                               sides=sides), chart_mesh, declined)


@dataclass(frozen=True)
class _Joined:
    """Meshes' arrays end to end: ``positions`` (n, 3) float64, ``triangles`` (m, 3) int64 into
    them, the mesh of each vertex (n,) and triangle (m,), and where each mesh's vertices and
    triangles start (meshes + 1,)."""

    positions: np.ndarray
    triangles: np.ndarray
    vertex_mesh: np.ndarray
    triangle_mesh: np.ndarray
    vertex_start: np.ndarray
    triangle_start: np.ndarray

    @classmethod
    def of(cls, meshes: list[tuple[np.ndarray, np.ndarray]]) -> _Joined:
        vertices = np.array([len(p) for p, _ in meshes], np.int64)
        triangles = np.array([len(t) for _, t in meshes], np.int64)
        vertex_start = np.concatenate([[0], np.cumsum(vertices)])
        triangle_mesh = np.repeat(np.arange(len(meshes)), triangles)
        return cls(
            positions=np.concatenate([np.asarray(p, np.float64).reshape(-1, 3) for p, _ in meshes]),
            triangles=np.concatenate([np.asarray(t, np.int64).reshape(-1, 3) for _, t in meshes])
            + vertex_start[triangle_mesh, None],
            vertex_mesh=np.repeat(np.arange(len(meshes)), vertices),
            triangle_mesh=triangle_mesh,
            vertex_start=vertex_start,
            triangle_start=np.concatenate([[0], np.cumsum(triangles)]))

    def split(self, charts: Charts, chart_mesh: np.ndarray, declined: np.ndarray
              ) -> list[Charts | None]:
        """Each mesh's part of the joined ``charts`` (numbered mesh by mesh: ``chart_mesh``
        (c,) the mesh of each, ascending) with its own numbers, or None where ``declined``."""
        chart_start = np.searchsorted(chart_mesh, np.arange(len(declined) + 1))
        corner_start = np.searchsorted(charts.chart, chart_start)
        out = []
        for i in range(len(declined)):
            if declined[i]:
                out.append(None)
                continue
            c0, c1 = chart_start[i], chart_start[i + 1]
            k0, k1 = corner_start[i], corner_start[i + 1]
            out.append(Charts(
                vertices=charts.vertices[k0:k1] - self.vertex_start[i],
                triangles=charts.triangles[self.triangle_start[i]:self.triangle_start[i + 1]] - k0,
                uv=charts.uv[k0:k1], chart=charts.chart[k0:k1] - c0, sides=charts.sides[c0:c1]))
        return out


def _flattened(p: np.ndarray, t: np.ndarray, cross: np.ndarray, valid: np.ndarray,
               double_area: np.ndarray, chart: np.ndarray, count: int
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each chart projected along its area-weighted normal (``cross``: (m, 3) the triangles'
    edge cross products), scaled to its surface's area: (k,) the mesh vertex and (k,) the
    chart of each chart vertex (by chart, then vertex), (m, 3) each triangle's chart
    vertices, (k, 2) their projected points."""
    axis = np.stack([np.bincount(chart, np.where(valid, cross[:, k], 0.0), count)
                     for k in range(3)], axis=1)
    u, v = _bases(axis)
    keys, corners = np.unique(chart[:, None] * len(p) + t, return_inverse=True)
    vertex, owner = keys % len(p), keys // len(p)
    corners = corners.reshape(-1, 3)
    flat = np.stack([np.einsum("ij,ij->i", p[vertex], u[owner]),
                     np.einsum("ij,ij->i", p[vertex], v[owner])], axis=1)
    flat *= _area_scale(flat, corners, chart, double_area, count)[owner, None]
    flat[_no_area(chart, valid, count)[owner]] = 0.0
    return vertex, owner, corners, flat


def _regrown(chart: np.ndarray, count: int, overlapping: np.ndarray, normals: np.ndarray,
             valid: np.ndarray, neighbours: np.ndarray, seeds: np.ndarray, cone_cos: float,
             mesh: np.ndarray) -> tuple[np.ndarray, int]:
    """The charts with the ``overlapping`` ones (c,) bool grown again from their own triangles
    within the narrower cone (``_grow``; the others keep theirs), numbered 0 … count − 1 mesh
    by mesh (``mesh`` (m,) of each triangle), within a mesh in order of their old numbers, the
    new ones last; and their count."""
    chart = np.where(overlapping[chart], -1, chart)
    count = _grow(normals, valid, neighbours, seeds[chart[seeds] < 0], cone_cos, chart, count)
    chart_mesh = _chart_mesh(chart, count, mesh)
    numbers = np.unique(chart)
    renumbered = np.zeros(count, np.int64)
    renumbered[numbers[np.lexsort((numbers, chart_mesh[numbers]))]] = np.arange(len(numbers))
    return renumbered[chart], len(numbers)


def _no_area(chart: np.ndarray, valid: np.ndarray, count: int) -> np.ndarray:
    """(c,) bool the charts of degenerate triangles only (no area, ``valid`` all False):
    collapsed to a point, they get no texels and take no room (``unwrap._packed`` gives them
    all one place), where a scene's 350,000 loose degenerate triangles made as many charts,
    7,134 pages and a minute of packing."""
    return np.bincount(chart, valid, count) == 0


def _welded(p: np.ndarray, mesh: np.ndarray) -> np.ndarray:
    """(n,) int64 the same number for vertices at the same position in the same ``mesh`` (n,)
    (the first's index)."""
    order = np.lexsort((p[:, 2], p[:, 1], p[:, 0], mesh))
    ordered = p[order]
    new = np.ones(len(p), bool)
    new[1:] = np.any(ordered[1:] != ordered[:-1], axis=1) | (mesh[order][1:] != mesh[order][:-1])
    first = order[np.flatnonzero(new)][np.cumsum(new) - 1]
    welded = np.empty(len(p), np.int64)
    welded[order] = first
    return welded


def _neighbours(corners: np.ndarray) -> np.ndarray:
    """(m, 3) int64 the triangle across each edge (corner k to k + 1) of each triangle, -1 at
    an open edge or one shared by more than two triangles. ``corners`` (m, 3) welded vertices."""
    a = corners.reshape(-1)
    b = corners[:, [1, 2, 0]].reshape(-1)
    keys = np.minimum(a, b) * (int(corners.max(initial=0)) + 1) + np.maximum(a, b)
    order = np.argsort(keys, kind="stable")
    return _pair_edges(keys, order, len(corners))


@jit
def _pair_edges(keys, order, count):
    """``_neighbours``' work on the edges' keys sorted by ``order``."""
    across = np.full((count, 3), -1, np.int64)
    i = 0
    while i < len(order):
        j = i + 1
        while j < len(order) and keys[order[j]] == keys[order[i]]:
            j += 1
        if j - i == 2:
            e, f = order[i], order[i + 1]
            if e // 3 != f // 3:
                across[e // 3, e % 3] = f // 3
                across[f // 3, f % 3] = e // 3
        i = j
    return across


@jit
def _grow(normals, valid, neighbours, seeds, cone_cos, chart, count):
    """Charts grown breadth-first from each seed (``seeds``: triangles, largest first) not yet
    charted (``chart`` (m,) −1), across edges, to uncharted triangles whose normal is within
    the cone of the seed's (degenerate ones, ``valid`` False, join any chart that reaches
    them), numbered from ``count`` on, into ``chart``. Returns the chart count."""
    queue = np.empty(len(normals), np.int64)
    for s in seeds:
        if chart[s] >= 0:
            continue
        chart[s] = count
        queue[0] = s
        head, tail = 0, 1
        while head < tail:
            t = queue[head]
            head += 1
            for k in range(3):
                w = neighbours[t, k]
                if w < 0 or chart[w] >= 0:
                    continue
                if valid[w] and (normals[s, 0] * normals[w, 0] + normals[s, 1] * normals[w, 1]
                                 + normals[s, 2] * normals[w, 2]) < cone_cos:
                    continue
                chart[w] = count
                queue[tail] = w
                tail += 1
        count += 1
    return count


def _crumpled(chart: np.ndarray, count: int, neighbours: np.ndarray, mesh: np.ndarray,
              meshes: int) -> np.ndarray:
    """(meshes,) bool: whether the charts cut from connected pieces of surface of each mesh
    (``mesh`` (m,) of each triangle) average fewer than ``LEAST_TRIANGLES`` triangles (loose
    parts charted whole do not count: a leaf is one chart of two triangles, and rightly so)."""
    inner = neighbours >= 0
    rows = np.repeat(np.arange(len(chart)), 3)[inner.reshape(-1)]
    cut = np.zeros(count, bool)
    # Set, not ``|=``: a chart's many edges repeat its index, and a buffered ``|=`` keeps only
    # the last edge's answer (a chart was cut only if its last edge was).
    cut[chart[rows][chart[rows] != chart[neighbours[inner]]]] = True
    cut_triangles = np.bincount(mesh, cut[chart], meshes)
    return (cut_triangles >= 64) & (cut_triangles < LEAST_TRIANGLES * np.bincount(
        _chart_mesh(chart, count, mesh), cut, meshes))


def _chart_mesh(chart: np.ndarray, count: int, mesh: np.ndarray) -> np.ndarray:
    """(count,) int64 the mesh of each chart numbered 0 … count − 1 (0 for a number no
    triangle has), from ``chart`` and ``mesh`` (m,), each triangle's."""
    out = np.zeros(count, np.int64)
    out[chart] = mesh
    return out


def _bases(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit (u, v) spanning the plane normal to each of ``axis`` (c, 3), u × v along it (the
    z axis for a zero one): u the axis crossed with the coordinate axis least along it."""
    length = np.linalg.norm(axis, axis=1, keepdims=True)
    n = np.where(length > 0, axis / np.where(length > 0, length, 1.0), [0.0, 0.0, 1.0])
    least = np.eye(3)[np.argmin(np.abs(n), axis=1)]
    u = np.cross(n, least)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(n, u)


def _area_scale(flat: np.ndarray, corners: np.ndarray, chart: np.ndarray,
                double_area: np.ndarray, count: int) -> np.ndarray:
    """(c,) the factor that gives each chart's projection its surface's area (1 for one of no
    area): a texel then covers 1 / density² of surface on average over the chart."""
    a, b, c = flat[corners[:, 0]], flat[corners[:, 1]], flat[corners[:, 2]]
    projected = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    surface = np.bincount(chart, np.where(np.isfinite(double_area), double_area, 0.0), count)
    shadow = np.bincount(chart, projected, count)
    ok = (shadow > 0) & (surface > 0)
    return np.sqrt(np.divide(surface, shadow, out=np.ones(count), where=ok))


@jit
def _overlapping(flat, corners, by_chart, start, tolerance):
    """(c,) bool: whether two triangles of each chart overlap in ``flat`` (k, 2). Each chart's
    triangles (``by_chart[start[c]:start[c + 1]]``) are binned in the cells of a grid of about
    one triangle a cell that they cover: the cells of a triangle's bounding box that none of
    its edges has wholly on its outer side (so a long thin triangle across the grid is in a
    line of cells, not in its box's square: 16,002 triangles of a ramp 5.7 → 0.8 s). The
    pairs sharing a cell are tested by their separating axes, up to the first that overlaps.
    Triangles without area are apart from all (``_apart``) and binned nowhere."""
    overlapping = np.zeros(len(start) - 1, np.bool_)
    for c in range(len(start) - 1):
        first, last = start[c], start[c + 1]
        if last - first < 2:
            continue
        low = np.full(2, np.inf)
        high = np.full(2, -np.inf)
        for i in range(first, last):
            for k in range(3):
                for d in range(2):
                    low[d] = min(low[d], flat[corners[by_chart[i], k], d])
                    high[d] = max(high[d], flat[corners[by_chart[i], k], d])
        size = max(high[0] - low[0], high[1] - low[1])
        if not size > 0:
            continue
        slack = tolerance * size
        side = int(np.sqrt(last - first)) + 1
        cell = size / side * (1 + 1e-9)
        fill = np.zeros(side * side + 1, np.int64)
        members = np.empty(0, np.int64)
        for phase in range(2):  # the cells' counts, then their members
            if phase == 1:
                for g in range(side * side):
                    fill[g + 1] += fill[g]
                members = np.empty(fill[-1], np.int64)
                at = fill[:-1].copy()
            for i in range(first, last):
                tri = corners[by_chart[i]]
                ax, ay = flat[tri[0], 0], flat[tri[0], 1]
                bx, by = flat[tri[1], 0], flat[tri[1], 1]
                cx, cy = flat[tri[2], 0], flat[tri[2], 1]
                if not (bx - ax) * (cy - ay) - (by - ay) * (cx - ax) > 0:
                    continue
                gx0 = min(int((min(ax, bx, cx) - low[0]) / cell), side - 1)
                gy0 = min(int((min(ay, by, cy) - low[1]) / cell), side - 1)
                gx1 = min(int((max(ax, bx, cx) - low[0]) / cell), side - 1)
                gy1 = min(int((max(ay, by, cy) - low[1]) / cell), side - 1)
                for gx in range(gx0, gx1 + 1):
                    x0 = low[0] + gx * cell
                    for gy in range(gy0, gy1 + 1):
                        y0 = low[1] + gy * cell
                        if not (_meets(ax, ay, bx, by, x0, y0, cell, slack)
                                and _meets(bx, by, cx, cy, x0, y0, cell, slack)
                                and _meets(cx, cy, ax, ay, x0, y0, cell, slack)):
                            continue
                        g = gx * side + gy
                        if phase == 0:
                            fill[g + 1] += 1
                        else:
                            members[at[g]] = i
                            at[g] += 1
        for g in range(side * side):
            for i in range(fill[g], fill[g + 1]):
                a = corners[by_chart[members[i]]]
                for j in range(i + 1, fill[g + 1]):
                    b = corners[by_chart[members[j]]]
                    if not _share_an_edge(a, b) and not _apart(flat, a, b, slack):
                        overlapping[c] = True
                        break
                if overlapping[c]:
                    break
            if overlapping[c]:
                break
    return overlapping


@inline
def _meets(px, py, qx, qy, x0, y0, cell, slack):
    """Whether some of the cell [x0, x0 + cell] × [y0, y0 + cell] is on the inner side of a
    counter-clockwise triangle's edge p → q, or within ``slack`` × its length of it."""
    nx, ny = py - qy, qx - px  # points into the triangle
    reach = nx * (x0 + cell if nx > 0 else x0) + ny * (y0 + cell if ny > 0 else y0)
    return reach >= nx * px + ny * py - slack * np.sqrt(nx * nx + ny * ny)


@inline
def _share_an_edge(a, b):
    """Whether triangles ``a`` and ``b`` (corner rows) have two corners in common: turned the
    same way, they lie on either side of that edge and cannot overlap."""
    shared = 0
    for k in range(3):
        for m in range(3):
            if a[k] == b[m]:
                shared += 1
    return shared >= 2


@inline
def _apart(flat, a, b, tolerance):
    """Whether triangles ``a`` and ``b`` (corner rows into ``flat``) have no inner point in
    common: an edge of either separates them (touching counts as apart), or either has no
    area."""
    for tri in (a, b):
        ax, ay = flat[tri[0], 0], flat[tri[0], 1]
        area = ((flat[tri[1], 0] - ax) * (flat[tri[2], 1] - ay)
                - (flat[tri[1], 1] - ay) * (flat[tri[2], 0] - ax))
        if not area > 0:
            return True
    for first in (a, b):
        for k in range(3):
            p, q = first[k], first[(k + 1) % 3]
            nx, ny = flat[p, 1] - flat[q, 1], flat[q, 0] - flat[p, 0]
            slack = tolerance * np.sqrt(nx * nx + ny * ny)
            lo_a, hi_a, lo_b, hi_b = np.inf, -np.inf, np.inf, -np.inf
            for j in range(3):
                s = nx * flat[a[j], 0] + ny * flat[a[j], 1]
                lo_a, hi_a = min(lo_a, s), max(hi_a, s)
                s = nx * flat[b[j], 0] + ny * flat[b[j], 1]
                lo_b, hi_b = min(lo_b, s), max(hi_b, s)
            if hi_a <= lo_b + slack or hi_b <= lo_a + slack:
                return True
    return False


@jit
def _turned(flat, order, start):
    """Each chart's vertices (``start[c]:start[c + 1]`` of ``flat`` (k, 2), in the order of
    their mesh vertices; ``order``: the same ranges sorted by x, then y) turned so that their
    bounding rectangle is the least of those with a side along a side of their convex hull,
    of equals (within ``_EQUAL``) the one whose x axis is most along the chart's first two
    vertices, moved to start at (0, 0): (k, 2) and the (c, 2) rectangles' sides."""
    uv = np.empty_like(flat)
    sides = np.zeros((len(start) - 1, 2))
    hull = np.empty(len(flat) + 1, np.int64)
    for c in range(len(start) - 1):
        first, last = start[c], start[c + 1]
        h = 0  # Andrew's monotone chain: the lower hull, then the upper
        for i in range(first, last):
            h = _pushed(flat, hull, 0, h, order[i])
        h -= 1  # each half's last point is the other's first
        base = h
        for i in range(last - 1, first - 1, -1):
            h = _pushed(flat, hull, base, h, order[i])
        h = max(h - 1, 1)
        # The mesh's own direction in the chart: from its vertex of least index to the next
        # (vertices are in order of index within a chart), to choose among equal rectangles
        # the same way however the mesh is turned or mirrored in its frame.
        ref_x, ref_y = 0.0, 0.0
        if last - first > 1:
            ref_x, ref_y = flat[first + 1, 0] - flat[first, 0], flat[first + 1, 1] - flat[first, 1]
        best, best_along, cos_best, sin_best = np.inf, -np.inf, 1.0, 0.0
        for e in range(h):
            p, q = hull[e], hull[(e + 1) % h]
            dx, dy = flat[q, 0] - flat[p, 0], flat[q, 1] - flat[p, 1]
            length = np.sqrt(dx * dx + dy * dy)
            if length == 0:
                continue
            for quarter in range(4):  # the rectangle along this side, each way round
                cs, sn = dx / length, dy / length
                for _ in range(quarter):
                    cs, sn = -sn, cs
                lo_x, hi_x, lo_y, hi_y = np.inf, -np.inf, np.inf, -np.inf
                for f in range(h):
                    x = cs * flat[hull[f], 0] + sn * flat[hull[f], 1]
                    y = cs * flat[hull[f], 1] - sn * flat[hull[f], 0]
                    lo_x, hi_x = min(lo_x, x), max(hi_x, x)
                    lo_y, hi_y = min(lo_y, y), max(hi_y, y)
                area = (hi_x - lo_x) * (hi_y - lo_y)
                along = cs * ref_x + sn * ref_y
                if area < best * (1 - _EQUAL) or (area <= best * (1 + _EQUAL)
                                                   and along > best_along):
                    best = min(best, area)
                    best_along, cos_best, sin_best = along, cs, sn
        lo_x, lo_y, hi_x, hi_y = np.inf, np.inf, -np.inf, -np.inf
        for i in range(first, last):
            uv[i, 0] = cos_best * flat[i, 0] + sin_best * flat[i, 1]
            uv[i, 1] = cos_best * flat[i, 1] - sin_best * flat[i, 0]
            lo_x, hi_x = min(lo_x, uv[i, 0]), max(hi_x, uv[i, 0])
            lo_y, hi_y = min(lo_y, uv[i, 1]), max(hi_y, uv[i, 1])
        for i in range(first, last):
            uv[i, 0] -= lo_x
            uv[i, 1] -= lo_y
        sides[c, 0], sides[c, 1] = hi_x - lo_x, hi_y - lo_y
    return uv, sides


@inline
def _pushed(flat, hull, base, h, q):
    """Point ``q`` put on the hull chain ``hull[base:h]``, the points it makes turn right or
    go straight taken off first; the chain's new end."""
    while h >= base + 2:
        o, a = hull[h - 2], hull[h - 1]
        turn = ((flat[a, 0] - flat[o, 0]) * (flat[q, 1] - flat[o, 1])
                - (flat[a, 1] - flat[o, 1]) * (flat[q, 0] - flat[o, 0]))
        if turn > 0:
            break
        h -= 1
    hull[h] = q
    return h + 1
