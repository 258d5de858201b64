"""Every distinct mesh's charts, by projection where it can be, by xatlas where it cannot.

A mesh is charted in its instance's rigid-free frame in world units (``unwrap.frame_positions``):
by projection (``planar.project``), or, where that declines (a chart would overlap itself in
a mesh of one xatlas piece or less, or the surface is too crumpled), by xatlas
(``_xatlas_charts``, a big mesh in pieces). The charts hold no texel density, so a bake at
another density packs the same charts again. Each distinct
mesh is charted once, in forked children beside each other (one per core; ``forked.py``:
xatlas's threads can crash a process), the meshes dealt by triangles; each result is cached by
the mesh's content (``unwrap_cache.py``): instances of one mesh stretched alike share one
charting, and a bake with one mesh edited charts only that one again; the charts of all of a
scene's meshes are kept as one entry too, which the next bake of the same meshes reads in one
go. Both ways are pure functions of the mesh, so the charts do not depend on the cores, the
order the children end in, or the cache.
"""

from __future__ import annotations

import functools
import mmap
from typing import Callable

import numpy as np
import xatlas

from baker.atlas import planar, unwrap_cache
from baker.atlas.layout import Charts
from baker.geometry.world import triangle_cross
from baker.run.forked import call_forked_together
from baker.run.parallel import cores
from baker.run.progress import Steps

_NO_PAGE = np.uint32(0xFFFFFFFF)  # xatlas's page index for vertices of faces it could not place
# xatlas charts a mesh scaled to this many of its units² of surface: every chart many units
# wide, so that its own packing (a unit a texel, a unit of padding) moves charts, never shapes
# them; the scale is undone after.
_XATLAS_AREA = 1e5
# xatlas charts a mesh in pieces of at most this many triangles (``_pieces``), each an xatlas
# mesh of its own, side by side on xatlas's threads: its time per triangle grows with a mesh's
# size (a crumpled rock of 81,920 triangles 6.8 s whole, 3.2–4.1 s in 8,000–32,000-triangle
# pieces; of 327,680, 68 s whole), while the pieces add few charts (1,008 → 1,128 at 16,000).
_PIECE_TRIANGLES = 16_000
# Meshes of a piece or less are projected this many triangles at a time (``chart_many``): far
# more than numpy's cost per call is worth, few enough that a child's progress moves.
_BATCH_TRIANGLES = 50_000
# The CPU time (all its threads) a charting child may use before it is taken for hung
# (``forked.call_forked_together``: CPU time, so a loaded machine never makes a genuine run
# look hung):
# 5 s, and 2 ms a triangle (xatlas charts about 15,000 triangles a second on one busy core).
_SECONDS, _SECONDS_PER_TRIANGLE = 5.0, 2e-3

Mesh = tuple[np.ndarray, np.ndarray]  # positions (n, 3) float64 world units, triangles (m, 3) int64


def chart_meshes(meshes: list[Mesh], threads: int, steps: Steps | None = None,
                 elsewhere: Callable[[list[Mesh], Steps], list[Charts]] | None = None,
                 scene: str | None = None) -> list[Charts]:
    """Every mesh's ``Charts``, in order: each distinct mesh once, from the cache or charted
    in forked children (at most ``threads`` at once, 0: one per core); the split changes only
    who charts what, not the charts. The charts of all the distinct meshes are also kept as
    one entry (named by theirs), read back in one go by the next bake of the same meshes
    (hundreds of small files cost a millisecond or two each). ``steps``: the triangles to
    chart and charted, counted as the children go. ``elsewhere(meshes, steps)``: the charts
    of the meshes not cached, made elsewhere (on a cluster's workers:
    ``pipeline.cluster.chart_on_workers``) instead of in forked children here. ``scene``: the
    scene file's path, whose last joint entry holds the charts of the meshes an edit left as
    they were (``unwrap_cache.last_joint``): read in one go, not from an entry each."""
    names, named = [], {}
    for mesh in meshes:
        shared = (id(mesh[0]), id(mesh[1]))  # one mesh's arrays for many instances: named once
        if shared not in named:
            named[shared] = chart_name(mesh)
        names.append(named[shared])
    first = {name: m for m, name in reversed(list(enumerate(names)))}  # each distinct mesh's first
    together = unwrap_cache.key([], ("together", *first))
    charted = _read_together(together, first, meshes)
    if charted is not None:
        return [charted[name] for name in names]
    charted = _from_last(scene, first, meshes) if scene is not None else {}
    for name, m in first.items():
        if name in charted:
            continue
        stored = unwrap_cache.read(name, 1)
        found = _from_entry(stored[0], stored[1][0], meshes[m]) if stored is not None else None
        if found is not None:
            charted[name] = found
    missing = sorted((m for name, m in first.items() if name not in charted),
                     key=lambda m: (-len(meshes[m][1]), m))
    steps = steps or Steps()
    if missing and elsewhere is not None:
        for m, charts in zip(missing, elsewhere([meshes[m] for m in missing], steps)):
            charted[names[m]] = charts
            unwrap_cache.write(names[m], (len(charts.sides),), (_entry(charts),), prune=False)
    elif missing:
        weights = [len(meshes[m][1]) for m in missing]
        groups = balanced(missing, weights, min(threads or cores(), cores()))
        limit = max(_SECONDS + _SECONDS_PER_TRIANGLE * sum(len(meshes[m][1]) for m in group)
                    for group in groups)
        steps.expect(sum(weights))
        charted_so_far = np.frombuffer(mmap.mmap(-1, 8 * len(groups)), np.int64)  # shared
        runs = call_forked_together(
            [functools.partial(_chart_group, meshes, group, charted_so_far, k)
             for k, group in enumerate(groups)], "the chart builder", limit,
            tick=lambda: steps.done_so_far(int(charted_so_far.sum())))
        steps.done_so_far(steps.total)
        for group, results in zip(groups, runs):
            for m, charts in zip(group, results):
                charted[names[m]] = charts
    unwrap_cache.write(together, tuple(len(charted[name].sides) for name in first),
                       tuple(_entry(charted[name]) for name in first))
    if scene is not None:
        unwrap_cache.remember_joint(scene, together, list(first))
    return [charted[name] for name in names]


def _from_last(scene: str, first: dict[str, int], meshes: list[Mesh]) -> dict[str, Charts]:
    """The charts of those of the distinct meshes (``first``: name → a mesh of it) that the
    scene file ``scene``'s last joint entry holds."""
    last = unwrap_cache.last_joint(scene)
    stored = unwrap_cache.read(last[0], len(last[1])) if last is not None else None
    if stored is None or len(stored[0]) != len(last[1]):
        return {}
    charted = {}
    for name, count, arrays in zip(last[1], stored[0], stored[1]):
        found = _from_entry((count,), arrays, meshes[first[name]]) if name in first else None
        if found is not None:
            charted[name] = found
    return charted


def _read_together(name: str, first: dict[str, int], meshes: list[Mesh]
                   ) -> dict[str, Charts] | None:
    """The charts of the distinct meshes (``first``: name → a mesh of it) from their joint
    entry ``name``, or None when there is none whole."""
    stored = unwrap_cache.read(name, len(first))
    if stored is None or len(stored[0]) != len(first):
        return None
    charted = {}
    for (mesh_name, m), count, arrays in zip(first.items(), stored[0], stored[1]):
        found = _from_entry((count,), arrays, meshes[m])
        if found is None:
            return None
        charted[mesh_name] = found
    return charted


@functools.cache
def _charting() -> tuple[object, ...]:
    """What besides a mesh decides its charts: the projection's constants, xatlas's version
    and options (made once: every mesh's cache name asks for it)."""
    return (*planar.KEY, xatlas.__version__, _XATLAS_AREA, _PIECE_TRIANGLES,
            *map(_options_of, _xatlas_options()))


def chart_name(mesh: Mesh) -> str:
    """The cache name of one mesh's charts (``unwrap_cache.py``)."""
    return unwrap_cache.key([mesh], _charting())


def chart_list(meshes: list[Mesh]) -> list[Charts]:
    """Each of ``meshes``' charts (``chart_many``), in order: a cluster worker's task."""
    return chart_many(meshes)


def _chart_group(meshes: list[Mesh], group: list[int], charted_so_far: np.ndarray, slot: int
                 ) -> list[Charts]:
    """The charts of the meshes ``group`` (indices into ``meshes``; one child's), each kept in
    the cache as it is made (by the child: the cores write side by side); the triangles
    charted so far are kept in ``charted_so_far[slot]`` (memory shared with the parent, which
    shows them). Meshes of one xatlas piece or less go ``_BATCH_TRIANGLES`` at a time
    (``chart_many``), bigger ones one by one."""
    made = {}
    charted_so_far[slot] = 0  # a child run again starts again
    for batch in _batches([m for m in group if len(meshes[m][1]) <= _PIECE_TRIANGLES],
                          meshes) + [[m] for m in group if len(meshes[m][1]) > _PIECE_TRIANGLES]:
        for m, charts in zip(batch, chart_many([meshes[m] for m in batch])):
            made[m] = charts
            unwrap_cache.write(chart_name(meshes[m]), (len(charts.sides),), (_entry(charts),),
                               prune=False)
            charted_so_far[slot] += len(meshes[m][1])
    return [made[m] for m in group]


def _batches(small: list[int], meshes: list[Mesh]) -> list[list[int]]:
    """``small`` (indices into ``meshes``) in runs of about ``_BATCH_TRIANGLES`` triangles."""
    batches, size = [], _BATCH_TRIANGLES
    for m in small:
        if size >= _BATCH_TRIANGLES:
            batches.append([])
            size = 0
        batches[-1].append(m)
        size += len(meshes[m][1])
    return batches


def chart_many(meshes: list[Mesh]) -> list[Charts]:
    """Each mesh's charts: by projection, else by xatlas; none for no triangles. The meshes of
    one xatlas piece or less are projected together (``planar.project_many``: the same charts,
    without numpy's cost per call for each of many small meshes). A mesh bigger
    than one xatlas piece whose projected charts overlap is split by projection
    (``planar.project``'s ``split``): xatlas would cut it into pieces too, and take 20 s
    against 1.2 s for a crumpled rock of 327,680 triangles (bench_unwrap.py --rock; its atlas
    then 0.43 of the page used against 0.59, 0.115 of the inner edges cut against 0.063,
    stretch 1.000 [0.957, 1.040] against 1.026 [0.992, 1.172]). One piece or less, xatlas
    charts it in under half a second and cuts fewer seams (a rock of 20,480, a little over a
    piece: 0.45 s against 0.09 s, 0.180 of its inner edges cut against 0.333)."""
    small = [m for m, (_, t) in enumerate(meshes) if 0 < len(t) <= _PIECE_TRIANGLES]
    projected = dict(zip(small, planar.project_many([meshes[m] for m in small]) if small else []))
    out = []
    for m, (positions, triangles) in enumerate(meshes):
        if not len(triangles):
            out.append(Charts(vertices=np.zeros(0, np.int64), triangles=np.zeros((0, 3), np.int64),
                              uv=np.zeros((0, 2)), chart=np.zeros(0, np.int64),
                              sides=np.zeros((0, 2))))
            continue
        charts = projected[m] if m in projected else planar.project(positions, triangles)
        out.append(charts if charts is not None else _xatlas_charts(positions, triangles))
    return out


def balanced(items: list[int], weights: list[int], count: int) -> list[list[int]]:
    """``items`` (heaviest first) dealt into at most ``count`` non-empty groups of about equal
    summed ``weights``: each to the lightest group so far (the first of equals)."""
    groups: list[list[int]] = [[] for _ in range(max(1, min(count, len(items))))]
    loads = [0] * len(groups)
    for item, weight in zip(items, weights):
        k = loads.index(min(loads))
        groups[k].append(item)
        loads[k] += weight
    return groups


def _xatlas_options() -> tuple[xatlas.ChartOptions, xatlas.PackOptions]:
    """xatlas's settings for charting one mesh: its packing only places the charts, which
    ``packing.py`` packs again, so the cheapest: no bilinear margin, a unit of padding (charts
    touching would be read back as one)."""
    options = xatlas.PackOptions()
    options.texels_per_unit = 1.0
    options.padding = 1
    options.bilinear = False
    options.resolution = 0
    options.create_image = False
    return xatlas.ChartOptions(), options


def _options_of(options: xatlas.ChartOptions | xatlas.PackOptions) -> dict[str, object]:
    """Every setting of an xatlas options object by name (for the cache key)."""
    return {name: getattr(options, name) for name in sorted(dir(options))
            if not name.startswith("_")}


def _xatlas_charts(positions: np.ndarray, triangles: np.ndarray) -> Charts:
    """One mesh charted by xatlas (scaled to ``_XATLAS_AREA`` units², see there) in
    ``_pieces``, one xatlas mesh each, its charts each moved to start at (0, 0) and scaled back
    to world units; the triangles keep their order. Vertices of faces xatlas leaves out
    (degenerate ones) take the chart and place of the nearest placed vertex of their piece."""
    p = np.asarray(positions, np.float64)
    t = np.asarray(triangles, np.int64)
    area = 0.5 * float(np.linalg.norm(triangle_cross(p, t), axis=1).sum())
    scale = np.sqrt(_XATLAS_AREA / area) if area > 0 else 1.0
    parts = _pieces(p[t].mean(axis=1), _PIECE_TRIANGLES)
    atlas = xatlas.Atlas()
    corners = []  # each piece's vertices of the mesh
    for part in parts:
        used, local = np.unique(t[part], return_inverse=True)
        corners.append(used)
        atlas.add_mesh((p[used] * scale).astype(np.float32), local.reshape(-1, 3).astype(np.uint32))
    atlas.generate(*_xatlas_options())
    vertices, faces, uv, owner = [], np.empty_like(t), [], []
    count = 0  # vertices so far
    charts = 0  # charts so far
    for i, (part, used) in enumerate(zip(parts, corners)):
        piece = _piece_charts(atlas, i, p[used], scale)
        vertices.append(used[piece[0]])
        faces[part] = piece[1] + count
        uv.append(piece[2])
        owner.append(piece[3] + charts)
        count += len(piece[0])
        charts += int(piece[3].max()) + 1 if len(piece[3]) else 0
    uv_all, owner_all = np.concatenate(uv), np.concatenate(owner)
    sides = np.zeros((charts, 2))
    np.maximum.at(sides, owner_all, uv_all)
    return Charts(vertices=np.concatenate(vertices), triangles=faces, uv=uv_all,
                  chart=owner_all, sides=sides)


def _pieces(centroids: np.ndarray, most: int) -> list[np.ndarray]:
    """The triangles of a mesh, by their ``centroids`` (m, 3), in pieces of at most ``most``:
    halved at the median along the longest side of their bounds until they fit (compact
    pieces, cut across the surface as few times as halving allows). Indices (k,) int64,
    ascending in each piece; the pieces in a fixed order."""
    out, todo = [], [np.arange(len(centroids))]
    while todo:
        part = todo.pop()
        if len(part) <= most:
            out.append(part)
            continue
        c = centroids[part]
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        order = np.argsort(c[:, axis], kind="stable")
        half = len(part) // 2
        todo += [np.sort(part[order[half:]]), np.sort(part[order[:half]])]
    return out


def _piece_charts(atlas: xatlas.Atlas, i: int, where: np.ndarray, scale: float
                  ) -> tuple[np.ndarray, ...]:
    """xatlas's charting of piece ``i`` (``where``: its vertices' positions): (its vertices
    (k,) into the piece's, faces (f, 3) into those, uv (k, 2) world units from each chart's
    corner, chart (k,) from 0)."""
    vertices, faces, uv = atlas[i]
    page, owner = atlas.get_mesh_vertex_assignment(i)
    vertices, faces = vertices.astype(np.int64), faces.astype(np.int64)
    uv = uv.astype(np.float64) * [atlas.width, atlas.height] / scale
    placed = page != _NO_PAGE
    if not placed.any():
        placed[:] = True  # nothing placed: every vertex one point of one chart
        uv[:], owner = 0.0, np.zeros(len(vertices), np.int64)
    lost = np.flatnonzero(~placed)
    owner = owner.astype(np.int64)
    if len(lost):
        nearest = _nearest(where[vertices], np.flatnonzero(placed), lost)
        uv[lost], owner[lost] = uv[nearest], owner[nearest]
    _, owner = np.unique(owner, return_inverse=True)
    low = np.full((int(owner.max()) + 1 if len(owner) else 0, 2), np.inf)
    np.minimum.at(low, owner, uv)
    return vertices, faces, uv - low[owner], owner


def _nearest(where: np.ndarray, placed: np.ndarray, lost: np.ndarray) -> np.ndarray:
    """(len(lost),) for each vertex of ``lost`` the one of ``placed`` nearest to it in
    ``where`` (k, 3) (the first of equals)."""
    nearest = np.empty(len(lost), np.int64)
    for chunk in np.array_split(np.arange(len(lost)), max(1, len(lost) // 256)):
        distance = np.linalg.norm(where[lost[chunk], None] - where[None, placed], axis=-1)
        nearest[chunk] = placed[np.argmin(distance, axis=1)]
    return nearest


def _entry(charts: Charts) -> tuple[np.ndarray, ...]:
    """A mesh's charts as the cache keeps them (``unwrap_cache.PER_MESH`` arrays)."""
    return charts.vertices, charts.triangles, charts.uv, charts.chart, charts.sides


def _from_entry(header: tuple[int, ...], arrays: tuple[np.ndarray, ...], mesh: Mesh
                ) -> Charts | None:
    """The charts of a cache entry's mesh (its header and arrays, ``unwrap_cache.read``), or
    None when they have not the shapes, types and index ranges a charting of ``mesh`` gives
    (it is charted again)."""
    vertices, faces, uv, owner, sides = arrays
    k, count = len(vertices), len(sides)
    if (header != (count,) or vertices.dtype != np.int64 or faces.dtype != np.int64
            or uv.dtype != np.float64 or owner.dtype != np.int64 or sides.dtype != np.float64
            or vertices.shape != (k,) or faces.shape != mesh[1].shape or uv.shape != (k, 2)
            or owner.shape != (k,) or sides.shape != (count, 2)
            or (k and (vertices.min() < 0 or vertices.max() >= len(mesh[0])))
            or (faces.size and (faces.min() < 0 or faces.max() >= k))
            or (k and (owner.min() < 0 or owner.max() >= count))):
        return None
    return Charts(vertices=vertices, triangles=faces, uv=uv, chart=owner, sides=sides)
