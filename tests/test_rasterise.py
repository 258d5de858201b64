"""Rasterisation: conservative coverage, sample points on their triangles, stable keys."""

import numpy as np

from assets.make_scenes import open_plane, slivers_and_tiny, three_instances
from baker.geometry.world import build_world, triangle_cross
from baker.atlas.rasterise import INSET, _baked_triangles, _texel_barycentrics
from baker.settings import Settings, resolve
from baker.atlas.unwrap import unwrap
from tests.bakehelp import loaded, rasterised


def _raster(builder, tmp_path, density):
    scene = loaded(builder, tmp_path)
    world = build_world(scene)
    settings = resolve(Settings(texel_density=density), world.areas().sum(), 1.0)
    atlas = unwrap(scene, world, settings)
    return scene, world, atlas, rasterised(atlas, world)


def test_every_triangle_with_area_gets_texels_slivers_and_tiny_included(tmp_path):
    scene, world, atlas, texels = _raster(slivers_and_tiny(), tmp_path, 32.0)
    has_area = world.areas() > 0
    baked = np.isin(world.tri_instance, [u.instance for u in atlas.instances])
    assert has_area.sum() > 10
    without = np.flatnonzero(has_area & baked & (texels.triangle_texels == 0))
    assert without.size == 0, f"triangles without texels: {without}"


def _barycentric(world, texels) -> np.ndarray:
    """(N, 3) barycentric coordinates of the texels' sample points in their owning triangles,
    solved from the world points (the projection onto the triangle's plane)."""
    a, b, c = world.corners(texels.triangle)
    e1, e2, p = b - a, c - a, texels.position - a
    d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    p1, p2 = (p * e1).sum(1), (p * e2).sum(1)
    det = d11 * d22 - d12 * d12
    s, t = (d22 * p1 - d12 * p2) / det, (d11 * p2 - d12 * p1) / det
    return np.stack([1 - s - t, s, t], axis=1)


def test_sample_points_lie_on_their_triangles(tmp_path):
    scene, world, atlas, texels = _raster(three_instances(), tmp_path, 16.0)
    a, b, c = world.corners(texels.triangle)
    bary = _barycentric(world, texels)
    rebuilt = bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c
    assert np.allclose(rebuilt, texels.position)
    assert bary.min() >= -1e-9
    # On a plane through the triangle: distance to the plane is ~0.
    n = world.geometric_normals(texels.triangle)
    assert np.abs(((texels.position - a) * n).sum(axis=1)).max() < 1e-9


def test_sample_points_keep_inside_their_triangles_edges(tmp_path):
    """Every sample point is at least ``INSET`` texels inside each edge of its UV triangle (a
    centre clamped onto an edge would lie in the surfaces meeting there, where ties in Embree
    depend on its BVH), and the two edges at a corner get different insets."""
    scene, world, atlas, texels = _raster(three_instances(), tmp_path, 16.0)
    corners, _, tris = _baked_triangles(atlas, world)  # UV corners, texel units
    slot = np.full(len(world.triangles), -1, np.int64)
    slot[tris] = np.arange(len(tris))
    uv = corners[slot[texels.triangle]]
    bary = _barycentric(world, texels)  # the same in UV: the map is affine
    point = np.einsum("kc,kcj->kj", bary, uv)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    area2 = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    distance = bary * area2[:, None] / np.linalg.norm(
        uv[:, [2, 0, 1]] - uv[:, [1, 2, 0]], axis=2)  # to the edge facing each corner
    clamped = distance.min(axis=1) < 0.5  # near an edge
    assert clamped.sum() > 100
    assert distance.min() >= INSET * (1 - 1e-6)
    _, y, x = texels.pixels()
    centre = np.stack([x + 0.5, y + 0.5], axis=1)
    assert np.abs(point - centre)[~clamped].max() < 1e-6  # the others keep their centres
    at_corner = np.sort(distance[clamped], axis=1)[:, :2]  # a corner's two nearest edges
    corner = at_corner[:, 1] < 2 * INSET
    assert corner.any() and (at_corner[corner, 1] - at_corner[corner, 0] > 1e-4).all()


def test_collinear_uv_triangles_give_weights_not_an_error():
    """UV triangles whose corners lie on one line at scales from 10⁻³ to 10⁹ texels (a
    mutated file's UVs): every texel centre gets finite weights ≥ 0 summing to 1. The Gram
    determinant that decides "degenerate" can round above 0 where the corners' cross product
    rounds to 0, and the inset then divided by that 0 (a ZeroDivisionError out of a bake)."""
    rng = np.random.default_rng(5)
    count = 20_000
    a = rng.uniform(0, 64, (count, 2))
    d = rng.normal(size=(count, 2)) * 10.0 ** rng.uniform(-3, 9, (count, 1))
    uv = np.stack([a, a + d, a + rng.integers(2, 5, (count, 1)) * d], axis=1)
    key = rng.integers(0, 64 * 64, count)
    bary = _texel_barycentrics(key, np.arange(count), uv, 64, 64)
    assert np.isfinite(bary).all() and (bary >= 0).all()
    np.testing.assert_allclose(bary.sum(axis=1), 1.0, rtol=1e-12)


def test_keys_are_unique_sorted_and_match_page_positions(tmp_path):
    scene, world, atlas, texels = _raster(three_instances(), tmp_path, 16.0)
    assert np.all(np.diff(texels.key.astype(np.int64)) > 0)
    page, y, x = texels.pixels()
    assert (page < atlas.page_count).all() and (y < atlas.height).all() and (x < atlas.width).all()
    expected = (page * atlas.height + y) * atlas.width + x
    assert np.array_equal(texels.key.astype(np.int64), expected)


def test_texel_size_follows_texel_density(tmp_path):
    scene, world, atlas, texels = _raster(open_plane(size=2.0), tmp_path, 10.0)
    # One texel side is 1/density world units (xatlas may shrink charts a little to pack).
    assert np.allclose(np.median(texels.size()), 0.1, rtol=0.1)
    # And the plane's 4 m² holds about 400 texels, plus its conservative border.
    assert 350 < len(texels) < 600


def _overlap_area(triangle: np.ndarray, x: int, y: int) -> float:
    """Area of the texel square [x, x+1] × [y, y+1] inside the UV triangle (3, 2): the square
    clipped by each edge's half-plane in turn (Sutherland–Hodgman), then the shoelace."""
    polygon = [np.array(p, float) for p in ((x, y), (x + 1, y), (x + 1, y + 1), (x, y + 1))]
    a, b, c = triangle
    sign = np.sign((b - a)[0] * (c - a)[1] - (b - a)[1] * (c - a)[0])
    for p, q in ((a, b), (b, c), (c, a)):
        def inside(point, p=p, q=q):
            return sign * ((q - p)[0] * (point - p)[1] - (q - p)[1] * (point - p)[0])
        clipped = []
        for i, current in enumerate(polygon):
            previous = polygon[i - 1]
            now, before = inside(current), inside(previous)
            if (now >= 0) != (before >= 0):
                clipped.append(previous + (current - previous) * before / (before - now))
            if now >= 0:
                clipped.append(current)
        polygon = clipped
        if not polygon:
            return 0.0
    xs, ys = np.array([p[0] for p in polygon]), np.array([p[1] for p in polygon])
    return 0.5 * abs(np.dot(xs, np.roll(ys, -1)) - np.dot(ys, np.roll(xs, -1)))


def test_coverage_is_every_texel_a_triangle_overlaps_owned_by_the_deepest():
    """Random triangles (some past the page's edges, of every size down to a sliver) on a
    12 × 9 page: a texel is covered exactly when its square overlaps some triangle with an area
    (square clipped by the triangle, computed independently of the separating axes), each
    triangle counts the texels it overlaps, and the owner is the triangle whose edges are
    farthest from the texel centre on the inside (the centre's distance inside the nearest)."""
    from baker.atlas.rasterise import _cover_kernel, _edge_terms

    rng = np.random.default_rng(11)
    width, height = 12, 9
    centres = rng.uniform([-2, -2], [width + 2, height + 2], size=(40, 1, 2))
    corners = centres + rng.normal(size=(40, 3, 2)) * rng.choice([0.05, 0.7, 3.0], (40, 1, 1))
    corners[0] = [[1.1, 1.2], [6.3, 1.25], [10.7, 1.3]]  # a sliver along a row
    normals, offsets = _edge_terms(corners)
    best_depth, best_owner = np.full(width * height, -np.inf), np.full(width * height, -1, np.int32)
    counts = np.zeros(len(corners), np.int64)
    _cover_kernel(corners, normals, offsets, np.zeros(len(corners), np.int64), width, height,
                  best_depth, best_owner, counts)
    area = np.array([[[_overlap_area(t, x, y) for x in range(width)] for y in range(height)]
                     for t in corners])  # (triangles, y, x)
    overlapping = area > 1e-12
    np.testing.assert_array_equal(counts, overlapping.sum(axis=(1, 2)))
    np.testing.assert_array_equal(best_owner >= 0, overlapping.any(axis=0).reshape(-1))
    y, x = np.divmod(np.arange(width * height), width)
    centre = np.stack([x + 0.5, y + 0.5], axis=1)
    depth = (np.einsum("tej,pj->tpe", normals, centre) - offsets[:, None]).min(axis=2)
    depth = np.where(overlapping.reshape(len(corners), -1), depth, -np.inf)
    covered = best_owner >= 0
    np.testing.assert_array_equal(best_owner[covered], np.argmax(depth, axis=0)[covered])
    assert covered.sum() > 30 and (counts == 0).sum() > 2  # covered texels and triangles off the page


def test_the_geometry_handed_on_is_read_only(tmp_path):
    """The world, each instance's unwrap, the coverage and the owners are read by every later
    stage and written by none (``baker/frozen.py``): numpy refuses a write into any of them."""
    import pytest

    from baker.atlas.rasterise import cover, owners

    scene = loaded(three_instances(), tmp_path)
    world = build_world(scene)
    settings = resolve(Settings(texel_density=8.0), world.areas().sum(), 1.0)
    atlas = unwrap(scene, world, settings)
    coverage = cover(atlas, world)
    arrays = [world.positions, world.triangles, world.texcoords[0] if world.texcoords else
              world.normals, atlas.instances[0].uv, coverage.key,
              owners(atlas, world, coverage).normal]
    for array in arrays:
        with pytest.raises(ValueError, match="read-only"):
            array[(0,) * array.ndim] = array[(0,) * array.ndim]


def test_triangle_cross_products_are_numpys_to_the_bit():
    """``world.triangle_cross`` (compiled, every area and normal of a bake starts from it) gives
    np.cross's bits, at scales from 1e-3 to 1e3, for repeated and collapsed corners too."""
    rng = np.random.default_rng(5)
    positions = rng.normal(size=(4000, 3)) * rng.uniform(1e-3, 1e3, (4000, 1))
    triangles = rng.integers(0, 4000, (30_000, 3))
    triangles[:100, 1] = triangles[:100, 0]  # two corners the same: no area
    a, b, c = (positions[triangles[:, k]] for k in range(3))
    got = triangle_cross(positions, triangles)
    assert np.array_equal(got, np.cross(b - a, c - a)) and not got[:100].any()
