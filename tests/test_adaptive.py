"""Adaptive sampling and integrating a subset of texels."""

from dataclasses import replace

import numpy as np
import pytest

from assets.make_scenes import cornell_box
from baker.image.compose import effective_r_ave
from baker.light.hemisphere import Terms, cosine_directions, unsettled
from baker.light.integrate import integrate
from baker.errors import SettingsError
from baker.settings import Settings
from baker.geometry.surface import LUMINANCE
from baker.rays.trace import Tracer
from tests.bakehelp import computed

SETTINGS = dict(texel_density=6.0, rays=16, max_rays=256, d_max=0.6)


def _ambient(done, scale):
    """(N,) luminance of I_A · W at R_ave and lum I_A ``scale`` (a reference's: I_A's estimate
    depends on the seed, and only W's noise is under test)."""
    return done.terms.obscurance(scale[0]) @ LUMINANCE * scale[1]


def test_the_target_is_met_with_no_more_rays_than_the_best_uniform_count(tmp_path):
    """On the Cornell room: ≥ 95 % of texels within E of a 4096-ray reference, RMSE ≤ E, and
    at most 1.25× the rays of the smallest power-of-two uniform count that does as well."""
    reference = computed(cornell_box(), tmp_path, **{**SETTINGS, "rays": 4096}, seed=2)
    scale = (effective_r_ave(reference.ambient, "sqrt"),
             float(reference.ambient.intensity @ LUMINANCE))
    truth = _ambient(reference, scale)
    target = 0.004

    def meets(done):
        error = _ambient(done, scale) - truth
        return np.sqrt(np.mean(error ** 2)) <= target and np.mean(np.abs(error) <= target) >= 0.95

    done = computed(cornell_box(), tmp_path, target_error=target, **SETTINGS)
    assert meets(done)
    uniform = next(n for n in (16, 32, 64, 128, 256)
                   if meets(computed(cornell_box(), tmp_path, **{**SETTINGS, "rays": n})))
    assert uniform > 16  # else the test would not tell adaptive rounds from one
    assert done.terms.rays <= 1.25 * uniform * len(truth)
    assert len(np.unique(done.terms.counts)) > 2  # texels stopped at different rounds


def test_a_texel_whose_rays_agree_and_never_escape_does_not_stop():
    """σ = 0 is never claimed where nothing escaped: the ``binomial_floor`` decides."""
    terms = Terms(w_hit=np.zeros((2, 3)), escaped=np.array([0.0, 1.0]), hit_sq=np.zeros(2),
                  counts=np.array([64, 64]), half_split=np.zeros((2, 2)))
    assert list(unsettled(terms, None, 0.01)) == [True, False]
    assert not unsettled(replace(terms, counts=np.array([256, 64])), None, 0.01)[0]


def test_rounds_grow_the_two_nets_of_the_first_round():
    """A round's sobol points are the next points of the texel's two nets, so after it the
    texel holds the first n/2 points of each, as the uniform bake's nets are laid out."""
    keys = np.array([3, 77], np.uint64)
    start = cosine_directions(keys, 8, 5)  # two nets of 4 points from sample 0 and 4
    grown = cosine_directions(keys, 8, 5, first=8, start=8)  # points 4 … 7 of each
    whole_a = cosine_directions(keys, 16, 5)  # its first net: points 0 … 7 from word OBSCURANCE
    for texel in range(2):
        assert np.array_equal(grown[0][texel * 8:texel * 8 + 4],
                              whole_a[0][texel * 16 + 4:texel * 16 + 8])
        assert np.array_equal(start[0][texel * 8:texel * 8 + 4],
                              whole_a[0][texel * 16:texel * 16 + 4])


def test_target_error_refuses_an_odd_first_round():
    with pytest.raises(SettingsError, match="even number of rays"):
        Settings(rays=15, target_error=0.01).check()


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
    """Without adaptive rounds (with them, the error model is pooled over the rows asked for:
    ``hemisphere.unsettled``)."""
    done = computed(cornell_box(), tmp_path, **SETTINGS)
    rows = np.random.default_rng(1).choice(len(done.texels), 300, replace=False)
    part = integrate(done.scene, done.world, Tracer(done.world), done.texels, done.settings,
                     rows=rows)
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
