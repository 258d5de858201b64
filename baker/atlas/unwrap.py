"""Lay every baked instance out in lightmap pages with xatlas.

Two steps. Charts: each distinct mesh, in its instance's rigid-free frame (``frame_positions``:
local positions × the stretch part of its world matrix, in texel units), is charted alone by
xatlas (``_chart``), in forked children beside each other (one per core), each result cached by
the mesh's content (``unwrap_cache.CHARTS``): instances of one mesh whose world matrices stretch
it alike (the same texels per metre) share one charting, and a bake with one mesh edited charts
only that one again. Packing: the charts of every baked instance, each instance its own copy,
go into one xatlas run as UV meshes (``_pack``), so that one texel covers about
1 / texel_density world units everywhere and every instance gets its own area. Both steps are
pure functions of their input, so the atlas does not depend on the cores, the order the
children end in, or the cache; and moving or turning a node leaves it bit for bit as it was
(incremental rebake). Where one instance holds most triangles, charting apart cannot win, and
one xatlas run charts and packs everything (``_one_run``, ``_whole``). A mesh of many small flat
loose parts (a crown's leaf quads, grass) has those charted by projection and packed in blocks
(``planar.py``, ``_split``); xatlas places one rectangle a block among the other charts.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np
import xatlas

from baker.atlas import planar, unwrap_cache
from baker.atlas.layout import Atlas, InstanceUV
from baker.errors import SettingsError
from baker.geometry.world import World, triangle_cross
from baker.gltf.scene import Scene
from baker.jit import jit
from baker.run.forked import call_forked_together
from baker.run.parallel import cores
from baker.settings import Resolved

_NO_PAGE = np.uint32(0xFFFFFFFF)  # xatlas's page index for vertices of faces it could not place
_SHRUNK = 0.95  # a chart whose texels are this much larger than asked was shrunk to fit a page
# The CPU time (all its threads) an xatlas run may use before it is taken for hung
# (``forked.call_forked``: CPU time, so a loaded machine never makes a genuine run look hung):
# 5 s, 1 ms a triangle and 10 µs a texel its charts cover (packing is a search over the pages'
# texels). Measured on 2 busy cores (load 12): 250,000 triangles of one mesh at 8·10⁶ texels
# took 12–14 s and are given 335 s; the 60-crate room's 7,000 triangles take 0.03 s.
_SECONDS, _SECONDS_PER_TRIANGLE, _SECONDS_PER_TEXEL = 5.0, 1e-3, 1e-5
# Expected texels above this share of a page: the page xatlas sizes itself may come out larger
# than a page, so the run into whole pages is made beside it (on a second core) instead of after.
_BESIDE = 0.25
# The derived density is lowered, when the charts spill onto a second page though their texels
# fit in one, by the page side over the side xatlas needs, times this (packing is not exactly
# proportional: padding stays), in at most this many rounds (``_fitted``).
_FIT_MARGIN, _FIT_TRIES = 0.98, 3
# One xatlas run charts and packs everything when one instance holds over this share of the
# triangles (``_one_run``).
_ONE_RUN = 0.5


class PageTooSmall(SettingsError):
    """A chart does not fit in one page at the texel density asked for. ``texel_density`` is the
    highest density at which it fits (xatlas would otherwise shrink it without a word)."""

    def __init__(self, message: str, *, texel_density: float, fix: str):
        super().__init__(message, fix=fix)
        self.texel_density = texel_density


def baked_instances(scene: Scene) -> list[int]:
    """Indices of the instances that get lightmap texels, in scene order."""
    return [i for i, inst in enumerate(scene.instances) if inst.baked]


def _pack_options(settings: Resolved, resolution: int, turn: bool = False
                  ) -> xatlas.PackOptions:
    """Settings of the packing of every instance's charts (``_pack``); positions reach xatlas
    in texel units, so one texel per unit. The charts were turned to their best axis when
    charted (``_chart``): turned again, a chart under a texel wide would be made a texel wide
    once more (xatlas's least chart size), and a 0.1-texel triangle would own 5 texels. ``turn``:
    for the run that charts and packs at once (``_whole``), where the charts are turned once."""
    options = xatlas.PackOptions()
    options.rotate_charts_to_axis = turn
    options.texels_per_unit = 1.0
    options.padding = int(settings.padding)
    options.bilinear = True
    options.resolution = int(resolution)
    options.create_image = False
    return options


def stretch(linear: np.ndarray) -> np.ndarray:
    """The part of a (3, 3) world matrix that a rigid move of its node leaves alone.

    Polar decomposition ``linear = R · S`` (S symmetric, |det R| = 1), with the signs chosen so
    that det R = +1 (S is negated for a mirroring matrix): ``local @ S.T`` is then congruent to
    the world shape by a proper rotation, winding included. S is rounded to 2^-30 of its
    largest singular value, so that the rounding noise of a rotated matrix's SVD (~1e-16) does
    not change it: a node moved or turned keeps bit-identical unwrap input (docs/design.md §5).
    """
    return _stretch_of(np.ascontiguousarray(linear, np.float64).tobytes())


@functools.lru_cache(maxsize=1 << 16)
def _stretch_of(raw: bytes) -> np.ndarray:
    """``stretch`` of the (3, 3) float64 matrix whose bytes are ``raw``, computed once per
    matrix (a scene's many instances each ask for theirs several times); read-only."""
    linear = np.frombuffer(raw, np.float64).reshape(3, 3)
    _u, sigma, vt = np.linalg.svd(linear)
    s = (vt.T * sigma) @ vt
    if np.linalg.det(linear) < 0:
        s = -s
    top = float(sigma.max()) if len(sigma) else 0.0
    if np.isfinite(top) and top > 0:
        quantum = 2.0 ** (np.round(np.log2(top)) - 30)
        s = np.round(s / quantum) * quantum
    s.flags.writeable = False
    return s


def frame_positions(scene: Scene, instance: int) -> np.ndarray:
    """(n, 3) float64 positions of an instance's primitive in its rigid-free frame.

    The mesh's local positions times the stretch part of the world matrix (``stretch``),
    recentred on their bounds' middle: what xatlas sees, and the same bits before and after a
    rigid move of the node, so the atlas and every texel's (page, x, y, key, barycentric) stay.
    """
    inst = scene.instances[instance]
    positions = scene.primitives[inst.primitive].positions @ stretch(inst.world[:3, :3]).T
    if not len(positions):
        return positions
    return positions - (positions.min(0) + positions.max(0)) / 2


def frame_area(scene: Scene, world: World, instances: list[int] | None = None) -> float:
    """Summed area (scene units²) of the baked instances' triangles, in their rigid-free frames
    (a rigid move of a node leaves it bit-identical, and with it the derived texel density)."""
    total = 0.0
    for i in baked_instances(scene) if instances is None else instances:
        local = world.triangles[world.instance_triangles(i)] - world.vertex_start[i]
        if len(local):
            cross = triangle_cross(frame_positions(scene, i), local)
            total += float(0.5 * np.linalg.norm(cross, axis=1).sum())
    return total


@dataclass(frozen=True)
class _Packed:
    """What an xatlas run gave: its page size, page and chart counts, and per mesh (one per
    instance, in the order added) xatlas's (vertices, triangles, uv) and the pages and charts of
    its vertices (``xatlas.Atlas.get_mesh_vertex_assignment``)."""

    width: int
    height: int
    atlas_count: int
    chart_count: int
    meshes: tuple[tuple[np.ndarray, ...], ...]
    least_texels: int = 0  # page texels the flat parts need at any density (``planar.py``)


# xatlas's input for one mesh: positions (n, 3) float32 in texel units, triangles (m, 3) uint32
_Mesh = tuple[np.ndarray, np.ndarray]
_Charted = tuple[tuple[int, ...], tuple[np.ndarray, ...]]  # a run's header and one mesh's arrays


def xatlas_meshes(scene: Scene, world: World, instances: list[int], settings: Resolved
                   ) -> list[_Mesh]:
    """The instances' triangles in their rigid-free frames (``frame_positions``), scaled to
    texel units, as xatlas takes them (float32 positions, uint32 triangles).

    xatlas ignores faces with an area under about 1e-7 of its units; in texel units only faces
    far below a texel's size fall under that, not merely small ones."""
    meshes = []
    for i in instances:
        positions = frame_positions(scene, i) * settings.texel_density
        local = world.triangles[world.instance_triangles(i)] - world.vertex_start[i]
        meshes.append((positions.astype(np.float32), local.astype(np.uint32)))
    return meshes


def _chart_options() -> tuple[xatlas.ChartOptions, xatlas.PackOptions]:
    """xatlas's settings for charting one mesh alone: its packing only places the charts for
    ``_pack`` to pack again, so the cheapest: no bilinear margin, and a padding of one texel,
    which ``_pack`` needs: xatlas joins into one chart UV meshes' faces that share a UV point
    (charts moved to share a corner packed as one, overlapping)."""
    options = xatlas.PackOptions()
    options.texels_per_unit = 1.0
    options.padding = 1
    options.bilinear = False
    options.resolution = 0
    options.create_image = False
    return xatlas.ChartOptions(), options


def _chart(mesh: _Mesh) -> _Charted:
    """One mesh charted alone: header (width, height, pages, charts) and xatlas's (vertices,
    triangles, uv in texel units (k, 2) float32, page and chart of each vertex); a mesh of no
    triangles (every one charted by ``planar.py``) has none."""
    if not len(mesh[1]):
        return (0, 0, 0, 0), _no_charts()
    atlas = xatlas.Atlas()
    atlas.add_mesh(*mesh)
    atlas.generate(*_chart_options())
    vertices, triangles, uv = atlas[0]
    page, chart = atlas.get_mesh_vertex_assignment(0)
    # Vertices of faces xatlas left out sit at 0 (NaN in an atlas of no texels, 0 / 0).
    uv = np.where((page != _NO_PAGE)[:, None],
                  uv * np.array([atlas.width, atlas.height], np.float32), 0).astype(np.float32)
    return ((int(atlas.width), int(atlas.height), int(atlas.atlas_count), int(atlas.chart_count)),
            (vertices, triangles, uv, page, chart))


def _chart_all(meshes: list[_Mesh], settings: Resolved) -> list[_Charted]:
    """Every mesh's charts (``_chart``), in order: each distinct mesh once, from the cache or
    charted in forked children (``forked.py``), the meshes split by triangles among one per core
    (``settings.threads``); the split changes only who charts what, not the charts."""
    names = [chart_name(mesh) for mesh in meshes]
    first = {name: m for m, name in reversed(list(enumerate(names)))}  # each distinct mesh's first
    charted: dict[str, _Charted] = {}
    for name, m in first.items():
        stored = unwrap_cache.read(name, 1, unwrap_cache.CHARTS)
        if stored is not None and _fits(stored, [meshes[m]]):
            charted[name] = (stored[0], stored[1][0])
    missing = sorted((m for name, m in first.items() if name not in charted),
                     key=lambda m: (-len(meshes[m][1]), m))
    if missing:
        groups = _balanced(missing, [len(meshes[m][1]) for m in missing],
                           min(settings.threads or cores(), cores()))
        limit = max(_time_limit(sum(len(meshes[m][1]) for m in group),
                                sum(_texels(meshes[m]) for m in group)) for group in groups)
        runs = call_forked_together(
            [functools.partial(_chart_group, meshes, group) for group in groups],
            "the unwrapper (xatlas)", limit)
        for group, results in zip(groups, runs):
            for m, result in zip(group, results):
                charted[names[m]] = result
                unwrap_cache.write(names[m], result[0], (result[1],), unwrap_cache.CHARTS,
                                   prune=False)
        unwrap_cache.prune_kind(unwrap_cache.CHARTS)
    return [charted[name] for name in names]


@functools.cache
def _charting() -> tuple[object, ...]:
    """What besides a mesh decides its charts: xatlas's version and ``_chart_options`` (made
    once: every mesh's cache name asks for it)."""
    return (xatlas.__version__, "charts", *map(_options_of, _chart_options()))


def chart_name(mesh: _Mesh) -> str:
    """The cache name of one mesh's charts (``unwrap_cache.CHARTS``)."""
    return unwrap_cache.key([mesh], _charting())


def _chart_group(meshes: list[_Mesh], group: list[int]) -> list[_Charted]:
    """``_chart`` of the meshes ``group`` (indices into ``meshes``), in turn (one child's)."""
    return [_chart(meshes[m]) for m in group]


def _balanced(items: list[int], weights: list[int], count: int) -> list[list[int]]:
    """``items`` (heaviest first) dealt into at most ``count`` non-empty groups of about equal
    summed ``weights``: each to the lightest group so far (the first of equals)."""
    groups: list[list[int]] = [[] for _ in range(max(1, min(count, len(items))))]
    loads = [0] * len(groups)
    for item, weight in zip(items, weights):
        k = loads.index(min(loads))
        groups[k].append(item)
        loads[k] += weight
    return groups


def _texels(mesh: _Mesh) -> float:
    """Texels a mesh's charts cover: its area in texel units²."""
    if not len(mesh[1]):
        return 0.0
    cross = triangle_cross(mesh[0].astype(np.float64), mesh[1].astype(np.int64))
    return float(0.5 * np.linalg.norm(cross, axis=1).sum())


def _pack(charted: list[_Charted], parts: list[_Split], settings: Resolved, resolution: int
          ) -> _Packed:
    """The instances' charts packed together (each instance's own copy, as a UV mesh; xatlas
    finds its charts again from the triangles sharing vertices) into pages of ``resolution``
    (0: one page of the size xatlas needs), with one rectangle for every block of flat parts
    (``planar.py``), all in one UV mesh after the instances'. Each mesh's arrays refer to the
    instance's own vertices: xatlas's vertex map of the packing composed with that of the
    charting; a vertex of a face the charting left out stays without a page."""
    atlas = xatlas.Atlas()
    added = [m for m, (_header, arrays) in enumerate(charted) if len(arrays[1])]
    for m in added:
        _header, (_vertices, triangles, uv, _page, _chart) = charted[m]
        atlas.add_uv_mesh(uv, triangles)
    sizes = [part.flats.sizes for part in parts if part.flats is not None]
    if sizes:
        atlas.add_uv_mesh(*_block_quads(np.concatenate(sizes)))
    atlas.generate(xatlas.ChartOptions(), _pack_options(settings, resolution))
    rests = {}
    for slot, m in enumerate(added):
        vertices, _triangles, _uv, page, _chart = charted[m][1]
        again, triangles, uv = atlas[slot]
        packed_page, packed_chart = atlas.get_mesh_vertex_assignment(slot)
        packed_page = np.where(page[again] == _NO_PAGE, _NO_PAGE, packed_page).astype(np.uint32)
        rests[m] = (vertices[again], triangles, uv, packed_page, packed_chart)
    blocks = _placed_blocks(atlas, len(added), np.concatenate(sizes)) if sizes else None
    meshes, first = [], 0
    for m, part in enumerate(parts):
        rest = rests.get(m) or _no_charts()
        if part.flats is None:
            meshes.append(rest)
            continue
        count = len(part.flats.sizes)
        meshes.append(_with_flats(rest, part, *(b[first:first + count] for b in blocks),
                                  (atlas.width, atlas.height)))
        first += count
    return _Packed(width=int(atlas.width), height=int(atlas.height),
                   atlas_count=int(atlas.atlas_count), chart_count=int(atlas.chart_count),
                   meshes=tuple(meshes))


@dataclass(frozen=True)
class _Split:
    """One instance's mesh for ``_pack``: the triangles xatlas charts (``rest``: every vertex,
    the other triangles; ``faces``: their indices in the mesh) and the flat parts charted by
    ``planar.flat_parts`` (None when the mesh has too few)."""

    rest: _Mesh
    faces: np.ndarray
    flats: planar.FlatParts | None


def _split(meshes: list[_Mesh], settings: Resolved) -> list[_Split]:
    """Each mesh's ``_Split``, worked out once per distinct mesh (instances share theirs)."""
    room = settings.page_size - 2 * int(settings.padding)
    done: dict[str, _Split] = {}
    out = []
    for mesh in meshes:
        name = chart_name(mesh)
        if name not in done:
            flats = planar.flat_parts(*mesh, int(settings.padding), room)
            faces = np.arange(len(mesh[1]))
            if flats is not None:
                faces = np.setdiff1d(faces, flats.faces)
            done[name] = _Split(rest=(mesh[0], mesh[1][faces]), faces=faces, flats=flats)
        out.append(done[name])
    return out


def _no_charts() -> tuple[np.ndarray, ...]:
    """An instance's arrays in ``_Packed.meshes`` when xatlas charted none of its triangles."""
    empty = np.zeros(0, np.uint32)
    return empty, np.zeros((0, 3), np.uint32), np.zeros((0, 2), np.float32), empty, empty


def _block_quads(sizes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One UV mesh of a rectangle per block of flat parts, (w + 1) × (h + 1) texels for a block
    of ``sizes`` w × h: the extra texel lets ``_placed_blocks`` move the parts onto whole texels
    wherever xatlas puts the rectangle. Side by side along x, a texel apart: xatlas would take
    rectangles sharing a UV point for one chart. (4b, 2) float32 corners, (2b, 3) uint32
    triangles."""
    w, h = sizes[:, 0] + 1.0, sizes[:, 1] + 1.0
    x = np.cumsum(w + 1) - (w + 1)
    zero = np.zeros_like(w)
    corners = np.stack([np.stack([x, zero], 1), np.stack([x + w, zero], 1),
                        np.stack([x + w, h], 1), np.stack([x, h], 1)], axis=1)
    base = 4 * np.arange(len(sizes))[:, None]
    triangles = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    return corners.reshape(-1, 2).astype(np.float32), triangles.astype(np.uint32)


def _placed_blocks(atlas: xatlas.Atlas, mesh: int, sizes: np.ndarray
                   ) -> tuple[np.ndarray, ...]:
    """Where xatlas put each block's rectangle (``_block_quads``, its UV mesh ``mesh``): per
    block the page-texel point of its corner (b, 2), its steps along x and y (b, 2, 2: a
    quarter turn or a mirror as xatlas chose), its page (b,) and chart (b,). The corner is
    moved (less than a texel, within the rectangle) so that the parts' cells land on whole
    texels, as ``planar.shelves`` laid them out."""
    again, _triangles, uv = atlas[mesh]
    page, chart = atlas.get_mesh_vertex_assignment(mesh)
    corner = np.zeros((len(sizes) * 4, 2))
    corner[again] = uv.astype(np.float64) * [atlas.width, atlas.height]
    corner = corner.reshape(-1, 4, 2)
    side = sizes + 1.0
    step = np.stack([(corner[:, 1] - corner[:, 0]) / side[:, :1],
                     (corner[:, 3] - corner[:, 0]) / side[:, 1:]], axis=1)
    extent = step * sizes[:, :, None].astype(np.float64)  # (b, axis, 2): the parts' sides
    low = corner[:, 0] + np.minimum(extent, 0).sum(axis=1)
    high = corner[:, 0] + np.maximum(extent, 0).sum(axis=1)
    bound_low, bound_high = corner.min(axis=1), corner.max(axis=1)
    target = np.clip(np.round(low), np.ceil(bound_low - 1e-3),
                     np.floor(bound_high - (high - low) + 1e-3))
    vertex_of = np.zeros(len(sizes) * 4, np.int64)
    vertex_of[again] = np.arange(len(again))
    owner = vertex_of[4 * np.arange(len(sizes))]
    return (corner[:, 0] + target - low, step, page[owner].astype(np.uint32),
            chart[owner].astype(np.uint32))


def _with_flats(rest: tuple[np.ndarray, ...], part: _Split, origin: np.ndarray,
                step: np.ndarray, page: np.ndarray, chart: np.ndarray,
                page_size: tuple[int, int]) -> tuple[np.ndarray, ...]:
    """An instance's ``_Packed.meshes`` arrays: xatlas's for the triangles it charted (``rest``)
    and the flat parts moved to their blocks' places, the triangles in the mesh's order."""
    vertices, triangles, uv, pages, charts = rest
    flats = part.flats
    block = flats.block
    where = origin[block] + step[block, 0] * flats.uv[:, :1] + step[block, 1] * flats.uv[:, 1:]
    faces = np.zeros((len(part.faces) + len(flats.faces), 3), np.uint32)
    faces[part.faces] = triangles
    faces[flats.faces] = flats.triangles + len(vertices)
    return (np.concatenate([vertices, flats.vertices.astype(np.uint32)]), faces,
            np.concatenate([uv, (where / page_size).astype(np.float32)]),
            np.concatenate([pages, page[block]]), np.concatenate([charts, chart[block]]))


def _generate(scene: Scene, world: World, instances: list[int], settings: Resolved,
              resolutions: tuple[int, ...]) -> list[_Packed]:
    """The instances unwrapped, one atlas per pack resolution of ``resolutions``: each read
    whole from the cache (``unwrap_cache.py``) or made in a forked child, all at once
    (``forked.py``: xatlas's threads can crash it, and a crashed run is run again). Made by
    charting each mesh and packing (``_chart_all``, ``_pack``), or, where one instance holds
    most triangles (``_one_run``), by one xatlas run that charts and packs (``_whole``)."""
    meshes = xatlas_meshes(scene, world, instances, settings)
    parts = _split(meshes, settings)
    flat = any(part.flats is not None for part in parts)
    whole = not flat and _one_run(meshes)
    names = [unwrap_cache.key(meshes, _whole_charting(settings, resolution) if whole else (
        *_charting(), _options_of(_pack_options(settings, resolution)),
        *(planar.KEY if flat else ()))) for resolution in resolutions]
    found: list[_Packed | None] = []
    for name in names:
        stored = unwrap_cache.read(name, len(meshes))
        found.append(_Packed(*stored[0], stored[1]) if stored is not None
                     and _fits(stored, meshes) else None)
    missing = [k for k, packed in enumerate(found) if packed is None]
    if missing:
        limit = _time_limit(sum(len(t) for _, t in meshes), sum(map(_texels, meshes)))
        if whole:
            calls = [functools.partial(_whole, meshes, settings, resolutions[k]) for k in missing]
        else:
            charted = _chart_all([part.rest for part in parts], settings)
            calls = [functools.partial(_pack, charted, parts, settings, resolutions[k])
                     for k in missing]
        runs = call_forked_together(calls, "the unwrapper (xatlas)", limit)
        for k, packed in zip(missing, runs):
            found[k] = packed
            unwrap_cache.write(names[k], (packed.width, packed.height, packed.atlas_count,
                                          packed.chart_count), packed.meshes)
    least = planar.least_texels(sum(part.flats.parts for part in parts
                                    if part.flats is not None), settings.padding)
    return [replace(packed, least_texels=least) for packed in found]


def _one_run(meshes: list[_Mesh]) -> bool:
    """Whether one xatlas run should chart and pack every mesh (``_whole``): when one instance
    holds over ``_ONE_RUN`` of the triangles, charting the meshes apart gains little (that one
    is charted alone on one core) and packing charts as UV meshes costs about as much again
    (1M-triangle terrain: charting 9.9 s + packing 9.7 s against one run's 12.6 s)."""
    counts = [len(t) for _, t in meshes]
    return max(counts) > _ONE_RUN * sum(counts)


def _whole_charting(settings: Resolved, resolution: int) -> tuple[object, ...]:
    """What besides the meshes decides ``_whole``'s atlas (for the cache key)."""
    return (xatlas.__version__, "whole", _options_of(xatlas.ChartOptions()),
            _options_of(_pack_options(settings, resolution, turn=True)))


def _whole(meshes: list[_Mesh], settings: Resolved, resolution: int) -> _Packed:
    """Every mesh charted and packed in one xatlas run (charts turned to their best axis once),
    into pages of ``resolution`` (0: one page of the size xatlas needs); per mesh xatlas's
    (vertices, triangles, uv in 0–1, page and chart of each vertex), as ``_pack`` gives."""
    atlas = xatlas.Atlas()
    for mesh in meshes:
        atlas.add_mesh(*mesh)
    atlas.generate(xatlas.ChartOptions(), _pack_options(settings, resolution, turn=True))
    return _Packed(width=int(atlas.width), height=int(atlas.height),
                   atlas_count=int(atlas.atlas_count), chart_count=int(atlas.chart_count),
                   meshes=tuple((*atlas[m], *atlas.get_mesh_vertex_assignment(m))
                                for m in range(len(meshes))))


def _time_limit(triangles: int, texels: float) -> float:
    """CPU seconds an xatlas run of ``triangles`` charting ``texels`` texels may use before it
    is taken for hung (``forked.call_forked``): ``_SECONDS`` and the work's share of each."""
    return _SECONDS + triangles * _SECONDS_PER_TRIANGLE + texels * _SECONDS_PER_TEXEL


def _options_of(options: xatlas.ChartOptions | xatlas.PackOptions) -> dict[str, object]:
    """Every setting of an xatlas options object by name (for the cache key)."""
    return {name: getattr(options, name) for name in sorted(dir(options))
            if not name.startswith("_")}


def _fits(stored: tuple[tuple[int, ...], tuple[tuple[np.ndarray, ...], ...]],
          meshes: list[tuple[np.ndarray, np.ndarray]]) -> bool:
    """Whether a cache entry (``unwrap_cache.read``) has the shapes, types and index ranges
    an xatlas run of ``meshes`` gives; one that does not is run again (and rewritten)."""
    header, arrays = stored
    if len(header) != 4 or min(header) < 0:
        return False
    for (positions, triangles), (vertices, faces, uv, page, chart) in zip(meshes, arrays):
        k = len(vertices)
        if (vertices.dtype != np.uint32 or faces.dtype != np.uint32 or uv.dtype != np.float32
                or vertices.shape != (k,) or faces.shape != triangles.shape
                or page.dtype != np.uint32 or chart.dtype != np.uint32
                or uv.shape != (k, 2) or page.shape != (k,) or chart.shape != (k,)
                or (k and int(vertices.max()) >= len(positions))
                or (faces.size and int(faces.max()) >= k)):
            return False
    return True


def unwrap(scene: Scene, world: World, settings: Resolved, fit_one_page: bool = False,
           area: float | None = None) -> Atlas:
    """Unwrap the baked instances into pages of at most ``settings.page_size`` texels a side.

    One page of the size xatlas needs is tried first; if it would exceed the page size, the
    charts are packed into as many ``page_size``² pages as they need. Where the first may well
    exceed it (expected texels over ``_BESIDE`` of a page), both runs are made at once.

    ``fit_one_page`` (the derived, default density): when the charts spill onto a second page
    although their texels would fit in one, the density is lowered until they fit
    (``_fitted``); the atlas's ``texel_density`` is then the one used. ``area``: the baked
    instances' ``frame_area`` where the caller has it (summed here otherwise).
    """
    instances = baked_instances(scene)
    if not instances:
        return Atlas(width=0, height=0, page_count=0, texel_density=settings.texel_density,
                     padding=settings.padding, instances=())
    _check_triangles_fit(world, scene, instances, settings)
    area = frame_area(scene, world, instances) if area is None else area
    atlas, settings = _laid_out(scene, world, instances, settings, fit_one_page, area)
    if atlas.width == 0 or atlas.height == 0:
        raise SettingsError("no surface got any lightmap texels at this texel density",
                            fix="raise --texel-density, or check that the meshes have area")
    _check_not_shrunk(atlas, world, scene, instances, settings)
    result = []
    for mesh, i in enumerate(instances):
        vertices, triangles, uv, page_of_vertex, _chart = atlas.meshes[mesh]
        vertices, triangles = vertices.astype(np.int64), triangles.astype(np.int64)
        uv, page = _snap_unplaced(frame_positions(scene, i), vertices, uv.astype(np.float64),
                                  page_of_vertex.astype(np.int64), int(_NO_PAGE))
        result.append(InstanceUV(instance=i, vertices=vertices, triangles=triangles, uv=uv,
                                 pages=page[triangles[:, 0]]))
    return Atlas(width=int(atlas.width), height=int(atlas.height),
                 page_count=int(atlas.atlas_count), texel_density=float(settings.texel_density),
                 padding=int(settings.padding), instances=tuple(result))


def _laid_out(scene: Scene, world: World, instances: list[int], settings: Resolved,
              fit_one_page: bool, area: float) -> tuple[_Packed, Resolved]:
    """The atlas (``_packed``, then ``_fitted`` where asked and the charts spill) and the
    settings with the density it has. What a fit came to is kept in the unwrap cache
    (``unwrap_cache.FITS``, named by ``_fit_name``): a bake of the same meshes reads it back
    without the layouts the fit went through (three xatlas layouts read, for a scene of many
    objects most of the cached unwrap's time). ``area``: the instances' ``frame_area``."""
    if not fit_one_page:
        return _packed(scene, world, instances, settings, area)[0], settings
    meshes = xatlas_meshes(scene, world, instances, settings)
    name = _fit_name(meshes, settings)
    stored = unwrap_cache.read(name, len(meshes), unwrap_cache.FITS)
    if stored is not None and len(stored[0]) == 5 and _fits((stored[0][:4], stored[1]), meshes):
        density = float(np.int64(stored[0][4]).view(np.float64))
        return _Packed(*stored[0][:4], stored[1]), replace(settings, texel_density=density)
    atlas, sized = _packed(scene, world, instances, settings, area)
    if atlas.atlas_count <= 1:  # one page, or none (no texels: ``unwrap`` says so)
        return atlas, settings
    atlas, fitted = _fitted(scene, world, instances, settings, area, atlas, sized)
    density = int(np.float64(fitted.texel_density).view(np.int64))
    unwrap_cache.write(name, (atlas.width, atlas.height, atlas.atlas_count, atlas.chart_count,
                              density), atlas.meshes, unwrap_cache.FITS)
    return atlas, fitted


def _fit_name(meshes: list[_Mesh], settings: Resolved) -> str:
    """The cache name of what ``_fitted`` makes of ``meshes`` (at ``settings``' density): every
    option any layout on its way depends on, and its own constants."""
    page = settings.page_size
    return unwrap_cache.key(meshes, (
        "fitted to one page", _FIT_MARGIN, _FIT_TRIES, _BESIDE, _ONE_RUN, *_charting(),
        _options_of(_pack_options(settings, page)), _whole_charting(settings, page),
        *planar.KEY))


def _packed(scene: Scene, world: World, instances: list[int], settings: Resolved,
            area: float) -> tuple[_Packed, _Packed | None]:
    """The atlas at ``settings.texel_density`` (see ``unwrap``), and the run in one page of
    the size xatlas chose itself when one was made (None otherwise): its size says how much
    the charts must shrink to fit one page. ``area``: the instances' ``frame_area``."""
    expected = area * settings.texel_density ** 2
    page = settings.page_size
    if expected > 0.5 * page ** 2:
        [atlas] = _generate(scene, world, instances, settings, (page,))
        return atlas, None
    if expected > _BESIDE * page ** 2 and settings.threads != 1 and cores() > 1:
        sized, paged = _generate(scene, world, instances, settings, (0, page))
    else:
        [sized] = _generate(scene, world, instances, settings, (0,))
        if max(sized.width, sized.height) <= page:
            return sized, sized
        [paged] = _generate(scene, world, instances, settings, (page,))
    return (paged if max(sized.width, sized.height) > page else sized), sized


def _fitted(scene: Scene, world: World, instances: list[int], settings: Resolved, area: float,
            atlas: _Packed, sized: _Packed | None) -> tuple[_Packed, Resolved]:
    """The atlas in one page at a lower density when the charts' texels fit in one, else
    ``atlas`` (spilled onto several pages) at ``settings``' density as it was.

    The charts fit when their texels (``_chart_texels``), and the least their flat parts need at
    any density with their padding (``planar.least_texels``), are at most a page's; the density is
    then scaled by the page side over the side of the one page xatlas sized itself
    (``sized``), less ``_FIT_MARGIN``, and packed again; padding does not shrink with the
    charts, so up to ``_FIT_TRIES`` rounds. Deterministic: each round is a pure function of
    the last one's atlas (and each is kept in the unwrap cache). ``area``: as ``_packed``.
    """
    page = settings.page_size
    if max(_chart_texels(atlas), atlas.least_texels) > page * page:
        return atlas, settings
    if sized is None:
        [sized] = _generate(scene, world, instances, settings, (0,))
    trial = settings
    for _round in range(_FIT_TRIES):
        side = max(sized.width, sized.height)
        trial = replace(trial, texel_density=_round_down(
            trial.texel_density * page / side * _FIT_MARGIN))
        found, sized = _packed(scene, world, instances, trial, area)
        if found.atlas_count == 1 and max(found.width, found.height) <= page:
            return found, trial
        if sized is None:  # the lower density still expects over half a page: give up
            break
    return atlas, settings


def _chart_texels(atlas: _Packed) -> float:
    """Texels the charts of ``atlas`` cover, summed over its pages (their UV area)."""
    total = 0.0
    for _vertices, faces, uv, _page, _chart in atlas.meshes:
        corners = uv.astype(np.float64)[faces.astype(np.int64)] * [atlas.width, atlas.height]
        a, b = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
        total += 0.5 * float(np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum())
    return total


def _snap_unplaced(frame: np.ndarray, vertices: np.ndarray, uv: np.ndarray,
                   page: np.ndarray, no_page: int) -> tuple[np.ndarray, np.ndarray]:
    """Give vertices xatlas left unplaced the UV and page of the nearest placed vertex.

    xatlas leaves out faces it finds degenerate; collapsing them onto the closest placed point
    (in the instance's rigid-free frame, ``frame`` (n, 3)) of the same instance gives them a real texel to read, so no face of the
    output samples outside the lightmap. Returns uv (k, 2) and page (k,), -1 where the instance
    has no placed vertex at all.
    """
    lost = page == no_page
    if not lost.any():
        return uv, page
    placed = np.flatnonzero(~lost)
    page = np.where(lost, -1, page)
    if placed.size == 0:
        return uv, page
    where = frame[vertices]
    uv, page = uv.copy(), page.copy()
    for chunk in np.array_split(np.flatnonzero(lost), max(1, int(np.flatnonzero(lost).size // 256))):
        distance = np.linalg.norm(where[chunk, None] - where[None, placed], axis=-1)
        nearest = placed[np.argmin(distance, axis=1)]
        uv[chunk], page[chunk] = uv[nearest], page[nearest]
    return uv, page


def _check_not_shrunk(atlas: _Packed, world: World, scene: Scene, instances: list[int],
                      settings: Resolved) -> None:
    """Raise PageTooSmall when xatlas shrank a chart to fit it in a page.

    xatlas scales down, silently, a chart larger than a page: its texels then stand for more than
    1 / texel_density world units. A chart's scale is the summed length of its edges in texels
    over their world length × density (≈ 1 for a chart that was not shrunk, thin or not); one
    below ``_SHRUNK`` whose bounds fill the page was shrunk.
    """
    corners, charts, tris, label = [], [], [], []
    for mesh, i in enumerate(instances):
        _vertices, triangles, uv, _page, chart = atlas.meshes[mesh]
        chart_of = chart.astype(np.int64)[triangles[:, 0].astype(np.int64)]
        placed = (chart_of >= 0) & (chart_of < atlas.chart_count)
        if not placed.any() or len(placed) != len(world.instance_triangles(i)):
            continue
        corners.append(uv.astype(np.float64)[triangles.astype(np.int64)[placed]])
        charts.append(chart_of[placed] + len(label) * atlas.chart_count)  # (instance, chart)
        tris.append(world.instance_triangles(i)[placed])
        label.append(i)
    if not label:
        return
    # Every instance at once; np.unique orders the charts by instance, then by chart.
    corners = np.concatenate(corners) * [atlas.width, atlas.height]
    ids, inverse = np.unique(np.concatenate(charts), return_inverse=True)
    uv_length, world_length, extent = _chart_spans(
        corners, world.positions, world.triangles, np.concatenate(tris),
        inverse.reshape(-1), len(ids))
    label = np.asarray(label)[ids // atlas.chart_count]
    wanted = world_length * settings.texel_density
    scale = np.divide(uv_length, wanted, out=np.ones_like(uv_length), where=wanted > 0)
    room = settings.page_size - 2 * settings.padding
    shrunk = (scale < _SHRUNK) & (extent > 0.75 * room)
    if not shrunk.any():
        return
    worst = int(np.argmin(np.where(shrunk, scale, np.inf)))
    need = extent[worst] / scale[worst]
    fits = _round_down(settings.texel_density * scale[worst] * 0.98)
    page = int(2 ** np.ceil(np.log2(need + 2 * settings.padding + 2)))
    inst = scene.instances[label[worst]]
    prim = scene.primitives[inst.primitive]
    where = f"nodes[{inst.node}] meshes[{prim.mesh}].primitives[{prim.index}]"
    bigger = f", or --page-size {page} or more" if page <= 16384 else ""
    raise PageTooSmall(
        f"at texel density {settings.texel_density:g} a chart of {where} needs about "
        f"{need:.0f} texels a side, more than a page of {settings.page_size} holds",
        texel_density=fits, fix=f"use --texel-density {fits:g} or less{bigger}")


@jit
def _chart_spans(corners: np.ndarray, positions: np.ndarray, triangles: np.ndarray,
                 tris: np.ndarray, chart: np.ndarray, count: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per chart of ``count``: the summed edge lengths of its triangles in texels (their page
    ``corners`` (n, 3, 2)) and in world units (world triangles ``tris`` (n,)), and the larger
    side of its bounds in texels, (count,) each; triangle i belongs to ``chart[i]``. One pass
    (numpy's reductions over the three corners took most of ``_check_not_shrunk``'s time)."""
    texels, metres = np.zeros(count), np.zeros(count)
    low, high = np.full((count, 2), np.inf), np.full((count, 2), -np.inf)
    for i in range(len(tris)):
        k = chart[i]
        for j in range(3):
            e = (j + 1) % 3
            du, dv = corners[i, j, 0] - corners[i, e, 0], corners[i, j, 1] - corners[i, e, 1]
            texels[k] += np.sqrt(du * du + dv * dv)
            p, q = triangles[tris[i], j], triangles[tris[i], e]
            dx, dy, dz = (positions[p, 0] - positions[q, 0], positions[p, 1] - positions[q, 1],
                          positions[p, 2] - positions[q, 2])
            metres[k] += np.sqrt(dx * dx + dy * dy + dz * dz)
            for axis in range(2):
                low[k, axis] = min(low[k, axis], corners[i, j, axis])
                high[k, axis] = max(high[k, axis], corners[i, j, axis])
    extent = np.maximum(high[:, 0] - low[:, 0], high[:, 1] - low[:, 1])
    return texels, metres, extent


def _check_triangles_fit(world: World, scene: Scene, instances: list[int], settings: Resolved) -> None:
    """Raise PageTooSmall, before xatlas runs, when one triangle is longer than a page holds.

    A chart holds at least one whole triangle, so such a triangle means a chart xatlas would
    have to shrink; and xatlas, given triangles of 10⁷ texels next to ones of 10⁻⁷ in float32,
    can spin for ever instead. Checked on the longest edge of every baked triangle.
    """
    room = settings.page_size - 2 * settings.padding - 2
    tris = np.concatenate([world.instance_triangles(i) for i in instances])
    if not len(tris):
        return
    a, b, c = world.corners(tris)
    edges = np.stack([np.linalg.norm(p - q, axis=1) for p, q in ((a, b), (b, c), (c, a))], 1)
    worst = int(np.argmax(edges.max(axis=1)))
    longest, owner = float(edges[worst].max()), int(world.tri_instance[tris[worst]])
    if longest * settings.texel_density <= room:
        return
    fits = _round_down(room / longest * 0.98)
    page = int(2 ** np.ceil(np.log2(longest * settings.texel_density + 2 * settings.padding + 2)))
    bigger = f", or --page-size {page} or more" if page <= 16384 else ""
    inst = scene.instances[owner]
    prim = scene.primitives[inst.primitive]
    where = f"nodes[{inst.node}] meshes[{prim.mesh}].primitives[{prim.index}]"
    raise PageTooSmall(
        f"at texel density {settings.texel_density:g} a triangle of {where} is "
        f"{longest * settings.texel_density:.3g} texels long, more than a page of "
        f"{settings.page_size} holds", texel_density=fits,
        fix=f"use --texel-density {fits:g} or less{bigger}, or look for stray vertices")


def _round_down(value: float, digits: int = 3) -> float:
    """``value`` cut (never rounded up) to ``digits`` significant digits."""
    if value <= 0:
        return value
    step = 10.0 ** (np.floor(np.log10(value)) - digits + 1)
    return float(np.floor(value / step) * step)
