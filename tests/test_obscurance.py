"""The obscurance estimator against closed forms (DESIGN.md §2, equations 2–4)."""

import numpy as np
import pytest

from assets.make_scenes import open_plane, parallel_planes, red_wall_floor
from baker.compose import effective_r_ave
from baker.integrate import Terms
from tests.bakehelp import computed


def _w(done) -> np.ndarray:
    return done.terms.obscurance(effective_r_ave(done.ambient, done.settings.rho))


def test_open_plane_sees_r_ave_exactly(tmp_path):
    done = computed(open_plane(albedo=0.6), tmp_path, texel_density=8.0, rays=16, d_max=1.0)
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
    done = computed(red_wall_floor(), tmp_path, texel_density=8.0, rays=256, d_max=2.0)
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
                  half_split=np.zeros((1, 2)), quarter_split=np.zeros((1, 2)))
    stderr = terms.standard_error(np.zeros(3))
    assert np.isclose(stderr[0], np.sqrt(0.25 * 100 / 99 / 100))
