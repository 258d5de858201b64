"""Adaptive sampling and integrating a subset of texels."""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

import baker
from assets.light_scenes import floor_under_box, penumbra
from assets.make_scenes import cornell_box, parallel_planes
from baker.image.compose import effective_r_ave
from baker.light import adaptive
from baker.light.hemisphere import Terms, cosine_directions, predicted_error
from baker.light.integrate import integrate
from baker.errors import SettingsError
from baker.settings import DEFAULT_RAYS, FIRST_ROUND_RAYS, Settings, resolve
from baker.geometry.surface import LUMINANCE
from tests.bakehelp import computed, saved

SETTINGS = dict(texel_density=6.0, rays=16, max_rays=256, d_max=0.6)


def _lightmap(done, scale):
    """(N,) luminance of D + I_A · W at R_ave and lum I_A ``scale`` (a reference's: I_A's
    estimate depends on the seed, and only the texels' noise is under test)."""
    return (done.terms.obscurance(scale[0]) @ LUMINANCE * scale[1]
            + done.direct.irradiance() @ LUMINANCE)


def _every_kind(rays: int) -> dict:
    """Settings with ``rays`` rays of every kind: obscurance, shadow, emissive, sky."""
    return dict(rays=rays, shadow_rays=rays, emissive_rays=rays, sky_rays=rays)


def test_the_target_is_met_with_no_more_rays_than_the_best_uniform_count(tmp_path):
    """On the Cornell room, lit by its emissive lamp (noisy direct light, adapted too): ≥ 95 %
    of texels' lightmap luminance within E of a 2048-ray reference, RMSE ≤ E, and at most
    1.25× the rays of the smallest power-of-two uniform count of every kind that does as well."""
    reference = computed(cornell_box(), tmp_path, **{**SETTINGS, **_every_kind(2048)}, seed=2)
    scale = (effective_r_ave(reference.ambient, "sqrt"),
             float(reference.ambient.intensity @ LUMINANCE))
    truth = _lightmap(reference, scale)
    target = 0.004

    def meets(done):
        error = _lightmap(done, scale) - truth
        return np.sqrt(np.mean(error ** 2)) <= target and np.mean(np.abs(error) <= target) >= 0.95

    def rays(done):
        return done.terms.rays + done.direct.rays

    done = computed(cornell_box(), tmp_path, target_error=target, **SETTINGS)
    assert meets(done)
    uniform = next(u for u in (computed(cornell_box(), tmp_path, **{**SETTINGS, **_every_kind(n)})
                               for n in (16, 32, 64, 128, 256)) if meets(u))
    assert uniform.settings.rays > 16  # else the test would not tell adaptive rounds from one
    assert rays(done) <= 1.25 * rays(uniform)
    assert len(np.unique(done.terms.counts)) > 2  # texels stopped at different rounds
    assert len(np.unique(done.direct.texel_rays)) > 2  # and so did their direct light


def test_gi_paths_meet_the_target_with_no_more_rays_than_the_best_uniform_count(tmp_path):
    """``--method gi`` on the Cornell room: the lightmap D + E_ind within E of a 2048-path
    reference at ≥ 95 % of texels, RMSE ≤ E, with at most 1.25× the GI and shadow rays of the
    smallest power-of-two uniform path count that does as well. (Without the nets' gain, the
    paths' sample variance overstated their error and the rounds took 1.64× those rays; with
    settled neighbours' variance per mean instead of per path, more.)"""
    settings, target = dict(texel_density=4.0, method="gi", **_every_kind(16)), 0.04
    truth = computed(cornell_box(), tmp_path, **{**settings, "rays": 2048}, seed=2)

    def light(done):
        return done.lightmaps.light[done.lightmaps.covered] @ LUMINANCE

    def meets(done):
        error = light(done) - light(truth)
        return np.sqrt(np.mean(error ** 2)) <= target and np.mean(np.abs(error) <= target) >= 0.95

    def rays(done):
        return done.tally.gi_rays + done.tally.shadow_rays

    done = computed(cornell_box(), tmp_path, target_error=target, max_rays=512, **settings)
    assert meets(done)
    uniform = next(u for u in (computed(cornell_box(), tmp_path, **{**settings, "rays": n})
                               for n in (32, 64, 128, 256)) if meets(u))
    assert uniform.settings.rays > 32
    assert rays(done) <= 1.25 * rays(uniform)


def test_a_texel_whose_rays_agree_and_never_escape_does_not_stop():
    """σ = 0 is never claimed where nothing escaped: the ``binomial_floor`` decides."""
    terms = Terms(w_hit=np.zeros((2, 3)), escaped=np.array([0.0, 1.0]), hit_sq=np.zeros(2),
                  counts=np.array([64, 64]), half_split=np.zeros((2, 2)))
    apart = SimpleNamespace(key=np.array([0, 100], np.uint64), page_width=10)  # no neighbours

    def unsettled(terms):
        return adaptive.WITHIN * predicted_error(terms, None, apart, np.arange(2)) > 0.01

    assert list(unsettled(terms)) == [True, False]
    assert not unsettled(replace(terms, counts=np.array([256, 64])))[0]


def test_a_texel_whose_rays_all_escaped_under_a_ceiling_does_not_stop(tmp_path):
    """Step AO under a ceiling at h = 0.9 d_max: a ray escapes unless cos θ ≥ h, so W's
    escaped fraction is h² = 0.81 at every texel. At 16 rays about one texel in 30 sees all of
    them escape (zero sample variance); its neighbours' variance keeps it going
    (``hemisphere._stopping_error``): no texel ends with every ray escaped, and the lightmap's
    RMSE against the closed form is within E (stopped by their own rays, those texels were
    0.19 off: RMSE 0.028 for E = 0.004)."""
    target = 0.004
    done, error = _step_ceiling(tmp_path, 0.9, 1.0, target, 2048)
    assert len(done.texels) > 300
    assert np.all(done.terms.escaped < 1.0)
    assert np.sqrt(np.mean(error ** 2)) <= target


def _step_ceiling(tmp_path, height, probe_size, target, max_rays):
    """A bake with ``target`` of the probe under a ceiling at ``height`` d_max (ρ = step, 16
    rays first, 20 texels per unit), and each texel's lightmap error against the closed
    form: a ray escapes unless cos θ ≥ h, so W's escaped fraction is h²."""
    builder = parallel_planes(height=height, half_extent=5.0, probe_size=probe_size)
    done = computed(builder, tmp_path, only_nodes={builder.info["nodes"]["probe"]},
                    texel_density=20.0, d_max=1.0, rho="step", rays=16, target_error=target,
                    max_rays=max_rays)
    scale = float(effective_r_ave(done.ambient, "step") @ LUMINANCE) * float(
        done.ambient.intensity @ LUMINANCE)
    return done, (done.terms.escaped - height ** 2) * scale


def test_texels_whose_nets_happen_to_agree_do_not_stop_together(tmp_path):
    """Under a ceiling at 0.3 d_max (ρ = step; W = (h/d_max)² exactly) most texels' two nets
    of 128 rays both see 12 escapes, split 0, while the truth is 11.52. Grouped for the nets'
    gain by their own variance, those texels made a group of their own, measured a gain of 0
    and stopped together: 560 of 1681 texels, each 0.0038 off at E = 0.002 (65.6 % within E).
    Grouped by their neighbours' variance, the gain is measured on texels whose own split did
    not choose them."""
    target = 0.002
    done, error = _step_ceiling(tmp_path, 0.3, 2.0, target, 4096)
    assert len(done.texels) > 4 * adaptive.GAIN_TEXELS  # several groups
    assert np.sqrt(np.mean(error ** 2)) <= target
    assert np.mean(np.abs(error) <= target) >= 0.95


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


def test_target_error_starts_at_a_small_first_round_unless_rays_are_given(tmp_path):
    """The first round is the least a texel gets: without ``--rays``, a target starts at
    ``FIRST_ROUND_RAYS`` obscurance and sky rays (the default 64 would be every texel's
    floor), and a bake without a target keeps ``DEFAULT_RAYS``."""
    from baker.cli.bake import settings_from
    from baker.cli.main import build_parser

    def resolved(*options):
        args = build_parser().parse_args(["bake", "in.glb", "-o", "out.glb", *options])
        s = resolve(settings_from(args), 1.0, 1.0)
        return s.rays, s.sky_rays

    assert resolved() == (DEFAULT_RAYS, DEFAULT_RAYS)
    assert resolved("--target-error", "0.01") == (FIRST_ROUND_RAYS, FIRST_ROUND_RAYS)
    assert resolved("--target-error", "0.01", "--rays", "64", "--sky-rays", "32") == (64, 32)
    settings = {k: v for k, v in SETTINGS.items() if k != "rays"}
    done = computed(cornell_box(), tmp_path, target_error=0.01, **settings)
    assert done.settings.rays == FIRST_ROUND_RAYS < DEFAULT_RAYS
    assert done.terms.counts.min() == FIRST_ROUND_RAYS < done.terms.counts.max()


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
    ``hemisphere.predicted_error``)."""
    done = computed(cornell_box(), tmp_path, **SETTINGS)
    rows = np.random.default_rng(1).choice(len(done.texels), 300, replace=False)
    part = integrate(done.context(), done.texels, rows=rows)
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


PENUMBRA = dict(texel_density=40.0, rays=16, max_rays=512)


@pytest.mark.long
def test_soft_light_rounds_meet_the_target_and_match_uniform_bakes(tmp_path):
    """A soft point light's penumbra (direct light only is noisy there, the obscurance rounds
    aim at E/√2): D's luminance within E of a 2048-shadow-ray reference at ≥ 95 % of texels
    with RMSE ≤ E; a texel that stopped after m× the first round's shadow rays has exactly the
    D of a uniform bake with m× the rays."""
    target = 0.002
    reference = computed(penumbra(0.2), tmp_path, **{**PENUMBRA, "shadow_rays": 2048}, seed=2)
    done = computed(penumbra(0.2), tmp_path, target_error=target, **PENUMBRA)
    truth = reference.direct.irradiance() @ LUMINANCE
    error = done.direct.irradiance() @ LUMINANCE - truth
    assert np.sqrt(np.mean(error ** 2)) <= target and np.mean(np.abs(error) <= target) >= 0.95
    first = done.direct.rays_per_texel
    for scale in (2, 4):
        uniform = computed(penumbra(0.2), tmp_path, **{**PENUMBRA, "shadow_rays": 16 * scale})
        stopped = done.direct.texel_rays == first * (2 * scale - 1)  # 16 + 32 (+ 64)
        assert stopped.any()
        assert np.array_equal(done.direct.punctual[stopped], uniform.direct.punctual[stopped])


def test_sky_rounds_meet_the_target_beside_a_small_occluder(tmp_path):
    """A floor beside a box under the sky: far from the box a texel's few sky rays all miss it
    (σ = 0 by its samples alone) while it hides a little sky; the rule of succession's floor
    near the texels that saw the box keeps them going. D within E of a 2048-ray reference at
    ≥ 95 % of texels, RMSE ≤ E."""
    target, settings = 0.004, dict(texel_density=10.0, sky=(0.3, 0.4, 0.6), rays=16, sky_rays=16)
    reference = computed(floor_under_box(), tmp_path, **{**settings, "sky_rays": 2048}, seed=2)
    done = computed(floor_under_box(), tmp_path, target_error=target, max_rays=2048, **settings)
    error = (done.direct.irradiance() - reference.direct.irradiance()) @ LUMINANCE
    assert np.sqrt(np.mean(error ** 2)) <= target and np.mean(np.abs(error) <= target) >= 0.95


def test_neighbour_mean_averages_the_square_about_each_texel_without_it():
    """``adaptive.neighbour_mean`` against a brute force over every pair of keys: the texels
    within NEAR rows and NEAR columns, the texel itself left out (a row's ends beside the next
    row's, as its keys run on), its own value where it has none."""
    rng = np.random.default_rng(5)
    width = 13
    keys = np.sort(rng.choice(400, 90, replace=False)).astype(np.uint64)
    values = rng.random(len(keys))
    texels = SimpleNamespace(key=keys, page_width=width)
    offsets = {dy * width + dx for dy in range(-adaptive.NEAR, adaptive.NEAR + 1)
               for dx in range(-adaptive.NEAR, adaptive.NEAR + 1)} - {0}
    rows = rng.choice(len(keys), 40, replace=False)
    expected = []
    for r in rows:
        near = [values[j] for j in range(len(keys)) if int(keys[j]) - int(keys[r]) in offsets]
        expected.append(np.mean(near) if near else values[r])
    assert np.allclose(adaptive.neighbour_mean(texels, values, rows), expected, rtol=1e-12)
    assert any(e != values[r] for e, r in zip(expected, rows))


def test_a_target_the_rays_cannot_reach_is_said(tmp_path):
    """A target below what ``--max-rays`` can reach leaves a note with the estimated RMSE and
    what to change; a target the bake meets leaves none."""
    scene = saved(cornell_box(), tmp_path)

    def bake(target):
        return baker.bake(scene, tmp_path / "out.glb", Settings(
            texel_density=4.0, rays=4, max_rays=8, target_error=target)).report

    tight = bake(1e-6)
    said = [note for note in tight["notes"] if note.startswith("--target-error")]
    assert len(said) == 1 and tight["rmse_estimate"] > 1e-6
    assert "1e-06 was not met" in said[0] and "--max-rays 8" in said[0]
    assert f"{tight['rmse_estimate']:.4g}" in said[0]
    loose = bake(10.0)
    assert loose["rmse_estimate"] <= 10.0
    assert not any(note.startswith("--target-error") for note in loose["notes"])


def test_rays_asked_a_few_of_a_texel_at_a_time_are_the_bits_of_its_rays(tmp_path):
    """A rebake's candidate rays (``reach.rays_meet``: some of each texel's, in any order,
    made from each texel's normals and lift gathered once, ``world_rays``) are the bits of
    those rays made texel by texel (``hemisphere_rays``), on smooth and flat texels alike."""
    from assets.artifact_scenes import sphere_on_floor
    from baker.light.hemisphere import hemisphere_rays, world_rays
    from baker.rays.trace import Tracer
    from tests.bakehelp import computed

    done = computed(sphere_on_floor(), tmp_path, page_size=64, rays=4)
    texels, center, rays = done.texels, Tracer(done.world).center, 8
    rng = np.random.default_rng(5)
    rows = rng.choice(len(texels), 300, replace=False)
    texel, sample = rng.integers(0, len(rows), 5000), rng.integers(0, rays, 5000)
    x, y, z = (axis.reshape(len(rows), rays)[texel, sample]
               for axis in cosine_directions(texels.key[rows], rays, 3))
    asked = world_rays(texels, rows, texel, x, y, z, center, sample)
    whole = hemisphere_rays(texels, rows, rays, 3, center)
    ray = texel * rays + sample
    assert np.array_equal(asked[0], whole[0][ray]) and np.array_equal(asked[1], whole[1][ray])
    tilted = ~np.isclose(texels.hemisphere_normal(rows), texels.geometric_normal(rows)).all(axis=1)
    assert tilted.any() and (~tilted).any()  # both kinds of frame were made


def test_rays_made_texel_by_texel_are_the_bits_of_the_directions_drawn_at_once(tmp_path):
    """``hemisphere_rays`` makes each texel's points, directions and rays in one pass
    (``_rays_kernel``); they are the bits of ``cosine_directions`` then ``world_rays`` over all
    texels at once, for every technique, an adaptive round's grown nets and sub-positions."""
    from assets.make_scenes import cornell_box
    from baker.atlas.supersample import sub_positions
    from baker.light.hemisphere import hemisphere_rays, world_rays
    from baker.rays.trace import Tracer
    from tests.bakehelp import computed

    done = computed(cornell_box(), tmp_path, page_size=64, rays=4)
    texels, tracer = done.texels, Tracer(done.world)
    rows = np.arange(0, len(texels), 7)
    sub = sub_positions(tracer, texels, rows, 4, 3)
    for technique, rays, first, start, moved in (("sobol", 16, 0, 16, None),
                                                 ("sobol", 8, 8, 8, None),
                                                 ("sobol", 6, 0, 6, sub),
                                                 ("stratified", 12, 0, 12, None),
                                                 ("random", 5, 3, 0, sub)):
        fused = hemisphere_rays(texels, rows, rays, 3, tracer.center, technique, first, moved,
                                start)
        x, y, z = cosine_directions(texels.key[rows], rays, 3, technique, first, start)
        texel = np.repeat(np.arange(len(rows)), rays)
        sample = first + np.tile(np.arange(rays), len(rows))
        apart = world_rays(texels, rows, texel, x, y, z, tracer.center, sample, moved)
        assert np.array_equal(fused[0], apart[0]) and np.array_equal(fused[1], apart[1])
