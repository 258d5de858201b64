"""Adaptive sampling and integrating a subset of texels."""

import numpy as np

from assets.make_scenes import cornell_box
from baker.image.compose import effective_r_ave
from baker.light.integrate import integrate
from baker.geometry.surface import LUMINANCE
from baker.rays.trace import Tracer
from tests.bakehelp import computed

SETTINGS = dict(texel_density=6.0, rays=16, max_rays=256, d_max=0.6)


def _lightmap_stderr(done):
    scale = float(done.ambient.intensity @ LUMINANCE)
    return done.terms.standard_error(effective_r_ave(done.ambient, done.settings.rho)) * scale


def test_texels_get_rays_until_their_error_is_under_the_target(tmp_path):
    uniform = computed(cornell_box(), tmp_path, **SETTINGS)
    target = float(np.median(_lightmap_stderr(uniform)))
    done = computed(cornell_box(), tmp_path, target_error=target, **SETTINGS)
    counts = done.terms.counts
    stderr = _lightmap_stderr(done)
    assert set(np.unique(counts)) <= {16, 32, 64, 128, 256}
    assert counts.min() == 16 and counts.max() > 16  # some stop at once, some go on
    assert np.all((stderr <= target) | (counts == 256))
    # Texels that needed more rays were the noisy ones at 16 rays.
    first = _lightmap_stderr(uniform)
    assert first[counts > 16].min() > target >= first[counts == 16].max()


def test_adaptive_result_does_not_depend_on_chunks_or_threads(tmp_path):
    target = 0.01
    a = computed(cornell_box(), tmp_path, target_error=target, threads=1, chunk_texels=100000,
                 **SETTINGS)
    b = computed(cornell_box(), tmp_path, target_error=target, threads=2, chunk_texels=7,
                 **SETTINGS)
    assert np.array_equal(a.terms.counts, b.terms.counts)
    assert np.array_equal(a.terms.w_hit, b.terms.w_hit)
    assert np.array_equal(a.lightmaps.light, b.lightmaps.light)


def test_a_subset_of_rows_gets_the_same_terms_as_the_full_bake(tmp_path):
    for extra in ({}, {"target_error": 0.01}):
        done = computed(cornell_box(), tmp_path, **SETTINGS, **extra)
        rows = np.random.default_rng(1).choice(len(done.texels), 300, replace=False)
        part = integrate(done.scene, done.world, Tracer(done.world), done.texels, done.settings,
                         rows=rows, error_scale=(effective_r_ave(done.ambient, "sqrt"),
                                                 float(done.ambient.intensity @ LUMINANCE)))
        assert np.array_equal(part.w_hit, done.terms.w_hit[rows])
        assert np.array_equal(part.escaped, done.terms.escaped[rows])
        assert np.array_equal(part.counts, done.terms.counts[rows])


def test_a_texel_that_stops_after_one_round_has_the_uniform_bakes_terms(tmp_path):
    """The first round is a whole stratified grid (not the first rows of a grid laid out for
    max_rays), so texels that stop early are unbiased, for every technique."""
    for technique in ("sobol", "stratified", "random"):
        uniform = computed(cornell_box(), tmp_path, sampling=technique, **SETTINGS)
        done = computed(cornell_box(), tmp_path, sampling=technique, target_error=0.01,
                        **SETTINGS)
        stopped = done.terms.counts == 16
        assert 0 < stopped.sum() < len(stopped)
        assert np.array_equal(done.terms.w_hit[stopped], uniform.terms.w_hit[stopped])
        assert np.array_equal(done.terms.escaped[stopped], uniform.terms.escaped[stopped])
