"""The world-space filter (``image/world_filter``): what it mixes, and its error estimate."""

import json
from dataclasses import replace

import numpy as np
import pytest

import baker
from assets.light_scenes import penumbra
from assets.make_scenes import cornell_box
from assets.rebake_scenes import box_room, grid_boxes
from baker.atlas.validity import MOVED, VALID
from baker.cli.main import main
from baker.errors import SettingsError
from baker.geometry.surface import luminance
from baker.gltf.load import load
from baker.image.world_filter import smooth
from baker.pipeline.full import compute
from tests.bakehelp import computed


def _plane(n: int, size: float, normal=(0.0, 0.0, 1.0), offset=(0.0, 0.0, 0.0)):
    """(n², 3) texel centres of an n × n grid of side ``size`` in the plane through ``offset``
    with unit ``normal`` (its first two axes the plane's), and their normals."""
    u, v = np.meshgrid(np.arange(n) * size, np.arange(n) * size, indexing="ij")
    normal = np.asarray(normal, float)
    a = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    points = u.reshape(-1, 1) * a + v.reshape(-1, 1) * b + np.asarray(offset, float)
    return points, np.tile(normal, (len(points), 1))


def test_noise_on_a_smooth_surface_falls_and_sure_estimates_the_error_left():
    """A plane whose true value varies over a few texels (a period of 16), each texel's
    estimate noisy with a known variance: the chosen width smooths, the RMSE falls about 3×,
    and the mean SURE (from unbiased per-texel variance estimates of one degree of freedom,
    as a texel's split gives) is within 15 % of the squared error measured against the truth.
    The reported error, the bound, lies above it by its two standard errors."""
    rng = np.random.default_rng(1)
    position, normal = _plane(120, 0.1)
    truth = 0.5 + 0.3 * np.sin(position[:, 0] * 4.0)
    sigma = 0.1
    noisy = truth + rng.normal(0.0, sigma, len(truth))
    variance = sigma ** 2 * rng.chisquare(1, len(truth))  # unbiased, one degree of freedom
    done = smooth(position, normal, np.full(len(truth), 0.1), noisy[:, None], noisy, variance)
    measured = np.mean((done.values[:, 0] - truth) ** 2)
    assert done.width > 0
    assert np.sqrt(measured) < sigma / 2.5
    assert 0.85 < done.sure.mean() / measured < 1.15
    assert 1.0 < done.error ** 2 / measured < 1.5  # the bound: above, not far
    assert done.bound_by_width[0.0] == variance.mean()  # unsmoothed: today's estimate


def test_exact_values_with_an_edge_are_left_alone():
    """No noise (variance 0) and a sharp step: any smoothing only adds error, SURE says so,
    and the values come back unchanged."""
    position, normal = _plane(40, 0.1)
    values = np.where(position[:, 0] < 2.0, 0.0, 1.0)
    done = smooth(position, normal, np.full(len(values), 0.1), values[:, None], values,
                  np.zeros(len(values)))
    assert done.width == 0.0 and np.array_equal(done.values[:, 0], values)


def test_light_does_not_cross_creases_walls_or_gaps():
    """Texels of a floor at 0 beside a wall at 1 (a crease), under a thin wall's other side
    at 1 (back to back, 0.1 texel apart) and under a shelf at 1 a texel above it (parallel,
    off its plane): smoothed as hard as the filter goes, the floor's texels stay 0 exactly."""
    size = 0.1
    floor, up = _plane(30, size)
    wall, out = _plane(30, size, normal=(1.0, 0.0, 0.0), offset=(-0.05, 0.0, 0.05))
    back, down = _plane(30, size, normal=(0.0, 0.0, -1.0), offset=(0.0, 0.0, -0.01))
    shelf, over = _plane(30, size, offset=(0.0, 0.0, size))
    position = np.vstack([floor, wall, back, shelf])
    normal = np.vstack([up, out, down, over])
    values = np.r_[np.zeros(len(floor)), np.ones(3 * len(floor))]
    rng = np.random.default_rng(2)
    noisy = values + rng.normal(0.0, 0.3, len(values)) * (values > 0)  # noise: smooth hard
    variance = np.where(values > 0, 0.09, 0.0)
    done = smooth(position, normal, np.full(len(values), size), noisy[:, None], noisy, variance)
    assert done.width > 0
    assert np.array_equal(done.values[:len(floor), 0], np.zeros(len(floor)))


def test_where_sure_is_too_noisy_to_trust_the_bound_stays_above_the_error():
    """A truth 8× smoother: smoothing leaves about 1/70 of the raw noise's squared error, and
    the mean SURE, a difference of two sums of the raw noise's size, swings from 0.07 to
    1.06 of the measured error by seed. The bound the filter reports (and chooses the width
    by) stays above the measured error, within 3× of it, for every seed."""
    position, normal = _plane(120, 0.1)
    truth = 0.5 + 0.3 * np.sin(position[:, 0] * 0.5)
    for seed in range(4):
        rng = np.random.default_rng(seed)
        noisy = truth + rng.normal(0.0, 0.1, len(truth))
        variance = 0.01 * rng.chisquare(1, len(truth))
        done = smooth(position, normal, np.full(len(truth), 0.1), noisy[:, None], noisy,
                      variance)
        measured = np.mean((done.values[:, 0] - truth) ** 2)
        assert done.width > 0 and measured < 0.1 * 0.01
        assert 1.0 < done.error ** 2 / measured < 9.0


def _valid_luminance(done) -> np.ndarray:
    """(k,) the composed light's luminance at the valid texels of a ``pipeline.full.Computed``."""
    valid = np.isin(done.validity.state, (VALID, MOVED))
    return luminance(done.lightmaps.light[done.texels.pixels()])[valid]


@pytest.fixture(scope="module")
def cornell(tmp_path_factory):
    """The demo's Cornell room (its ceiling lamp an emitter), loaded."""
    return load(cornell_box().save(tmp_path_factory.mktemp("cornell") / "room.glb"))


def test_a_smoothed_bake_is_nearer_the_truth_and_says_by_how_much(cornell):
    """The Cornell room at 4 rays, smoothed: against a 1024-ray bake of another seed (its own
    noise, as it estimates it, taken out), the error falls at least 2× (2.6× measured), and
    the bake's ``rmse_estimate`` is within 0.8–1.6× of the error measured (1.03: the report's
    figure is the smoothed light's, not the rays')."""
    settings = baker.Settings(rays=4, shadow_rays=4, emissive_rays=4, page_size=192, threads=2)
    raw = compute(cornell, settings)
    smoothed = compute(cornell, replace(settings, smooth=True))
    reference = compute(cornell, replace(settings, rays=1024, shadow_rays=256,
                                         emissive_rays=256, seed=7))
    truth = _valid_luminance(reference)

    def measured(done) -> float:
        squares = np.mean((_valid_luminance(done) - truth) ** 2)
        return float(np.sqrt(max(squares - reference.rmse_estimate() ** 2, 0.0)))

    assert smoothed.smoothed.width > 0
    assert measured(smoothed) < measured(raw) / 2
    assert 0.8 < smoothed.rmse_estimate() / measured(smoothed) < 1.6
    assert 0.8 < raw.rmse_estimate() / measured(raw) < 1.25  # the unsmoothed figure, as before
    assert smoothed.rmse_estimate() < raw.rmse_estimate()


def test_smoothing_asked_of_a_rebake_recomposes_to_the_full_bake(tmp_path):
    """``--smooth`` added on a rebake casts no ray (a recomposition from the state) and gives
    the bytes of a full bake with it; taken away again, those of a full bake without."""
    scene = box_room(grid_boxes(2, room=(3.0, 2.5, 3.0), size=0.4), room=(3.0, 2.5, 3.0),
                     lamp={"at": (0.2, 2.2, 0.1), "intensity": 5.0, "radius": 0.1}
                     ).save(tmp_path / "room.glb")
    plain = baker.Settings(rays=8, page_size=128, shadow_rays=4, threads=1)
    baker.bake(scene, tmp_path / "incremental.glb", plain)
    for smooth in (True, False):
        asked = replace(plain, smooth=smooth)
        again = baker.bake(scene, tmp_path / "incremental.glb", asked, incremental="always")
        baker.bake(scene, tmp_path / "full.glb", asked)
        assert again.rebake["incremental"] is True and again.rebake["dirty_texels"] == 0
        assert again.report["smooth"]["smoothed"] is smooth
        for name in ("incremental.glb", "full.glb"):
            assert (tmp_path / name).exists()
        assert (tmp_path / "incremental.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()


def test_smooth_and_denoise_together_are_refused():
    """Two denoisers: the second would see the first's output, the error estimate neither."""
    with pytest.raises(SettingsError, match="--smooth and --denoise"):
        baker.Settings(smooth=True, denoise=True).check()


def test_a_hard_shadow_keeps_its_edge_while_the_noise_around_it_is_smoothed(tmp_path):
    """A hard point light's shadow edge across a floor under a low occluder, the ambient term
    noisy (2 rays): smoothed, the light's step across the edge (1.5 texels either side) stays
    within 0.005 of the hard light's own step (0.248), and the noise far from it falls at
    least 4×: the hard lights' light (``Sources.exact``) is left out of the filter, so the
    edge costs the smoothing no width."""
    settings = dict(only_nodes={0}, texel_density=100.0, rays=2, page_size=512, ambient=1.0)
    profiles = {}
    for smooth in (False, True):
        done = computed(penumbra(0.0, width=0.5, edge_height=0.3), tmp_path, smooth=smooth,
                        **settings)
        light = luminance(done.lightmaps.light[done.texels.pixels()])
        x = done.texels.position[:, 0]
        exact = luminance(done.sources.exact(done.direct))
        left, right = (x > -0.02) & (x < -0.005), (x > 0.005) & (x < 0.02)
        profiles[smooth] = (light[right].mean() - light[left].mean(),
                            exact[right].mean() - exact[left].mean(),
                            light[(x < -0.3) & (x > -0.5)].std(), done.smoothed)
    step, exact_step, noise, smoothed = profiles[True]
    assert smoothed.width > 0 and exact_step > 0.2
    assert abs(step - exact_step) < 0.005
    assert noise < profiles[False][2] / 4


def test_where_smoothing_does_not_pay_the_bake_and_its_estimate_are_as_without(tmp_path):
    """A floor whose light has hardly any noise (a hard light, an open sky of obscurance): the
    width chosen is 0, and the pages and the estimate are those of a bake without --smooth
    (the estimate keeps the floor a texel whose rays all agreed takes)."""
    done = {smooth: computed(penumbra(0.0, width=0.5), tmp_path, only_nodes={0},
                             texel_density=100.0, rays=4, page_size=512, smooth=smooth)
            for smooth in (False, True)}
    assert done[True].smoothed.width == 0.0
    assert np.array_equal(done[True].lightmaps.light, done[False].lightmaps.light)
    assert done[True].rmse_estimate() == done[False].rmse_estimate() > 0


def test_the_command_says_how_wide_it_smoothed_and_the_error_before_and_after(tmp_path, capsys):
    """``baker bake --smooth`` prints the width and the estimated RMSE before and after (the
    report's ``smooth`` entry), the after being the bake's estimate."""
    scene = cornell_box().save(tmp_path / "room.glb")
    assert main(["bake", str(scene), "-o", str(tmp_path / "out.glb"), "--page-size", "128",
                 "--rays", "4", "--smooth", "--no-state", "--report",
                 str(tmp_path / "report.json")]) == 0
    said = capsys.readouterr().out
    smooth = json.loads((tmp_path / "report.json").read_text())["smooth"]
    assert smooth["width_texels"] > 0
    assert (f"smooth: {smooth['width_texels']:g} texel sides wide; estimated RMSE "
            f"{smooth['rmse_before']:.3g} before, {smooth['rmse_after']:.3g} after") in said
