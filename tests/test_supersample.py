"""Supersampled obscurance (issue 8): with ``supersample`` = N > 1 a texel's obscurance rays start
from its N sub-positions (ray j from sub-position j mod N), so a sharp step in obscurance across
a texel is box-filtered like a shadow edge, deterministically."""

from dataclasses import replace

import numpy as np
import pytest

from assets.artifact_scenes import obscurance_edge
from baker.light.hemisphere import hemisphere_rays
from baker.light.integrate import integrate
from baker.atlas.supersample import sub_positions
from baker.rays.trace import Tracer, ray_lift
from tests.bakehelp import computed

# Obscurance only (no light): the floor under a slab 1 cm above it is dark, beside it open.
SETTINGS = dict(texel_density=10.0, rays=64, d_max=1.0)
_GRID = 8  # the reference box-filters each texel's square with 8 × 8 sample points


def _obscurance(done, terms=None) -> np.ndarray:
    """(N,) W of every texel (white scene: one channel)."""
    return (terms or done.terms).obscurance(done.ambient.r_ave)[:, 0]


def _box_filtered_reference(done) -> np.ndarray:
    """(N,) W averaged over each texel's square: W at 8 × 8 points of the square (on the
    triangle's plane, ``Texels.axes``), 64 rays each with a seed of its own."""
    texels, context = done.texels, done.context()
    offsets = (np.arange(_GRID) + 0.5) / _GRID - 0.5
    total = np.zeros(len(texels))
    for i, (a, b) in enumerate((a, b) for a in offsets for b in offsets):
        moved = replace(texels, position=texels.position + a * texels.axes()[:, 0]
                        + b * texels.axes()[:, 1])
        total += _obscurance(done, integrate(
            context.with_settings(replace(done.settings, seed=1000 + i)), moved))
    return total / _GRID ** 2


@pytest.fixture(scope="module")
def edge_scene():
    return obscurance_edge()


def test_supersampling_antialiases_a_sharp_obscurance_step(edge_scene, tmp_path):
    """Texels that the slab's edge crosses: one sample point puts each wholly under or beside
    the slab; 16 sub-positions give them the mean over their square. Error against the
    box-filtered reference, measured (seeds 0–3): RMSE 0.065 → 0.019–0.027 on the crossed
    texels; elsewhere unchanged at the noise level (0.003)."""
    scene = edge_scene
    floor_only = {scene.info["floor"]}
    one = computed(scene, tmp_path, only_nodes=floor_only, supersample=1, **SETTINGS)
    many = computed(scene, tmp_path, only_nodes=floor_only, supersample=16, **SETTINGS)
    np.testing.assert_array_equal(one.texels.key, many.texels.key)  # same texels
    t = one.texels
    reference = _box_filtered_reference(one)
    corners = t.position[:, None] + np.einsum(
        "sj,kjc->ksc", np.array([[-0.5, -0.5], [0.5, -0.5], [-0.5, 0.5], [0.5, 0.5]]), t.axes())
    under = scene.info["under"](corners.reshape(-1, 3)).reshape(-1, 4)
    inner = (np.abs(t.position[:, [0, 2]]) < 0.85).all(axis=1)  # whole squares on the floor
    crossed = inner & under.any(axis=1) & ~under.all(axis=1)
    others = inner & ~crossed
    assert crossed.sum() > 15 and others.sum() > 200
    error = {n: _obscurance(done) - reference for n, done in ((1, one), (16, many))}
    rmse = {n: (np.sqrt(np.mean(e[crossed] ** 2)), np.sqrt(np.mean(e[others] ** 2)))
            for n, e in error.items()}
    assert rmse[1][0] > 10 * rmse[1][1]  # one point per texel: the step is aliased
    assert rmse[16][0] < 0.5 * rmse[1][0], rmse
    assert rmse[16][1] < 1.5 * rmse[1][1], rmse  # no noisier away from the step


def test_supersampled_obscurance_does_not_depend_on_threads_or_chunks(edge_scene, tmp_path):
    """Same bytes for any chunking and thread count, and for adaptive rounds (which start at
    sample ``first``: ray j still from sub-position j mod N)."""
    one = computed(edge_scene, tmp_path, supersample=8, threads=1, chunk_texels=4096, **SETTINGS)
    other = computed(edge_scene, tmp_path, supersample=8, threads=2, chunk_texels=37, **SETTINGS)
    np.testing.assert_array_equal(one.terms.w_hit, other.terms.w_hit)
    np.testing.assert_array_equal(one.terms.escaped, other.terms.escaped)
    np.testing.assert_array_equal(one.lightmaps.visibility, other.lightmaps.visibility)
    t, tracer, n = one.texels, Tracer(one.world), 8
    rows = np.arange(0, len(t), 7)
    sub = sub_positions(tracer, t, rows, n, one.settings.seed)
    whole, _ = hemisphere_rays(t, rows, 24, 0, tracer.center, "sobol", 0, sub)
    later, _ = hemisphere_rays(t, rows, 12, 0, tracer.center, "sobol", 12, sub)
    # Samples 12 … 23 of a round starting at 12 leave from the same points as in one round.
    np.testing.assert_array_equal(whole.reshape(len(rows), 24, 3)[:, 12:],
                                  later.reshape(len(rows), 12, 3))
    # Ray j starts at sub-position j mod 8 (lifted off the floor by the texel's offset).
    starts = whole.reshape(len(rows), 24, 3).astype(np.float64) + tracer.center
    lift = ray_lift(t.position[rows], t.size(rows), tracer.center)[:, None]
    expected = sub[:, np.arange(24) % n] + (lift * t.geometric_normal(rows))[:, None]
    np.testing.assert_allclose(starts, expected, atol=1e-5)
    assert len(np.unique(starts[0].round(6), axis=0)) == n
