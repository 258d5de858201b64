"""Error estimates a user can trust (issue 22): on small scenes, the bake's reported RMSE
against the one measured from a reference with 4× the rays of every kind
(``baker.study.calibration``), and the share of texels within 2σ / 3σ of their error map."""

from __future__ import annotations

import numpy as np
import pytest

from assets.light_scenes import floor_under_box, penumbra
from assets.make_scenes import cornell_box
from baker.geometry.surface import LUMINANCE
from baker.geometry.world import build_world
from baker.gltf.load import load
from baker.light.ambient import ambient_terms
from baker.light.direct import delivered_power, light_sources
from baker.rays.trace import Tracer
from baker.settings import Settings, resolve
from baker.study import calibration

CASES = {  # the terms whose estimates the sample variance used to overstate 2–4×
    "a soft light's penumbra": (lambda: penumbra(0.2), dict(texel_density=12.0)),
    "the Cornell room's emissive lamp": (cornell_box, dict(texel_density=6.0)),
    "the sky over a box": (floor_under_box, dict(texel_density=6.0, sky=(0.3, 0.4, 0.6))),
    "the Cornell room's path-traced GI": (cornell_box, dict(texel_density=3.0, method="gi")),
}


@pytest.mark.parametrize("name", CASES)
def test_the_reported_error_is_the_measured_one(name, tmp_path):
    """64 rays of every kind: reported ÷ measured RMSE in [0.67, 1.5], and the texels'
    errors within their error map's 2σ / 3σ about as often as normal errors are."""
    make, settings = CASES[name]
    scene = load(make().save(tmp_path / "scene.glb"))
    result = calibration(scene, settings, rays=64, factor=4)
    assert 0.67 <= result["ratio"] <= 1.5, result
    assert result["2σ"] >= 0.92 and result["3σ"] >= 0.98, result


def test_the_ambient_intensity_spreads_over_seeds_as_its_variance_says(tmp_path):
    """I_A comes from the power of the sources estimated at points: its relative variance
    (``Ambient.relative_variance``) is the spread of I_A over seeds (16 seeds: the ratio of
    the measured to the predicted variance is a χ²₁₅/15 draw, within [0.3, 2.2] 99 % of
    the time)."""
    scene = load(cornell_box().save(tmp_path / "room.glb"))
    world = build_world(scene)
    tracer = Tracer(world)
    levels, predicted = [], []
    for seed in range(16):
        resolved = resolve(Settings(seed=seed), 1.0, 1.0)
        sources = light_sources(scene, world, resolved)
        power = delivered_power(scene, world, tracer, sources, resolved)
        ambient = ambient_terms(scene, world, None, power)
        levels.append(float(ambient.intensity @ LUMINANCE))
        predicted.append(ambient.relative_variance)
    measured = np.var(levels, ddof=1) / np.mean(levels) ** 2
    assert 0.3 <= measured / np.mean(predicted) <= 2.2
