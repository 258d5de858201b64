"""Rasterisation: conservative coverage, sample points on their triangles, stable keys."""

import numpy as np

from assets.make_scenes import open_plane, slivers_and_tiny, three_instances
from baker.geometry import build_world
from baker.rasterise import rasterise
from baker.settings import Settings, resolve
from baker.unwrap import unwrap
from tests.bakehelp import loaded


def _raster(builder, tmp_path, density):
    scene = loaded(builder, tmp_path)
    world = build_world(scene)
    settings = resolve(Settings(texel_density=density), world.areas().sum(), 1.0)
    atlas = unwrap(scene, world, settings)
    return scene, world, atlas, rasterise(atlas, world)


def test_every_triangle_with_area_gets_texels_slivers_and_tiny_included(tmp_path):
    scene, world, atlas, texels = _raster(slivers_and_tiny(), tmp_path, 32.0)
    has_area = world.areas() > 0
    baked = np.isin(world.tri_instance, [u.instance for u in atlas.instances])
    assert has_area.sum() > 10
    without = np.flatnonzero(has_area & baked & (texels.triangle_texels == 0))
    assert without.size == 0, f"triangles without texels: {without}"


def test_sample_points_lie_on_their_triangles(tmp_path):
    scene, world, atlas, texels = _raster(three_instances(), tmp_path, 16.0)
    a, b, c = world.corners(texels.triangle)
    rebuilt = (texels.barycentric[:, :1] * a + texels.barycentric[:, 1:2] * b
               + texels.barycentric[:, 2:] * c)
    assert np.allclose(rebuilt, texels.position)
    assert texels.barycentric.min() >= 0
    # On a plane through the triangle: distance to the plane is ~0.
    n = world.geometric_normals(texels.triangle)
    assert np.abs(((texels.position - a) * n).sum(axis=1)).max() < 1e-9


def test_keys_are_unique_sorted_and_match_page_positions(tmp_path):
    scene, world, atlas, texels = _raster(three_instances(), tmp_path, 16.0)
    assert np.all(np.diff(texels.key.astype(np.int64)) > 0)
    expected = (texels.page * atlas.height + texels.y) * atlas.width + texels.x
    assert np.array_equal(texels.key.astype(np.int64), expected)


def test_texel_size_follows_texel_density(tmp_path):
    scene, world, atlas, texels = _raster(open_plane(size=2.0), tmp_path, 10.0)
    # One texel side is 1/density world units (xatlas may shrink charts a little to pack).
    assert np.allclose(np.median(texels.size), 0.1, rtol=0.1)
    # And the plane's 4 m² holds about 400 texels, plus its conservative border.
    assert 350 < len(texels) < 600
