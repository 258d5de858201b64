"""Extreme and stiff scenes bake to finite, sensible values (issue 7, DESIGN.md §7).

A first part of the suite: the stiff case of equation (3) and the model's limits on a closed room.
"""

from __future__ import annotations

import numpy as np
import pytest

from assets.extreme_scenes import closed_room, single_triangle
from baker.ambient import MAX_BOUNCES, bounce_factor
from baker.compose import effective_r_ave
from tests.bakehelp import computed


@pytest.mark.parametrize("r_ave", [0.9, 0.99, 0.999999, 1.0])
def test_bounce_series_is_finite_and_increasing_up_to_r_ave_one(r_ave):
    """1/(1 − R_ave) summed as a bounded series: finite at R_ave = 1 (= MAX_BOUNCES), equal to
    the closed form to 0.1 % where that is below the bound."""
    series, truncated = bounce_factor(np.full(3, r_ave))
    assert np.isfinite(series).all() and (series <= MAX_BOUNCES).all()
    if r_ave <= 0.99:
        np.testing.assert_allclose(series, 1 / (1 - r_ave), rtol=1e-3)
        assert not truncated
    else:
        assert truncated and series[0] > 0.6 * MAX_BOUNCES
    lower, _ = bounce_factor(np.full(3, r_ave * 0.999))
    assert (lower < series).all()


def _w(done):
    return done.terms.obscurance(effective_r_ave(done.ambient, done.settings.rho)).mean(axis=1)


def test_closed_room_limits_of_d_max(tmp_path):
    """d_max far below a texel: nothing is hit, W → R_ave. d_max far above the room: every ray
    hits at d ≪ d_max, ρ → 0, W → 0 (closed room)."""
    small = computed(closed_room(albedo=0.5), tmp_path, texel_density=4.0, rays=16, d_max=1e-6)
    w = _w(small)
    # Texels on the room's edges keep their sample point on the edge itself (clamped into the
    # triangle), where half the hemisphere grazes the other wall at d ≈ 0: they stay lower.
    assert np.isfinite(w).all() and (w <= 0.5 + 1e-12).all() and (w > 0.3).all()
    assert np.mean(np.abs(w - 0.5) < 1e-9) > 0.75
    huge = computed(closed_room(albedo=0.5), tmp_path, texel_density=4.0, rays=16, d_max=1e6)
    assert np.isfinite(_w(huge)).all() and _w(huge).max() < 0.01


def test_white_room_with_tiny_or_huge_emission_bakes_finite(tmp_path):
    """Albedo exactly 1 (R_ave = 1: the stiff case) and emission 1e-6 or 1e6: I_A bounded by
    the truncated series, lightmaps finite and in the ratio of the emissions (1e12)."""
    light = {}
    for emission in (1e-6, 1e6):
        done = computed(closed_room(albedo=1.0, emission=emission), tmp_path, texel_density=4.0,
                        rays=8)
        assert done.ambient.truncated and np.isfinite(done.ambient.intensity).all()
        light[emission] = done.lightmaps.light
        assert np.isfinite(light[emission]).all() and light[emission].max() > 0
    covered = light[1e-6] > 0
    np.testing.assert_allclose(light[1e6][covered] / light[1e-6][covered], 1e12, rtol=1e-6)


def test_one_triangle_scene(tmp_path):
    """A single open triangle: every ray escapes, W = R_ave on every texel."""
    done = computed(single_triangle(), tmp_path, texel_density=16.0, rays=8)
    assert len(done.texels) > 10
    np.testing.assert_allclose(_w(done), done.ambient.r_ave.mean(), rtol=1e-9)
