"""The foliage closed forms (baker/light/crowns.py) against their definitions, and the fits."""

import numpy as np
import pytest

from baker.light.crowns import (
    Shell,
    cap_factor,
    cap_of,
    cap_volume,
    crown_visibility,
    enclosing_shell,
    fit_density,
    fit_shells,
    grass_visibility,
    large_occluder_visibility,
    nearest_shell,
    shell_terms,
)


def _unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _rotation(seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q


def test_cap_volume_is_the_integral_of_its_discs():
    radius = 1.7
    for h in (0.0, 0.3, 1.7, 2.9, 3.4):
        z = np.linspace(radius - h, radius, 20001)
        discs = np.pi * (radius * radius - z * z)
        assert cap_volume(np.array([h]), radius)[0] == pytest.approx(np.trapezoid(discs, z), abs=1e-7)
    assert cap_volume(np.array([2 * radius]), radius)[0] == pytest.approx(4 / 3 * np.pi * radius ** 3)


def test_cap_height_and_offset_from_the_sphere_and_the_plane():
    rng = np.random.default_rng(1)
    radius = 2.0
    offset = rng.uniform(-1.5, 1.5, (500, 3))
    normal = _unit(rng.normal(size=(500, 3)))
    h, d = cap_of(offset, normal, radius)
    # h: how far the sphere reaches past the plane along n (its farthest point is c + R n)
    reach = np.einsum("ij,ij->i", radius * normal - offset, normal)
    assert np.allclose(h, np.clip(reach, 0, 2 * radius))
    # d: from the point to the foot of the centre on the plane
    foot = -offset + np.einsum("ij,ij->i", offset, normal)[:, None] * normal  # relative to x
    assert np.allclose(d, np.linalg.norm(foot, axis=1))


@pytest.mark.parametrize("radii", [(1.0, 1.0, 1.0), (2.0, 0.7, 1.2)])
def test_shell_cap_volume_counts_the_shells_points_beyond_the_plane(radii):
    """Monte Carlo: the share of the shell's volume on the normal's side of the plane through x,
    for a sphere and a rotated ellipsoid, is V_cap / V_shell."""
    rng = np.random.default_rng(2)
    shell = Shell(np.array([0.3, -1.0, 2.0]), _rotation(3).T, np.array(radii))
    q = _unit(rng.normal(size=(200_000, 3))) * rng.uniform(0, 1, (200_000, 1)) ** (1 / 3)
    inside = shell.center + (q * shell.radii) @ shell.axes
    x = shell.center + (np.array([[0.2, -0.3, 0.1], [0.5, 0.5, 0.5], [-0.9, 0.0, 0.0]])
                        * shell.radii) @ shell.axes
    n = _unit(np.array([[0.0, 1.0, 0.0], [1.0, 1.0, -1.0], [1.0, 0.2, 0.0]]))
    _, v_cap = shell_terms(shell, x, n)
    for i in range(3):
        share = np.mean((inside - x[i]) @ n[i] > 0)
        sigma = np.sqrt(share * (1 - share) / len(inside))
        assert v_cap[i] / shell.volume == pytest.approx(share, abs=4 * sigma + 1e-12)


def test_sphere_shell_terms_are_the_world_formulas():
    rng = np.random.default_rng(4)
    shell = Shell(np.array([1.0, 2.0, 3.0]), np.eye(3), np.full(3, 1.5))
    x = shell.center + rng.uniform(-1, 1, (100, 3))
    n = _unit(rng.normal(size=(100, 3)))
    f, v_cap = shell_terms(shell, x, n)
    h, d = cap_of(x - shell.center, n, 1.5)
    assert np.allclose(v_cap, np.pi * h ** 2 * (3 * 1.5 - h) / 3)
    assert np.allclose(f, h ** 2 / (h ** 2 + d ** 2))


def test_visibility_forms():
    f, v = np.array([0.0, 0.5, 1.0]), np.array([2.0, 2.0, 2.0])
    assert np.allclose(crown_visibility(0.7, f, v), np.exp(-0.7 * f * v))
    assert cap_factor(np.array([0.0]), np.array([0.0]))[0] == 0.0
    assert cap_factor(np.array([1.0]), np.array([0.0]))[0] == 1.0
    # A_SA = π (r/d)² is the far sphere's solid angle 2π(1 − cos α), sin α = r/d
    r, d = 1.0, np.array([10.0, 100.0, 1000.0])
    exact = 2 * np.pi * (1 - np.sqrt(1 - (r / d) ** 2))
    assert np.allclose((1 - large_occluder_visibility(r, d)) * 2 * np.pi / exact, 1, rtol=1e-2 * (10 / d))
    assert large_occluder_visibility(1.0, np.array([0.5]))[0] == 0.0
    assert np.allclose(grass_visibility(np.array([0.0, 0.25, 0.5, 0.5]), 0.5,
                                        np.array([1.0, 1.0, 1.0, 0.0])), [0.0, 0.5, 1.0, 0.5])


def test_enclosing_shell_recovers_an_ellipsoid():
    rng = np.random.default_rng(5)
    axes, radii, center = _rotation(6).T, np.array([3.0, 1.0, 0.5]), np.array([4.0, 5.0, 6.0])
    q = _unit(rng.normal(size=(50_000, 3))) * rng.uniform(0, 1, (50_000, 1)) ** (1 / 3)
    points = center + (q * radii) @ axes
    shell = enclosing_shell(points)
    assert np.linalg.norm(shell.to_unit(points), axis=1).max() <= 1 + 1e-9
    assert np.allclose(np.sort(shell.radii), np.sort(radii), rtol=0.05)
    assert shell.volume < 1.1 * 4 / 3 * np.pi * radii.prod()


def test_one_ball_is_one_shell_two_balls_are_two():
    rng = np.random.default_rng(7)
    ball = _unit(rng.normal(size=(20_000, 3))) * rng.uniform(0, 1, (20_000, 1)) ** (1 / 3)
    assert len(fit_shells(ball)) == 1
    left, right = ball[:10_000] + [-4.0, 0, 0], ball[10_000:] * 1.5 + [5.0, 1.0, 0]
    shells = fit_shells(np.concatenate([left, right]))
    assert len(shells) == 2
    owner = nearest_shell(shells, np.concatenate([left, right]))
    assert len(set(owner[:10_000])) == 1 and len(set(owner[10_000:])) == 1
    assert owner[0] != owner[-1]
    for j, shell in enumerate(shells):  # each point enclosed by its nearest shell
        mine = np.concatenate([left, right])[owner == j]
        assert np.linalg.norm(shell.to_unit(mine), axis=1).max() <= 1 + 1e-9


def test_fit_density_recovers_the_density_and_reports_the_residual():
    rng = np.random.default_rng(8)
    g = rng.uniform(0, 3, 2000)
    exact = fit_density(g, np.exp(-0.8 * g))
    assert exact.density == pytest.approx(0.8, rel=1e-6) and exact.residual < 1e-6
    noisy = fit_density(g, np.exp(-0.8 * g) + rng.normal(0, 0.05, len(g)))
    assert noisy.density == pytest.approx(0.8, rel=0.05)
    assert noisy.residual == pytest.approx(0.05, rel=0.1)
