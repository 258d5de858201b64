"""The obscurance estimator against closed forms (docs/design.md §2, equations 2–4)."""

import numpy as np
import pytest

from assets.make_scenes import open_plane, parallel_planes, red_wall_floor
from baker.image.compose import effective_r_ave
from baker.light.hemisphere import Terms
from tests.bakehelp import computed

_NO_DIRECTIONS = np.zeros((0, 3))  # no directional pages: the rays' directions unused


def _w(done) -> np.ndarray:
    return done.terms.obscurance(effective_r_ave(done.ambient, done.settings.rho))


def test_open_plane_sees_r_ave_exactly(tmp_path):
    done = computed(open_plane(albedo=0.6), tmp_path, texel_density=8.0, rays=16, d_max=1.0,
                    escape="scene")
    assert np.allclose(done.ambient.r_ave, 0.6)
    assert np.array_equal(done.terms.escaped, np.ones(len(done.texels)))
    assert np.allclose(_w(done), 0.6, atol=1e-12)


def _closed_form_w(rho: str, height: float, d_max: float, ceiling: float, r_ave: float) -> float:
    """W at a point facing an infinite parallel plane (albedo ``ceiling``) at ``height``.

    With cosine-weighted directions t = cos²θ is uniform on [0, 1]. A ray hits within d_max when
    cosθ > a = height / d_max, at distance height / cosθ, so ρ = sqrt(a) · t^(-1/4) for sqrt:
    W = ceiling · sqrt(a) · (4/3)(1 − a^(3/2)) + a² · R_ave. Classic AO (step) is W = a².
    """
    a = height / d_max
    if rho == "step":
        return a * a
    return ceiling * np.sqrt(a) * (4.0 / 3.0) * (1.0 - a ** 1.5) + a * a * r_ave


@pytest.mark.parametrize("rho", ["sqrt", "step"])
def test_parallel_plane_matches_closed_form(tmp_path, rho):
    height, d_max, ceiling = 0.5, 2.0, 0.5
    builder = parallel_planes(height=height, half_extent=50.0, probe_size=0.2,
                              ceiling_albedo=(ceiling,) * 3)
    done = computed(builder, tmp_path, only_nodes={builder.info["nodes"]["probe"]},
                    texel_density=20.0, rays=4096, d_max=d_max, rho=rho, chunk_texels=64)
    probe = np.abs(done.texels.position[:, 0]) < 0.08  # well inside the probe quad
    probe &= np.abs(done.texels.position[:, 2]) < 0.08
    assert probe.sum() >= 4
    r_ave = effective_r_ave(done.ambient, rho)
    w = _w(done)[probe].mean(axis=1)
    stderr = done.terms.standard_error(r_ave)[probe]
    expected = _closed_form_w(rho, height, d_max, ceiling, float(r_ave[0]))
    assert np.all(np.abs(w - expected) < 3 * stderr + 1e-9), (w, expected, stderr)


def test_colour_bleeding_red_shift_falls_off_with_distance(tmp_path):
    done = computed(red_wall_floor(), tmp_path, texel_density=8.0, rays=256, d_max=2.0,
                    escape="scene")
    distance = done.texels.position[:, 2] + 2.0  # from the wall at z = -2
    floor = (done.texels.geometric_normal()[:, 1] > 0.9) & (distance > 0.05)
    w = _w(done)[floor]
    redness = w[:, 0] / w[:, 1]  # red over green; a white floor alone gives 1
    distance = distance[floor]
    near, middle, far = distance < 0.5, (distance > 1.0) & (distance < 1.5), distance > 3.0
    assert redness[near].mean() > redness[middle].mean() > redness[far].mean() * 1.05
    # Texels farther than d_max from the wall see only R_ave, whose own tint is the wall's share.
    r_ave = done.ambient.r_ave
    assert np.allclose(redness[far], r_ave[0] / r_ave[1])


def test_standard_error_of_a_known_variance():
    """Half the rays hit a white surface at ρ = 1 and half escape with R_ave = 0: var = 1/4."""
    terms = Terms(w_hit=np.full((1, 3), 0.5), escaped=np.array([0.5]),
                  hit_sq=np.array([0.5]), counts=np.array([100]),
                  half_split=np.zeros((1, 2)))
    stderr = terms.standard_error(np.zeros(3))
    assert np.isclose(stderr[0], np.sqrt(0.25 * 100 / 99 / 100))


def test_classic_ao_by_occlusion_queries_is_the_bits_of_nearest_hits(tmp_path, monkeypatch):
    """``--rho step`` casts its obscurance rays as occlusion queries (``blocking_only``); the
    terms are the very bits that nearest hits give (a hit's value is 0 whatever its distance
    and albedo), with a target error's rounds too."""
    import baker.light.hemisphere as hemisphere

    settings = dict(texel_density=6.0, rays=8, rho="step", d_max=1.0)
    for extra in ({}, {"target_error": 0.02, "max_rays": 32}):
        occluded = computed(red_wall_floor(), tmp_path, **settings, **extra).terms
        with monkeypatch.context() as patch:
            patch.setattr(hemisphere, "blocking_only", lambda surfaces, settings: False)
            nearest = computed(red_wall_floor(), tmp_path, **settings, **extra).terms
        assert 0 < occluded.escaped.mean() < 1
        for name in ("w_hit", "escaped", "hit_sq", "half_split", "counts"):
            assert np.array_equal(getattr(occluded, name), getattr(nearest, name)), name


def _random_rays(seed: int, texels: int, rays: int, triangles: int = 50):
    """Embree-like hits of texels × rays rays, texel-major: primID (−1 for misses), tfar."""
    rng = np.random.default_rng(seed)
    primitive = np.where(rng.random(texels * rays) < 0.3, -1,
                         rng.integers(0, triangles, texels * rays)).astype(np.int32)
    distance = (rng.random(texels * rays) * 2.0).astype(np.float32)
    return primitive, distance, rng.random((triangles, 3))


def test_texel_sums_are_exact_in_any_order_and_recovered_from_the_means():
    """Every ray's values are rounded to a grid fine enough to be exact when summed, so a
    texel's sums are the same bits whatever the order of its rays (what a rebake that swaps one
    ray's old value for its new one relies on), and the stored means give them back exactly."""
    from baker.light.hemisphere import (COLUMNS, NO_DIRECTIONS, _TEXEL_MAJOR,
                                        accumulate_kernel, terms_of_sums)
    from baker.rebake.exact_sums import _sums_of
    from baker.geometry.surface import LUMINANCE

    texels, rays = 300, 64
    primitive, distance, table = _random_rays(4, texels, rays)
    kind = np.zeros(len(table), np.uint8)
    shade = (np.float32(2.0), 0, table, kind, np.zeros((0, 4)), LUMINANCE)
    in_order = np.zeros((texels, COLUMNS))
    accumulate_kernel(rays, primitive, distance, *shade, in_order, *_TEXEL_MAJOR, 1.0,
                      NO_DIRECTIONS)
    shuffled = np.random.default_rng(5).permutation(texels * rays)
    any_order = np.zeros((texels, COLUMNS))
    accumulate_kernel(rays, primitive[shuffled], distance[shuffled], *shade, any_order,
                      shuffled // rays, shuffled % rays, 1.0, NO_DIRECTIONS)
    assert np.array_equal(in_order, any_order)
    assert (in_order[:, 5] > 0).any() and (in_order[:, 6] > 0).any()  # the first halves
    counts = np.full(texels, rays, np.int64)
    assert np.array_equal(_sums_of(terms_of_sums(in_order, counts)), in_order)


def test_a_rays_change_replaces_its_value_in_the_sums_exactly():
    """The kernel's signed sums of changed rays (what ``ray_changes`` adds up) and
    ``changed_terms``: the terms of texels after some of their rays' hits changed are the bits
    of the terms of the new hits, summed afresh."""
    from baker.light.hemisphere import (COLUMNS, NO_DIRECTIONS, _TEXEL_MAJOR,
                                        accumulate_kernel, terms_of_sums)
    from baker.rebake.exact_sums import changed_terms
    from baker.geometry.surface import LUMINANCE

    texels, rays = 200, 16
    primitive, distance, table = _random_rays(6, texels, rays)
    rng = np.random.default_rng(7)
    changed = np.flatnonzero(rng.random(texels * rays) < 0.05)
    new_primitive, new_distance = primitive.copy(), distance.copy()
    new_primitive[changed] = rng.integers(-1, len(table), len(changed))
    new_distance[changed] = rng.random(len(changed)).astype(np.float32)
    kind = np.zeros(len(table), np.uint8)
    shade = (np.float32(2.0), 0, table, kind, np.zeros((0, 4)), LUMINANCE)
    before, after = np.zeros((texels, COLUMNS)), np.zeros((texels, COLUMNS))
    accumulate_kernel(rays, primitive, distance, *shade, before, *_TEXEL_MAJOR, 1.0,
                      NO_DIRECTIONS)
    accumulate_kernel(rays, new_primitive, new_distance, *shade, after, *_TEXEL_MAJOR, 1.0,
                      NO_DIRECTIONS)
    changes = np.zeros((texels, COLUMNS))
    for sign, hits, dist in ((-1.0, primitive, distance), (1.0, new_primitive, new_distance)):
        accumulate_kernel(rays, hits[changed], dist[changed], *shade, changes,
                          changed // rays, changed % rays, sign, NO_DIRECTIONS)
    counts = np.full(texels, rays, np.int64)
    terms, exact = changed_terms(terms_of_sums(before, counts), changes)
    assert exact.all()
    fresh = terms_of_sums(after, counts)
    for name in ("w_hit", "escaped", "hit_sq", "half_split"):
        assert np.array_equal(getattr(terms, name), getattr(fresh, name)), name
    assert not np.array_equal(fresh.w_hit, terms_of_sums(before, counts).w_hit)


def test_step_ao_under_a_low_ceiling_never_claims_an_exact_texel(tmp_path):
    """Classic AO (step) under a ceiling at 0.3·d_max: a ray escapes with p = 0.3² = 0.09, so
    at 16 rays about 0.91¹⁶ = 22 % of texels see no escape and have sample variance 0, while
    their true W is 0.09 (their error 100 %). Their standard error must not be 0, and the
    texels' ±2σ band must hold W's closed form about as often as a normal band does."""
    height, d_max = 0.3, 1.0
    builder = parallel_planes(height=height, half_extent=50.0, probe_size=0.4)
    done = computed(builder, tmp_path, only_nodes={builder.info["nodes"]["probe"]},
                    texel_density=40.0, rays=16, d_max=d_max, rho="step")
    r_ave = effective_r_ave(done.ambient, "step")
    w = _w(done).mean(axis=1)
    sigma = done.terms.standard_error(r_ave)
    expected = _closed_form_w("step", height, d_max, 0.5, float(r_ave[0]))
    unseen = done.terms.escaped == 0
    assert 0.1 < unseen.mean() < 0.4 and np.all(sigma[unseen] > 0)
    covered = np.mean(np.abs(w - expected) <= 2 * sigma)
    assert covered > 0.9, covered
