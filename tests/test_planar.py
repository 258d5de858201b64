"""Many small flat loose parts are charted by projection and packed in blocks (``planar.py``).

Checked on generated crowns and grass (random sizes, turns, counts), in the atlas ``unwrap``
makes of them beside xatlas's charts: every part keeps its shape and size (texels per metre
as asked), touches only the texels its rectangle needs, and keeps 2·padding free texels from
every other chart; a rigid move of the node leaves the atlas bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from assets.foliage_scenes import leaves, tree
from baker.atlas import planar
from baker.atlas.rasterise import _cover_kernel, _edge_terms
from baker.atlas.unwrap import unwrap
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


@pytest.mark.parametrize("seed", range(4))
def test_flat_parts_keep_their_shape_and_get_the_smallest_edge_aligned_rectangle(seed):
    """Leaf quads of random sizes and turns: every edge keeps its length in the chart, and a
    quad's rectangle is its own two sides (the least-area one of its edges)."""
    rng = np.random.default_rng(seed)
    count = int(rng.integers(planar.MIN_PARTS, 400))
    positions, triangles, _normals, _uv = leaves(count, (0, 0, 0), (30, 20, 30), 1.0, seed)
    scale = rng.uniform(0.3, 6.0, (count, 1))  # sides from 0.3 to 6 texels
    centres = positions.reshape(count, 4, 3).mean(axis=1, keepdims=True)
    positions = (centres + (positions.reshape(count, 4, 3) - centres) * scale[:, None]).reshape(-1, 3)
    flats = planar.flat_parts(positions.astype(np.float32), triangles.astype(np.uint32), 2, 500)
    assert flats is not None and len(flats.faces) == len(triangles)
    p = positions.astype(np.float32).astype(np.float64)[flats.vertices]
    for k in range(3):
        a, b = flats.triangles[:, k], flats.triangles[:, (k + 1) % 3]
        np.testing.assert_allclose(np.linalg.norm(flats.uv[a] - flats.uv[b], axis=1),
                                   np.linalg.norm(p[a] - p[b], axis=1), atol=1e-4)
    for part in range(count):  # each quad (triangles part, part + count) spans side × side
        corner = flats.uv[flats.triangles[np.flatnonzero(flats.faces % count == part)].ravel()]
        np.testing.assert_allclose(np.sort(np.ptp(corner, axis=0)), [scale[part, 0]] * 2,
                                   atol=1e-4)


def test_too_few_or_bent_or_large_parts_are_left_to_xatlas():
    """Fewer than MIN_PARTS parts, or parts folded out of their plane, or longer than
    MAX_SIDE texels: no flat charts."""
    positions, triangles, _n, _uv = leaves(planar.MIN_PARTS - 1, (0, 0, 0), (9, 9, 9), 2.0)
    assert planar.flat_parts(positions, triangles, 2, 500) is None
    positions, triangles, _n, _uv = leaves(200, (0, 0, 0), (99, 99, 99), 2.0)
    bent = positions.copy()
    bent[2::4] += np.cross(bent[1::4] - bent[0::4], bent[3::4] - bent[0::4]) * 0.2  # folded
    assert planar.flat_parts(bent, triangles, 2, 500) is None
    large = positions * (planar.MAX_SIDE / 1.5)
    assert planar.flat_parts(large, triangles, 2, 500) is None


@pytest.mark.parametrize("seed", range(3))
def test_shelves_keep_every_rectangle_apart_inside_its_block(seed):
    """Random rectangles: inside their block, and no two of one block within ``gap`` texels."""
    rng = np.random.default_rng(seed)
    cells = rng.integers(1, 9, (500, 2))
    gap, side = int(rng.integers(0, 5)), 40
    block, at, sizes = planar.shelves(cells, gap, side)
    assert (at >= 0).all() and (at + cells <= sizes[block]).all() and (sizes <= side).all()
    for b in range(len(sizes)):
        inside = np.flatnonzero(block == b)
        low, high = at[inside], at[inside] + cells[inside] + gap
        apart = ((low[:, None] >= high[None]) | (low[None] >= high[:, None])).any(axis=2)
        np.fill_diagonal(apart, True)
        assert apart.all()


def _charts_by_part(atlas, world, scene) -> list[tuple[int, np.ndarray, bool]]:
    """Every chart of the atlas: (page, its triangles' UV corners in texels (t, 3, 2), whether
    it is a flat part), a flat part being a loose part of the crown or the grass."""
    out = []
    for inst in atlas.instances:
        uv = inst.uv * [atlas.width, atlas.height]
        corners = uv[inst.triangles]
        name = scene.document.nodes[scene.instances[inst.instance].node].name
        flat = name in ("crown", "grass")
        # Charts: the pieces of triangles joined by shared (split) vertices.
        label, before = np.arange(len(inst.uv)), None
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
    """A tree (crown and grass as flat parts, trunk and ground by xatlas): every crown and grass
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
            if flat:  # exactly the texels of its rectangle: ceil of its sides
                low, high = corners.reshape(-1, 2).min(0), corners.reshape(-1, 2).max(0)
                assert mask.sum() == np.prod(np.floor(high - low + 2 * planar._MARGIN) + 1)
        owner = np.full((atlas.height, atlas.width), -1)
        for n, mask in enumerate(masks):
            assert (owner[mask] == -1).all()  # no texel shared between charts
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
