"""Lay every baked instance out in lightmap pages.

Two steps. Charts: each distinct mesh, in its instance's rigid-free frame (``frame_positions``:
local positions × the stretch part of its world matrix), is charted once, in world units
(``charts.py``: by projection, ``planar.py``, or by xatlas where projection declines), cached
by its content. Packing: every baked instance's own copy of its mesh's charts, scaled to the
texel density, each chart in a rectangle of whole texels, packed into pages
(``packing.py``), so that one texel covers about 1 / texel_density world units everywhere and
every instance gets its own area. The charts hold no density: a bake at another density packs
the cached charts again, in well under a second. Both steps are pure functions of their input,
so the atlas does not depend on the cores or the cache; and moving or turning a node leaves it
bit for bit as it was (incremental rebake).
"""

from __future__ import annotations

import functools
from dataclasses import replace
from typing import Callable

import numpy as np

from baker.atlas import packing
from baker.atlas.charts import chart_meshes
from baker.atlas.layout import Atlas, Charts, InstanceUV
from baker.errors import SettingsError
from baker.geometry.world import World, triangle_cross
from baker.gltf.scene import Scene
from baker.jit import jit
from baker.run.progress import Steps
from baker.settings import Resolved

_MARGIN = 0.01  # texels: a chart is kept this far inside its rectangle's texels, centred
# A derived density whose charts spill onto a second page is lowered by this factor at a time,
# down to this share of itself at most, until they fit one (``_fitted``).
_FIT_STEP, _FIT_FLOOR = 0.95, 0.5


class PageTooSmall(SettingsError):
    """A chart does not fit in one page at the texel density asked for. ``texel_density`` is the
    highest density at which it fits (xatlas would otherwise shrink it without a word)."""

    def __init__(self, message: str, *, texel_density: float, fix: str):
        super().__init__(message, fix=fix)
        self.texel_density = texel_density


def baked_instances(scene: Scene) -> list[int]:
    """Indices of the instances that get lightmap texels, in scene order."""
    return [i for i, inst in enumerate(scene.instances) if inst.baked]


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


def frame_meshes(scene: Scene, world: World, instances: list[int]
                 ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each instance's mesh as it is charted: positions in its rigid-free frame
    (``frame_positions``, (n, 3) float64 world units) and triangles (m, 3) int64, corners in
    ``World.triangles``' order. Instances of one primitive whose matrices stretch it alike
    share the same two arrays (the same objects: 20,000 instances of a crate are one mesh to
    name and chart, ``charts.chart_meshes``)."""
    made: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
    out = []
    for i in instances:
        inst = scene.instances[i]
        triangles = world.triangles[world.instance_triangles(i)] - world.vertex_start[i]
        alike = (inst.primitive, stretch(inst.world[:3, :3]).tobytes())
        if alike not in made or not np.array_equal(made[alike][1], triangles):
            made[alike] = (frame_positions(scene, i), triangles)
        out.append(made[alike])
    return out


def unwrap(scene: Scene, world: World, settings: Resolved, fit_one_page: bool = False,
           steps: Steps | None = None, chart_elsewhere: Callable | None = None) -> Atlas:
    """Unwrap the baked instances into pages of at most ``settings.page_size`` texels a side.

    One page sized to the charts when they fit in one, else as many ``page_size``² pages as
    they need (``packing.py``). ``fit_one_page`` (the derived, default density): when the
    charts spill onto a second page, the density is lowered until they fit one (``_fitted``);
    the atlas's ``texel_density`` is then the one used. ``steps``: the triangles charted,
    as they are; ``chart_elsewhere``: who charts the meshes not cached, if not forked children
    here (``charts.chart_meshes``: a cluster's workers).
    """
    instances = baked_instances(scene)
    if not instances:
        return Atlas(width=0, height=0, page_count=0, texel_density=settings.texel_density,
                     padding=settings.padding, instances=())
    _check_triangles_fit(world, scene, instances, settings)
    charts = chart_meshes(frame_meshes(scene, world, instances), settings.threads, steps,
                          chart_elsewhere, str(scene.path.absolute()))
    _check_charts_fit(charts, scene, instances, settings)
    density = settings.texel_density
    packed = _packed(charts, density, settings)
    if fit_one_page and packed.pages > 1:
        density, packed = _fitted(charts, settings, packed)
    if packed.pages == 0:
        raise SettingsError("no surface got any lightmap texels at this texel density",
                            fix="raise --texel-density, or check that the meshes have area")
    return Atlas(width=packed.width, height=packed.height, page_count=packed.pages,
                 texel_density=float(density), padding=int(settings.padding),
                 instances=tuple(_placed(charts, instances, density, packed)))


def _cells(charts: list[Charts], density: float) -> tuple[np.ndarray, np.ndarray]:
    """Every instance's charts in turn: their sides at ``density`` (c, 2) texels, and the
    rectangles of whole texels that hold them (c, 2) int64, ``_MARGIN`` inside."""
    wanted = np.concatenate([c.sides for c in charts]) * density
    return wanted, np.floor(wanted + 2 * _MARGIN).astype(np.int64) + 1


def _packed(charts: list[Charts], density: float, settings: Resolved) -> packing.Packed:
    """The charts' rectangles at ``density`` packed into pages (``packing.pack``). Charts of
    no extent (degenerate triangles collapsed to a point, ``planar._no_area``) get no texels:
    they all share the first one's rectangle."""
    extent, cells = _cells(charts, density)
    point = ~extent.any(axis=1)
    if np.count_nonzero(point) < 2:
        return packing.pack(cells, settings.padding, settings.page_size)
    keep = ~point
    keep[np.argmax(point)] = True
    packed = packing.pack(cells[keep], settings.padding, settings.page_size)
    row = np.cumsum(keep) - 1
    row[point] = row[np.argmax(point)]
    return replace(packed, page=packed.page[row], corner=packed.corner[row],
                   turned=packed.turned[row])


def _fitted(charts: list[Charts], settings: Resolved, spilled: packing.Packed
            ) -> tuple[float, packing.Packed]:
    """The first density of ``settings``' times ``_FIT_STEP``, ``_FIT_STEP``², … (cut to three
    digits) down to ``_FIT_FLOOR`` of it at which the charts pack into one page, and that
    packing; ``settings``' density and ``spilled`` when none does."""
    density = settings.texel_density
    trial = density
    while True:
        trial = _round_down(trial * _FIT_STEP)
        if trial < _FIT_FLOOR * density:
            return density, spilled
        packed = _packed(charts, trial, settings)
        if packed.pages == 1:
            return trial, packed


def _placed(charts: list[Charts], instances: list[int], density: float,
            packed: packing.Packed) -> list[InstanceUV]:
    """Each instance's ``InstanceUV``: its charts' vertices scaled to ``density``, each chart
    in the middle of its rectangle, turned where the packing turned it, in page UV."""
    extent, cells = _cells(charts, density)
    inset = (cells - extent) / 2
    size = np.array([packed.width, packed.height], np.float64)
    first = np.cumsum([0] + [len(mesh.sides) for mesh in charts])[:-1]
    alike: dict[int, list[int]] = {}  # the instances of each Charts object, by its id
    for k, mesh in enumerate(charts):
        alike.setdefault(id(mesh), []).append(k)
    out: list[InstanceUV | None] = [None] * len(charts)
    for group in alike.values():  # every instance of one mesh at once: (g, k) arrays
        mesh = charts[group[0]]
        rect = first[group][:, None] + mesh.chart[None, :]
        x, y = mesh.uv[:, 0] * density, mesh.uv[:, 1] * density
        ex, ix, iy = extent[rect, 0], inset[rect, 0], inset[rect, 1]
        turned = packed.turned[rect]
        at = packed.corner[rect].astype(np.float64)
        page_x = at[..., 0] + np.where(turned, iy + y, ix + x)
        page_y = at[..., 1] + np.where(turned, ix + (ex - x), iy + y)
        uv = np.stack([page_x, page_y], axis=-1) / size
        pages = packed.page[rect[:, mesh.triangles[:, 0]]]
        for row, k in enumerate(group):
            out[k] = InstanceUV(instance=instances[k], vertices=mesh.vertices,
                                triangles=mesh.triangles, uv=uv[row], pages=pages[row])
    return out


def _check_charts_fit(charts: list[Charts], scene: Scene, instances: list[int],
                      settings: Resolved) -> None:
    """Raise PageTooSmall when a chart's rectangle is larger than a page holds at the density
    asked for (``texel_density`` of the error: the highest at which it fits)."""
    room = settings.page_size
    extent, cells = _cells(charts, settings.texel_density)
    if not len(cells) or cells.max() <= room:
        return
    worst = int(np.argmax(cells.max(axis=1)))
    owner = int(np.searchsorted(np.cumsum([len(c.sides) for c in charts]), worst, side="right"))
    side = float(extent[worst].max()) / settings.texel_density
    fits = _round_down((room - 1) / side)
    page = int(2 ** np.ceil(np.log2(extent[worst].max() + 2)))
    bigger = f", or --page-size {page} or more" if page <= 16384 else ""
    inst = scene.instances[instances[owner]]
    prim = scene.primitives[inst.primitive]
    where = f"nodes[{inst.node}] meshes[{prim.mesh}].primitives[{prim.index}]"
    raise PageTooSmall(
        f"at texel density {settings.texel_density:g} a chart of {where} needs about "
        f"{extent[worst].max():.0f} texels a side, more than a page of {settings.page_size} "
        f"holds", texel_density=fits, fix=f"use --texel-density {fits:g} or less{bigger}")


def _check_triangles_fit(world: World, scene: Scene, instances: list[int], settings: Resolved) -> None:
    """Raise PageTooSmall, before any charting, when one triangle is longer than a page holds.

    A chart holds at least one whole triangle, so such a triangle means a chart too large for
    a page, and most likely a stray vertex: the message says so. Checked on the longest edge
    of every baked triangle.
    """
    room = settings.page_size - 2 * settings.padding - 2
    tris = np.concatenate([world.instance_triangles(i) for i in instances])
    if not len(tris):
        return
    longest, worst = _longest_edge(world.positions, world.triangles, tris)
    owner = int(world.tri_instance[tris[worst]])
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


@jit
def _longest_edge(positions, triangles, tris):
    """The longest edge of the triangles ``tris`` (world units) and its triangle's place in
    ``tris`` (the first of equals; 0 when every length is NaN)."""
    best, worst = 0.0, 0
    for i in range(len(tris)):
        for k in range(3):
            p, q = triangles[tris[i], k], triangles[tris[i], (k + 1) % 3]
            dx = positions[p, 0] - positions[q, 0]
            dy = positions[p, 1] - positions[q, 1]
            dz = positions[p, 2] - positions[q, 2]
            length = np.sqrt(dx * dx + dy * dy + dz * dz)
            if length > best:
                best, worst = length, i
    return best, worst


def _round_down(value: float, digits: int = 3) -> float:
    """``value`` cut (never rounded up) to ``digits`` significant digits."""
    if value <= 0:
        return value
    step = 10.0 ** (np.floor(np.log10(value)) - digits + 1)
    return float(np.floor(value / step) * step)
