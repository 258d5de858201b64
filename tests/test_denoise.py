"""--denoise: Open Image Denoise's lightmap filter per chart (baker/denoise.py).

Measured here: the denoised Cornell room is closer to a converged reference than the noisy bake;
a dark chart beside a bright one keeps its level (and a page-wide denoise would not); flagged
texels never feed valid ones; the result is the same bytes twice and for 1 or 2 threads.
"""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

import baker
from assets.make_scenes import cornell_box
from baker.pipeline.full import compute
from baker.image.compose import Lightmaps
from baker.image.denoise import MIN_TEXELS, chart_labels, denoise
from baker.errors import SettingsError
from baker.gltf.load import load
from baker.atlas.rasterise import Texels
from baker.settings import Settings


def _texels(page: np.ndarray, y: np.ndarray, x: np.ndarray, instance: np.ndarray,
            shape: tuple[int, int, int]) -> Texels:
    """Texels at the given page positions, all facing +z (only what denoise.py reads is set)."""
    n = len(page)
    zeros3 = np.zeros((n, 3))
    normal = np.tile([0.0, 0.0, 1.0], (n, 1))
    key = ((page * shape[1] + y) * shape[2] + x).astype(np.uint64)
    return Texels(key=key, position=zeros3,
                  normal=normal, triangle=instance, triangle_instance=np.arange(2),
                  triangle_normal=np.array([[0.0, 0.0, 1.0]] * 2), triangle_size=np.ones(2),
                  triangle_texels=np.zeros(0, np.int64), triangle_axes=np.zeros((2, 2, 3)),
                  terminator_push=zeros3, page_width=shape[2], page_height=shape[1])


def _two_charts(gap: int, same_instance: bool, seed: int = 0):
    """A 64×96 page with two 40×30 charts ``gap`` texels apart: the left one bright (50), the
    right one dark (0.05), each with 10 % Gaussian noise. Returns (lightmaps, texels, dark mask
    (H, W), noise σ of the dark chart)."""
    rng = np.random.default_rng(seed)
    shape = (1, 64, 96)
    light = np.zeros(shape + (3,))
    covered = np.zeros(shape, bool)
    left = (slice(12, 52), slice(10, 40))
    right = (slice(12, 52), slice(40 + gap, 70 + gap))
    dark = np.zeros(shape[1:], bool)
    dark[right] = True
    for region, level in ((left, 50.0), (right, 0.05)):
        noisy = level * (1 + 0.1 * rng.standard_normal((40, 30, 1)))
        light[0][region] = np.repeat(noisy, 3, axis=2)
        covered[0][region] = True
    _, y, x = np.nonzero(covered)
    instance = np.zeros(len(y), np.int64) if same_instance else np.where(dark[y, x], 0, 1)
    texels = _texels(np.zeros(len(y), np.int64), y, x, instance.astype(np.int64), shape)
    return Lightmaps(light=light, visibility=light.copy(), covered=covered), texels, dark, 0.005


@pytest.mark.parametrize("gap, same_instance", [(2, True), (0, False)])
def test_light_does_not_cross_chart_borders(gap, same_instance):
    lightmaps, texels, dark, sigma = _two_charts(gap, same_instance)
    out, info = denoise(lightmaps, texels)
    assert info.charts == 2
    before, after = lightmaps.light[0][dark], out.light[0][dark]
    # the dark chart stays at its level: every texel within 3σ of 0.05, the mean within σ/10
    assert np.abs(after - 0.05).max() < 3 * sigma, np.abs(after - 0.05).max()
    assert abs(after.mean() - 0.05) < sigma / 10
    assert after.std() < before.std() / 2  # and was denoised (its noise at least halved)
    # the same filter on the whole page at once smears the bright chart into the dark one
    import pyoidn
    whole = pyoidn.denoise(lightmaps.light[0].astype(np.float32), filter_type="RTLightmap")
    assert np.abs(whole[dark] - 0.05).max() > 10 * sigma


def test_flagged_texels_feed_nothing():
    lightmaps, texels, dark, sigma = _two_charts(2, True, seed=1)
    invalid = np.zeros(lightmaps.covered.shape, bool)
    invalid[0, 20:23, 50:53] = True  # a patch inside the dark chart, its rays started in a wall
    light = lightmaps.light.copy()
    light[invalid] = 1000.0
    out, info = denoise(Lightmaps(light, lightmaps.visibility, lightmaps.covered), texels,
                        invalid=invalid)
    valid_dark = dark & ~invalid[0]
    assert np.abs(out.light[0][valid_dark] - 0.05).max() < 3 * sigma
    assert np.array_equal(out.light[invalid], light[invalid])  # left for postprocess to fill
    assert info.texels == lightmaps.covered.sum() - invalid.sum()
    # uncovered texels are untouched too
    assert np.array_equal(out.light[~lightmaps.covered], light[~lightmaps.covered])


def test_small_patches_and_creases():
    """A patch under MIN_TEXELS keeps its values; a crease splits a chart into two patches."""
    y, x = np.mgrid[0:20, 0:20]
    y, x = y.ravel(), x.ravel()
    texels = _texels(np.zeros(len(y), np.int64), y, x, np.zeros(len(y), np.int64), (1, 20, 20))
    normal = texels.normal.copy()
    normal[x >= 10] = [1.0, 0.0, 0.0]  # a box's edge down the middle
    from dataclasses import replace
    creased = replace(texels, normal=normal)
    assert chart_labels(texels, (1, 20, 20)).max() == 0
    assert chart_labels(creased, (1, 20, 20)).max() == 1
    small = _texels(np.zeros(MIN_TEXELS - 1, np.int64), np.zeros(MIN_TEXELS - 1, np.int64),
                    np.arange(MIN_TEXELS - 1), np.zeros(MIN_TEXELS - 1, np.int64), (1, 4, 80))
    rng = np.random.default_rng(2)
    light = np.zeros((1, 4, 80, 3))
    light[0, 0, :MIN_TEXELS - 1] = rng.uniform(0.5, 1.5, (MIN_TEXELS - 1, 3))
    covered = np.zeros((1, 4, 80), bool)
    covered[0, 0, :MIN_TEXELS - 1] = True
    out, info = denoise(Lightmaps(light, light, covered), small)
    assert info.charts == 0 and np.array_equal(out.light, light)


def _rmse(light: np.ndarray, reference: np.ndarray, covered: np.ndarray) -> float:
    return float(np.sqrt(np.mean((light[covered] - reference[covered]) ** 2)))


def _settings(rays: int, **more) -> Settings:
    return Settings(page_size=128, rays=rays, shadow_rays=max(1, rays // 4),
                    emissive_rays=max(1, rays // 4), sky_rays=rays, **more)


def test_denoised_cornell_room_is_closer_to_the_reference(tmp_path):
    path = cornell_box().save(tmp_path / "cornell_box.glb")
    scene = load(path)
    reference = compute(scene, _settings(512)).lightmaps
    noisy = compute(scene, _settings(16)).lightmaps
    first = compute(scene, _settings(16, denoise=True))
    covered = reference.covered
    before = _rmse(noisy.light, reference.light, covered)
    after = _rmse(first.lightmaps.light, reference.light, covered)
    # measured 1.96e-2 → 1.10e-2 (1.8×) on this 128² page; 3.4× on a 256² page
    # (benchmarks/bench_denoise.py), where a texel is smaller than the light's detail
    assert after < before / 1.5, (before, after)
    assert first.stage_seconds["denoise"] > 0 and first.denoised.charts > 0
    # determinism: the same bytes again, and with one thread instead of one per core
    again = compute(scene, _settings(16, denoise=True, threads=1))
    assert first.lightmaps.light.tobytes() == again.lightmaps.light.tobytes()
    # the report says whether and how long it denoised
    out = tmp_path / "out.glb"
    result = baker.bake(path, out, _settings(16, denoise=True), report_path=tmp_path / "r.json")
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["denoise"]["denoised"] is True and report["denoise"]["seconds"] > 0
    assert report["settings"]["denoise"] is True and "denoise" in report["stage_seconds"]
    assert result.report["denoise"]["charts"] == first.denoised.charts
    plain = baker.bake(path, tmp_path / "plain.glb", _settings(16))
    assert plain.report["denoise"] == {"denoised": False}


def test_same_bytes_for_one_and_two_threads():
    lightmaps, texels, _, _ = _two_charts(2, True, seed=3)
    one, _ = denoise(lightmaps, texels, threads=1)
    two, _ = denoise(lightmaps, texels, threads=2)
    again, _ = denoise(lightmaps, texels, threads=2)
    assert one.light.tobytes() == two.light.tobytes() == again.light.tobytes()
    assert not np.array_equal(one.light, lightmaps.light)


def test_missing_pyoidn_names_the_fix(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "pyoidn" else real(name, *a))
    with pytest.raises(SettingsError) as caught:
        Settings(denoise=True).check()
    assert 'pip install "baker[denoise]"' in caught.value.fix
    assert 'pip install ".[denoise]"' in caught.value.fix
    Settings(denoise=False).check()  # not asked for: no complaint


def test_cli_flag():
    import argparse

    from baker.cli import bake as cli_bake
    parser = argparse.ArgumentParser()
    cli_bake.add_parser(parser.add_subparsers())
    args = parser.parse_args(["bake", "in.glb", "-o", "out.glb", "--denoise"])
    assert cli_bake.settings_from(args).denoise is True
    args = parser.parse_args(["bake", "in.glb", "-o", "out.glb"])
    assert cli_bake.settings_from(args).denoise is False
