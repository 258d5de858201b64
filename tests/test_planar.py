"""Meshes charted by projection (``planar.py``) and charts' rectangles packed (``packing.py``).

Checked on generated leaves, boxes, spheres, ramps and grids (random sizes, turns, counts):
every chart keeps its surface's area, no triangle turns over or overlaps another, flat parts
keep their shape; what projection cannot chart is left to xatlas; packed rectangles keep their
padding apart. In the atlas ``unwrap`` makes of a tree: every leaf and blade is as long in
texels as in metres × density, touches only the texels its rectangle needs, and keeps
2·padding free texels from every other chart; a rigid move of the node leaves the atlas bit
for bit."""

from __future__ import annotations

import numpy as np
import pytest

from assets.foliage_scenes import leaves, tree
from assets.gltf_builder import rock, rotation_matrix, uv_sphere
from assets.many_objects import grid_box
from baker.atlas import charts as charting
from baker.atlas import packing, planar
from baker.atlas.rasterise import _cover_kernel, _edge_terms
from baker.atlas.unwrap import _MARGIN, _packed, unwrap
from baker.geometry.world import build_world
from baker.settings import Settings, resolve
from tests.bakehelp import loaded


def _touched(corners: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width) bool: the texels the UV triangles (t, 3, 2) in texels overlap
    (the rasteriser's own conservative test)."""
    normals, offsets = _edge_terms(corners)
    depth = np.full(width * height, -np.inf)
    owner = np.full(width * height, -1, np.int32)
    _cover_kernel(corners, normals, offsets, np.zeros(len(corners), np.int64), width, height,
                  depth, owner, np.zeros(len(corners), np.int64))
    return (owner >= 0).reshape(height, width)


def _check_charts(charts, positions, triangles):
    """The invariants of any ``Charts`` of a mesh: every triangle once, its corners its own
    vertices; each chart inside its rectangle from (0, 0); each chart's UV area its surface's
    (the projection's scale); no triangle turned over or overlapping another of its chart."""
    p = np.asarray(positions, np.float64)
    np.testing.assert_array_equal(charts.vertices[charts.triangles], triangles)
    assert (charts.uv >= -1e-9).all()
    assert (charts.uv <= charts.sides[charts.chart] + 1e-9).all()
    for c in range(len(charts.sides)):
        assert np.isclose(charts.uv[charts.chart == c].min(axis=0), 0).all()
    corner = charts.uv[charts.triangles]
    e, f = corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0]
    uv_area = 0.5 * (e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0])
    surface = 0.5 * np.linalg.norm(np.cross(p[triangles[:, 1]] - p[triangles[:, 0]],
                                            p[triangles[:, 2]] - p[triangles[:, 0]]), axis=1)
    assert (uv_area > -1e-12).all(), "a triangle turned over"
    chart_of = charts.chart[charts.triangles[:, 0]]
    count = len(charts.sides)
    np.testing.assert_allclose(np.bincount(chart_of, uv_area, count),
                               np.bincount(chart_of, surface, count), rtol=1e-9)
    for c in range(count):
        _assert_apart(corner[(chart_of == c) & (uv_area > 0)])


def _assert_apart(corners, tolerance: float = 1e-9):
    """No two triangles (t, 3, 2) share an inner point (``_apart_pairs``)."""
    if len(corners) >= 2:
        assert _apart_pairs(corners, tolerance).all(), "two triangles of a chart overlap"


def _apart_pairs(corners, tolerance: float = 1e-9) -> np.ndarray:
    """(t, t) bool: whether each two triangles (t, 3, 2, counter-clockwise) share no inner
    point: some edge of one has the whole other on its outer side, within ``tolerance`` of
    their extent (every pair tested, no grid)."""
    apart = np.zeros((len(corners), len(corners)), bool)
    size = np.ptp(corners.reshape(-1, 2), axis=0).max()
    for k in range(3):  # triangles counter-clockwise: (dy, -dx) points out of edge a → b
        a, b = corners[:, k], corners[:, (k + 1) % 3]
        normal = np.stack([b[:, 1] - a[:, 1], a[:, 0] - b[:, 0]], axis=1)
        reach = tolerance * size * np.linalg.norm(normal, axis=1)
        edge = np.einsum("ij,ij->i", a, normal)
        nearest = np.minimum.reduce([np.outer(normal[:, 0], corners[:, m, 0])
                                     + np.outer(normal[:, 1], corners[:, m, 1])
                                     for m in range(3)])  # (i, p)
        apart |= nearest >= edge[:, None] - reach[:, None]
    apart |= apart.T
    np.fill_diagonal(apart, True)
    return apart


def test_the_overlap_test_finds_what_testing_every_pair_finds():
    """``planar._overlapping`` on long thin triangles at a random turn (strips of a grid,
    which a grid of cells bins badly by their bounding boxes), apart, and with one of them
    moved by a random offset: overlapping exactly when testing every pair (``_apart_pairs``)
    finds two that overlap, and never before the move."""
    overlapped = 0
    for seed in range(8):
        rng = np.random.default_rng(seed)
        rows, length = int(rng.integers(20, 200)), rng.uniform(0.3, 3.0)
        y = np.linspace(0.0, 1.0, rows + 1)
        low = np.stack([np.zeros(rows + 1), y], axis=1)
        flat = np.concatenate([low, low + [length, 0.0]]) @ rotation_matrix(
            (0, 0, 1), rng.uniform(0, 360))[:2, :2].T
        k = np.arange(rows)
        corners = np.concatenate([np.stack([k, k + rows + 1, k + 1], 1),
                                  np.stack([k + 1, k + rows + 1, k + rows + 2], 1)])

        def found() -> bool:
            return bool(planar._overlapping(flat, corners, np.arange(len(corners)),
                                            np.array([0, len(corners)]), 1e-9)[0])
        assert not found() and _apart_pairs(flat[corners]).all()
        one = int(rng.integers(len(corners)))  # moved: a triangle of its own corners
        flat = np.concatenate([flat, flat[corners[one]] + rng.uniform(-0.3, 0.3, 2)])
        corners[one] = len(flat) - 3 + np.arange(3)
        assert found() == (not _apart_pairs(flat[corners]).all()), seed
        overlapped += found()
    assert overlapped >= 4


@pytest.mark.parametrize("seed", range(3))
def test_leaves_keep_their_shape_and_get_the_smallest_edge_aligned_rectangle(seed):
    """Leaf quads of random sizes and turns: one chart each, every edge its length, and a
    quad's rectangle its own two sides (the least-area one of its hull's sides)."""
    rng = np.random.default_rng(seed)
    count = int(rng.integers(20, 400))
    positions, triangles, _normals, _uv = leaves(count, (0, 0, 0), (30, 20, 30), 1.0, seed)
    scale = rng.uniform(0.3, 6.0, (count, 1))
    centres = positions.reshape(count, 4, 3).mean(axis=1, keepdims=True)
    positions = (centres + (positions.reshape(count, 4, 3) - centres) * scale[:, None]).reshape(-1, 3)
    charts = planar.project(positions, triangles)
    assert charts is not None and len(charts.sides) == count
    _check_charts(charts, positions, triangles)
    p = positions[charts.vertices]
    for k in range(3):
        a, b = charts.triangles[:, k], charts.triangles[:, (k + 1) % 3]
        np.testing.assert_allclose(np.linalg.norm(charts.uv[a] - charts.uv[b], axis=1),
                                   np.linalg.norm(p[a] - p[b], axis=1), rtol=1e-9)
    quad_of = np.arange(len(triangles)) % count  # triangles part and part + count: one quad
    sides = np.sort(charts.sides[charts.chart[charts.triangles[np.argsort(quad_of)[::2], 0]]])
    np.testing.assert_allclose(sides, np.repeat(scale, 2, axis=1), rtol=1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_a_turned_box_of_split_faces_is_six_charts_of_its_faces(seed):
    """A box of random sides and turn, each face cut in squares with vertices of its own (flat
    normals): six charts, each its face's two sides."""
    rng = np.random.default_rng(seed)
    size = rng.uniform(0.1, 3.0, 3)
    positions, triangles, _n, _uv = grid_box(size, int(rng.integers(1, 8)))
    positions = positions @ rotation_matrix(rng.normal(size=3), rng.uniform(0, 360)).T
    charts = planar.project(positions, triangles)
    assert charts is not None and len(charts.sides) == 6
    _check_charts(charts, positions, triangles)
    faces = sorted(tuple(sorted(size[[a, b]])) for a, b in ((0, 1), (1, 2), (0, 2)) * 2)
    found = np.sort(charts.sides, axis=1)
    found = found[np.lexsort((found[:, 1].round(6), found[:, 0].round(6)))]
    np.testing.assert_allclose(found, faces, rtol=1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_loose_degenerate_triangles_take_no_room_in_the_atlas(seed):
    """A box beside thousands of loose triangles of no area (points and segments scattered
    around it, as a file of zero indices makes): the box keeps its six charts; the others are
    points (sides 0) and share one rectangle, so the atlas is about the box's alone."""
    rng = np.random.default_rng(seed)
    positions, triangles, _n, _uv = grid_box(rng.uniform(0.5, 2.0, 3), 2)
    count = 3000
    loose = rng.uniform(-5, 5, (count, 3, 3))
    loose[:, 2] = loose[:, 1]  # a segment: two corners at one place
    loose[: count // 2] = loose[: count // 2, :1]  # half of them a point: one place thrice
    joined = np.concatenate([positions, loose.reshape(-1, 3)])
    extra = len(positions) + np.arange(3 * count).reshape(-1, 3)
    both = planar.project(joined, np.concatenate([triangles, extra]))
    box = planar.project(positions, triangles)
    assert both is not None and box is not None
    _check_charts(both, joined, np.concatenate([triangles, extra]))
    degenerate = both.chart[both.triangles[len(triangles):, 0]]
    assert not both.sides[degenerate].any()
    np.testing.assert_array_equal(np.sort(np.delete(both.sides, degenerate, axis=0), axis=0),
                                  np.sort(box.sides, axis=0))
    settings = resolve(Settings(page_size=256, texel_density=20.0), 10.0, 1.0)
    alone, with_loose = _packed([box], 20.0, settings), _packed([both], 20.0, settings)
    assert with_loose.pages == alone.pages == 1
    assert with_loose.width * with_loose.height <= 1.2 * alone.width * alone.height


@pytest.mark.parametrize("rings", [6, 24, 56])
def test_a_sphere_is_charted_in_caps_within_the_cone(rings):
    """A sphere: charts whose normals lie within ``CONE`` of one another's seed, so within
    2·CONE of each other; every invariant of a chart holds."""
    positions, triangles, _n, _uv = uv_sphere(0.8, rings, 2 * rings)
    charts = planar.project(positions, triangles)
    assert charts is not None
    _check_charts(charts, positions, triangles)
    p = positions[triangles]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    chart_of = charts.chart[charts.triangles[:, 0]]
    for c in range(len(charts.sides)):
        n = normal[chart_of == c]
        assert (n @ n.T).min() >= np.cos(np.radians(2 * planar.CONE)) - 1e-9


def _ramp(turns: int, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """A ramp winding ``turns`` times round, 1 to 2 m from its axis, rising 0.05 m a radian:
    (positions, triangles) of 2 · ``steps`` triangles, its normals all near up."""
    angle = np.linspace(0, 2 * np.pi * turns, steps + 1)
    inner = np.stack([np.cos(angle), angle * 0.05, np.sin(angle)], axis=1)
    k = np.arange(steps)
    return (np.concatenate([inner, inner * [2.0, 1.0, 2.0]]),
            np.concatenate([np.stack([k, k + 1, k + steps + 1], 1),
                            np.stack([k + 1, k + steps + 2, k + steps + 1], 1)]))


def test_a_helical_ramp_is_charted_in_pieces_and_a_crumpled_surface_left_to_xatlas():
    """A ramp winding twice round (one chart, overlapping itself once projected) is grown
    again in narrower cones until no chart overlaps itself, none turned over, each keeping
    its area (it went to xatlas whole before); a grid of random heights (charts of a triangle
    or two): None."""
    steps = 160
    positions, triangles = _ramp(2, steps)
    charts = planar.project(positions, triangles)
    assert charts is not None and len(charts.sides) > 2  # two turns: no chart a whole turn
    _check_charts(charts, positions, triangles)
    part = np.concatenate([triangles[: steps // 3], triangles[steps: steps + steps // 3]])
    two_thirds = planar.project(positions, part)  # two thirds of a turn: flat, whole
    assert two_thirds is not None and len(two_thirds.sides) == 1
    rng = np.random.default_rng(0)
    side = 20
    x, z = np.meshgrid(np.arange(side + 1.0), np.arange(side + 1.0), indexing="ij")
    heights = rng.uniform(-1.0, 1.0, x.shape)
    grid = np.stack([x.ravel(), heights.ravel(), z.ravel()], axis=1)
    a = (np.arange(side)[:, None] * (side + 1) + np.arange(side)).ravel()
    cells = np.concatenate([np.stack([a, a + 1, a + side + 2], 1),
                            np.stack([a, a + side + 2, a + side + 1], 1)])
    assert planar.project(grid, cells) is None
    assert planar.project(grid * [1.0, 0.01, 1.0], cells) is not None  # flattened: one chart


@pytest.mark.parametrize("split", [False, True])
def test_meshes_projected_together_get_the_charts_each_gets_alone(split):
    """``project_many`` over boxes, spheres, ramps (split into narrower cones, or declined),
    crumpled grids and rocks (declined), leaves, random triangle soups (shared corners,
    degenerate and repeated triangles) and a mesh laid over another (the same positions: no
    welding across meshes), shuffled: for each mesh the arrays and types ``project`` gives it
    alone, or None where it does (every invariant of a chart holding but on the soups, whose
    repeated triangles overlap alone as well)."""
    rng = np.random.default_rng(7 + split)
    meshes = [grid_box(rng.uniform(0.1, 3.0, 3), int(rng.integers(1, 5)))[:2] for _ in range(4)]
    meshes += [uv_sphere(0.8, rings, 2 * rings)[:2] for rings in (3, 12)]
    meshes += [_ramp(2, 160), _ramp(1, 40), rock(1.0, 2, 1)[:2],
               leaves(30, (0, 0, 0), (3, 2, 3), 0.5, 3)[:2]]
    side = 12
    x, z = np.meshgrid(np.arange(side + 1.0), np.arange(side + 1.0), indexing="ij")
    grid = np.stack([x.ravel(), rng.uniform(-1.0, 1.0, x.shape).ravel(), z.ravel()], axis=1)
    a = (np.arange(side)[:, None] * (side + 1) + np.arange(side)).ravel()
    meshes.append((grid, np.concatenate([np.stack([a, a + 1, a + side + 2], 1),
                                         np.stack([a, a + side + 2, a + side + 1], 1)])))
    shaped = len(meshes)
    for _ in range(8):
        n = int(rng.integers(3, 60))
        points = np.round(rng.normal(size=(n, 3)), 1)  # some corners shared, some repeated
        meshes.append((points, rng.integers(0, n, (int(rng.integers(1, 120)), 3))))
    meshes.append((meshes[0][0].copy(), meshes[0][1][::-1].copy()))  # over the first box
    order = rng.permutation(len(meshes))
    meshes = [meshes[i] for i in order]
    soup = (order >= shaped) & (order < shaped + 8)
    together = planar.project_many(meshes, split)
    alone = [planar.project(p, t, split) for p, t in meshes]
    assert sum(c is None for c in alone) >= 2 and sum(c is not None for c in alone) >= 10
    for (p, t), one, joined, random in zip(meshes, alone, together, soup):
        assert (one is None) == (joined is None)
        if one is None:
            continue
        for name in ("vertices", "triangles", "uv", "chart", "sides"):
            mine, theirs = getattr(joined, name), getattr(one, name)
            assert mine.dtype == theirs.dtype and mine.shape == theirs.shape
            np.testing.assert_array_equal(mine, theirs)
        if not random:
            _check_charts(joined, p, t)


def test_an_overlapping_mesh_goes_to_xatlas_only_while_it_fits_one_xatlas_piece(monkeypatch):
    """``charts.chart_many``: a ramp of 320 triangles whose one chart overlaps itself goes to xatlas
    (fast at that size, fewer seams); one of 16,002 triangles (more than an xatlas piece,
    whose time per triangle grows with the mesh) is split by projection instead, its charts
    those of ``planar.project`` and apart."""
    asked = []
    monkeypatch.setattr(charting, "_xatlas_charts", lambda p, t: asked.append(len(t)))
    small = _ramp(2, 160)
    assert planar.project(*small, split=False) is None
    charting.chart_many([small])
    assert asked == [320]
    big = _ramp(2, charting._PIECE_TRIANGLES // 2 + 1)
    charts = charting.chart_many([big])[0]
    assert asked == [320] and charts is not None
    np.testing.assert_array_equal(charts.uv, planar.project(*big).uv)
    _check_charts(charts, *big)


def test_a_wavy_sheet_of_many_triangles_a_chart_is_projected():
    """A sheet rippled in two directions (charts of about 15 triangles, most of them cut from
    their neighbours): projected, not left to xatlas, which took 18.8 s for its 114,242
    triangles at 240². ``_crumpled`` once marked a chart cut only when its last edge was (a
    buffered ``|=`` on repeated indices), so such sheets counted as crumpled."""
    n = 80
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    heights = 0.05 * np.sin(7 * u * 2 * np.pi) * np.cos(5 * v * 2 * np.pi)
    positions = np.stack([u, heights, v], axis=-1).reshape(-1, 3)
    index = np.arange(n * n).reshape(n, n)
    a, b, c, d = (index[:-1, :-1].ravel(), index[:-1, 1:].ravel(), index[1:, 1:].ravel(),
                  index[1:, :-1].ravel())
    triangles = np.concatenate([np.stack([a, c, b], 1), np.stack([a, d, c], 1)])
    charts = planar.project(positions, triangles)
    assert charts is not None
    _check_charts(charts, positions, triangles)
    assert len(triangles) / len(charts.sides) >= planar.LEAST_TRIANGLES


@pytest.mark.parametrize("seed", range(2))
def test_a_crumpled_mesh_is_charted_by_xatlas_in_compact_pieces(seed, monkeypatch):
    """A rock of 5,120 triangles, charted by xatlas in pieces of at most 700 (issue 46: its
    time per triangle grows with a mesh's size, 68 s for a rock of 327,680 triangles whole):
    every triangle in one piece, the pieces halves of halves (700 ≥ size > 350) and compact
    (each spans at most 0.75 of the rock's widest extent); the charts keep every triangle
    once in order, none turned over in its chart (xatlas mirrors some) or overlapping another
    of it (by more than xatlas's own), none spanning two
    pieces, the surface's area within xatlas's stretch; charted again, the same arrays."""
    positions, triangles = rock(1.0, 4, seed)[:2]
    assert planar.project(positions, triangles) is None
    monkeypatch.setattr(charting, "_PIECE_TRIANGLES", 700)
    centroids = positions[triangles].mean(axis=1)
    pieces = charting._pieces(centroids, 700)
    piece_of = np.full(len(triangles), -1)
    for k, part in enumerate(pieces):
        assert (piece_of[part] == -1).all() and 350 < len(part) <= 700
        piece_of[part] = k
        assert np.ptp(centroids[part], axis=0).max() <= 0.75 * np.ptp(centroids, axis=0).max()
    assert (piece_of >= 0).all() and len(pieces) == 8
    charts = charting.chart_many([(positions, triangles)])[0]
    np.testing.assert_array_equal(charts.vertices[charts.triangles], triangles)
    chart_of = charts.chart[charts.triangles]
    assert (chart_of == chart_of[:, :1]).all(), "a triangle's corners in two charts"
    pairs = np.unique(np.stack([chart_of[:, 0], piece_of], axis=1), axis=0)
    assert len(pairs) == len(charts.sides) == len(np.unique(chart_of)), "a chart in two pieces"
    assert (charts.uv >= -1e-9).all() and (charts.uv <= charts.sides[charts.chart] + 1e-9).all()
    corner = charts.uv[charts.triangles]
    e, f = corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0]
    uv_area = 0.5 * (e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0])
    corners = positions[triangles]
    surface = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                            corners[:, 2] - corners[:, 0]), axis=1)
    sign = np.where(np.bincount(chart_of[:, 0], uv_area) < 0, -1.0, 1.0)  # a chart mirrored
    uv_area = uv_area * sign[chart_of[:, 0]]
    assert (uv_area > -1e-12).all(), "a triangle turned over in its chart"
    assert 0.9 < uv_area.sum() / surface.sum() < 1.2
    for c in range(len(charts.sides)):  # about 1 chart in 400 of xatlas's overlaps itself,
        # by up to 0.003 (whole) or 0.03 (in pieces) of its size (eight rocks)
        _assert_apart(corner[(chart_of[:, 0] == c) & (uv_area > 0)] * [sign[c], 1.0], 0.05)
    again = charting.chart_many([(positions, triangles)])[0]
    for name in ("vertices", "triangles", "uv", "chart", "sides"):
        np.testing.assert_array_equal(getattr(again, name), getattr(charts, name))


@pytest.mark.parametrize("seed", range(3))
def test_packing_keeps_every_rectangle_and_its_padding_apart_on_its_page(seed):
    """Random rectangles (many small, some large): every one inside its page, no two sharing
    a texel with their padding round them (``2·padding`` apart); one page is cut to its
    rectangles, several are whole pages; the same input gives the same bits."""
    rng = np.random.default_rng(seed)
    cells = np.concatenate([rng.integers(1, 12, (int(rng.integers(1, 600)), 2)),
                            rng.integers(20, 120, (int(rng.integers(0, 8)), 2))])
    padding, page = int(rng.integers(0, 4)), int(rng.choice([128, 256]))
    packed = packing.pack(cells, padding, page)
    p = padding  # the drawing has the padding beyond the page's sides too
    drawn = np.zeros((packed.pages, packed.height + 2 * p, packed.width + 2 * p), np.int64)
    for cell, at, turned, on in zip(cells, packed.corner, packed.turned, packed.page):
        w, h = cell[::-1] if turned else cell
        x, y = at
        assert x >= 0 and y >= 0 and x + w <= packed.width and y + h <= packed.height
        drawn[on, y:y + h + 2 * p, x:x + w + 2 * p] += 1
    assert drawn.max() == 1
    assert packed.pages >= 1 and (packed.pages == 1 or packed.width == packed.height == page)
    assert max(packed.width, packed.height) <= page
    again = packing.pack(cells.copy(), padding, page)
    for name in ("page", "corner", "turned"):
        np.testing.assert_array_equal(getattr(again, name), getattr(packed, name))


def test_rectangles_that_fill_a_square_pack_into_it():
    """Sixteen 30 × 30 rectangles with a padding of 1 fill a 126² page exactly (2 texels
    apart, none at the page's sides): one page, every texel but the gaps used."""
    packed = packing.pack(np.full((16, 2), 30), 1, 126)
    assert packed.pages == 1 and (packed.width, packed.height) == (126, 126)


def _charts_by_part(atlas, world, scene) -> list[tuple[int, np.ndarray, bool]]:
    """Every chart of the atlas: (page, its triangles' UV corners in texels (t, 3, 2), whether
    it is a flat part), a flat part being a loose part of the crown or the grass."""
    out = []
    for inst in atlas.instances:
        uv = inst.uv * [atlas.width, atlas.height]
        corners = uv[inst.triangles]
        name = scene.document.nodes[scene.instances[inst.instance].node].name
        flat = name in ("crown", "grass")
        # Charts: the pieces of triangles joined by shared UV points (touching leaves, their
        # corners welded, are charted together).
        page = np.zeros(len(inst.uv))
        page[inst.triangles.reshape(-1)] = np.repeat(inst.pages, 3)
        _, point = np.unique(np.c_[inst.uv, page], axis=0, return_inverse=True)
        label, before = point.reshape(-1).copy(), None
        while before is None or (label != before).any():
            before, least = label.copy(), label[inst.triangles].min(axis=1)
            np.minimum.at(label, inst.triangles.ravel(), np.repeat(least, 3))
        chart = label[inst.triangles[:, 0]]
        for c in np.unique(chart):
            faces = np.flatnonzero(chart == c)
            out.append((int(inst.pages[faces[0]]), corners[faces], flat))
    return out


@pytest.mark.parametrize("leaf_count,grass_count,page", [(300, 120, 256), (1500, 0, 512)])
def test_the_atlas_keeps_flat_parts_true_to_size_on_their_own_texels(
        tmp_path, leaf_count, grass_count, page):
    """A tree (crown and grass as flat parts, trunk and ground beside them): every crown and grass
    triangle is as long in texels as in metres × density; a flat part touches just the texels
    of its rectangle; no texel of a flat part is within 2·padding of another chart's."""
    scene = loaded(tree(leaf_count=leaf_count, grass_count=grass_count), tmp_path)
    world = build_world(scene)
    settings = resolve(Settings(page_size=page), world.areas().sum(), 1.0)
    atlas = unwrap(scene, world, settings, fit_one_page=True)
    for inst in atlas.instances:
        name = scene.document.nodes[scene.instances[inst.instance].node].name
        if name not in ("crown", "grass"):
            continue
        uv = inst.uv * [atlas.width, atlas.height]
        a, b, c = world.corners(world.instance_triangles(inst.instance))
        for (p, q), (j, k) in zip(((a, b), (b, c), (c, a)), ((0, 1), (1, 2), (2, 0))):
            np.testing.assert_allclose(
                np.linalg.norm(uv[inst.triangles[:, j]] - uv[inst.triangles[:, k]], axis=1),
                np.linalg.norm(p - q, axis=1) * atlas.texel_density, rtol=1e-3, atol=2e-3)
    charts = _charts_by_part(atlas, world, scene)
    gap = 2 * atlas.padding
    for page_index in range(atlas.page_count):
        on_page = [(corners, flat) for p, corners, flat in charts if p == page_index]
        masks = [_touched(corners, atlas.width, atlas.height) for corners, _flat in on_page]
        for (corners, flat), mask in zip(on_page, masks):
            if flat and len(corners) == 2:  # a quad: exactly the texels of its rectangle
                low, high = corners.reshape(-1, 2).min(0), corners.reshape(-1, 2).max(0)
                assert mask.sum() == np.prod(np.floor(high - low + 2 * _MARGIN) + 1)
        owner = np.full((atlas.height, atlas.width), -1)
        is_flat = np.array([flat for _corners, flat in on_page] + [False])
        for n, mask in enumerate(masks):  # no texel of a flat part shared with another chart
            assert not (is_flat[n] and (owner[mask] >= 0).any())
            assert not is_flat[owner[mask]].any()
            owner[mask] = n
        near = _dilated(owner, gap)
        for n, ((_corners, flat), mask) in enumerate(zip(on_page, masks)):
            if flat:
                assert set(np.unique(near[mask])) <= {n, -1}, "another chart within the padding"


def _dilated(owner: np.ndarray, reach: int) -> np.ndarray:
    """For each texel, the chart of ``owner`` within ``reach`` texels (Chebyshev) other than
    the texel's own when there is one (-2 where two others are), else its own or -1."""
    height, width = owner.shape
    near = owner.copy()
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            shifted = np.full_like(owner, -1)
            ys = slice(max(0, dy), height + min(0, dy))
            yd = slice(max(0, -dy), height + min(0, -dy))
            xs = slice(max(0, dx), width + min(0, dx))
            xd = slice(max(0, -dx), width + min(0, -dx))
            shifted[yd, xd] = owner[ys, xs]
            other = (shifted >= 0) & (shifted != owner)
            near = np.where(other & (near == owner), shifted, near)
            near = np.where(other & (near != owner) & (near != shifted), -2, near)
    return near


def test_a_rigid_move_of_the_tree_leaves_its_flat_charts_bit_for_bit(tmp_path):
    """The flat parts are charted in the instance's rigid-free frame: turning and moving the
    crown's node gives the same UVs and pages."""
    builder = tree(leaf_count=200, grass_count=0)
    scene = loaded(builder, tmp_path)
    world = build_world(scene)
    settings = resolve(Settings(page_size=512, texel_density=20.0), world.areas().sum(), 1.0)
    before = unwrap(scene, world, settings)
    node = builder._nodes[builder.info["nodes"]["crown"]]
    node.translation = [1.5, 0.25, -2.0]
    node.rotation = [0.0, np.sin(0.35), 0.0, np.cos(0.35)]
    (tmp_path / "moved").mkdir()
    moved = loaded(builder, tmp_path / "moved")
    after = unwrap(moved, build_world(moved), settings)
    for a, b in zip(before.instances, after.instances):
        np.testing.assert_array_equal(a.uv, b.uv)
        np.testing.assert_array_equal(a.pages, b.pages)
