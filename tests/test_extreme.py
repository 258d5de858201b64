"""Extreme and stiff scenes bake to finite, sensible values (issue 7, docs/design.md §7).

The stiff case of equation (3), the model's limits on a closed room, the same room at every scale
and far from the origin, meshes as exporters leave them, transforms, instancing and page size.
"""

from __future__ import annotations

import os
from dataclasses import replace

import numpy as np
import pytest

import baker
from assets.extreme_scenes import (closed_room, defect_panels, instanced_boxes, l_strip,
                                   non_manifold_fin, panel_over_floor, single_triangle)
from assets.light_scenes import lit_floor
from baker.light.ambient import MAX_BOUNCES, bounce_factor
from baker.image.compose import effective_r_ave
from baker.geometry.world import build_world
from baker.pipeline.input_warnings import input_warnings
from baker.atlas.rasterise import INSET
from baker.gltf.scene import Skipped
from baker.cli.bake import print_summary
from tests.bakehelp import computed, loaded, saved


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


@pytest.mark.parametrize("kind", ["point", "spot", "directional"])
def test_a_light_too_faint_for_its_power_squared_bakes(tmp_path, kind):
    """A punctual light of intensity 1e-300 or the least float64: the relative variance of the
    sources' power divided by the power's luminance squared, which underflows to 0 (a
    ZeroDivisionError in every bake of such a file; the long fuzzer's find). Now the bake
    ends with finite pages, its light in proportion to the intensity, and a finite estimate."""
    peaks = []
    for intensity in (1.0, 1e-300, 5e-324):
        done = computed(lit_floor(kind, intensity=intensity), tmp_path, texel_density=4.0,
                        rays=4)
        assert np.isfinite(done.lightmaps.light).all() and np.isfinite(done.rmse_estimate())
        peaks.append(done.lightmaps.light.max())
    assert peaks[0] > 0 and peaks[1] == pytest.approx(peaks[0] * 1e-300, rel=1e-6)
    assert 0 <= peaks[2] <= 1e-300


def test_one_triangle_scene(tmp_path):
    """A single open triangle: every ray escapes, W = what escaping rays count on every texel."""
    done = computed(single_triangle(), tmp_path, texel_density=16.0, rays=8)
    assert len(done.texels) > 10
    np.testing.assert_allclose(_w(done), effective_r_ave(done.ambient, done.settings.rho).mean(), rtol=1e-9)


# ------------------------------------------------------------------------------------------------
# the same scene however it is scaled, placed or transformed

def _same_points(points: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(n,) index into ``reference`` (n, 3) of the nearest point to each of ``points`` (n, 3)
    (brute force in blocks of rows: these scenes have a few thousand texels)."""
    match = np.empty(len(points), np.int64)
    for start in range(0, len(points), 512):
        block = points[start:start + 512]
        match[start:start + 512] = np.argmin(
            ((block[:, None, :] - reference[None, :, :]) ** 2).sum(axis=2), axis=1)
    return match


def _differing(done, reference, scale: float = 1.0, offset: float = 0.0) -> int:
    """Texels whose W luminance differs from the ``reference`` texel at the same place (world
    position − ``offset``, / ``scale``) by more than 5 combined standard errors (each bake's own,
    from its rays' sample variance). Every texel must have its counterpart."""
    where = (done.texels.position - offset) / scale
    assert len(done.texels) == len(reference.texels)
    match = _same_points(where, reference.texels.position)
    assert len(np.unique(match)) == len(match)
    # The same points, up to rounding; a point clamped into a corner of its triangle is drawn
    # inside by the corner's two edges (rasterise.INSET), so another triangulation of the
    # same surface (a mirrored mesh's diagonal) places it up to 2 × 1.7 insets away
    apart = np.linalg.norm(where - reference.texels.position[match], axis=1)
    assert (apart < 1e-6 + 4 * INSET * reference.texels.size(match)).all()
    w, w_ref = _w(done), _w(reference)[match]  # grey scenes: the mean of RGB is the luminance
    se, se_ref = (d.terms.standard_error(effective_r_ave(d.ambient, d.settings.rho))
                  for d in (done, reference))
    # 1e-6: float32 rounding (of areas in R_ave, of hit distances) where every ray escaped or
    # hit alike, so that the standard error is 0
    return int(np.count_nonzero(np.abs(w - w_ref) > 5 * np.sqrt(se ** 2 + se_ref[match] ** 2) + 1e-6))


@pytest.fixture(scope="module")
def unit_room(tmp_path_factory):
    return computed(closed_room(), tmp_path_factory.mktemp("room"), texel_density=4.0, rays=16,
                    d_max=0.5)


@pytest.mark.parametrize("scale,offset", [(1e-4, 0.0), (1e5, 0.0), (1.0, 1e6)])
def test_same_room_at_any_scale_or_far_from_the_origin_bakes_the_same(tmp_path, unit_room, scale,
                                                                      offset):
    """The 2-unit room at 1e-4 and 1e5 units, or 1e6 units from the origin on every axis, with
    d_max and texel density scaled with it: same texels, and no texel's W differs from the unit
    room's by more than 5 standard errors (float32 inside Embree shows no acne, leak or speckle;
    measured: 0 of 486, largest difference 1e-4 at 1e5 units)."""
    done = computed(closed_room(scale=scale, offset=(offset,) * 3), tmp_path,
                    texel_density=4.0 / scale, rays=16, d_max=0.5 * scale)
    assert np.isfinite(done.lightmaps.light).all()
    assert _differing(done, unit_room, scale, offset) == 0


@pytest.fixture(scope="module")
def plain_panel(tmp_path_factory):
    return computed(panel_over_floor(), tmp_path_factory.mktemp("panel"), texel_density=16.0,
                    rays=16, d_max=1.0)


@pytest.mark.parametrize("variant", [{"scale": (2.0, 0.5, 1.0)}, {"mirrored": True},
                                     {"scale": (-1.0, 1.0, -3.0)}, {"depth": 1000}],
                         ids=["non_uniform", "negative_x", "negative_xz_non_uniform", "nested_1000"])
def test_node_scale_and_deep_nesting_leave_the_lightmap_unchanged(tmp_path, plain_panel, variant):
    """A panel over a floor whose node scales (non-uniformly, negatively: winding flipped) a mesh
    divided by the same scale, or hangs under 1000 nested nodes that compose to the identity:
    the world panel is the same, and so is every texel of floor and panel (within 5 standard
    errors; the panel's own texels face down, so a winding error would show on both)."""
    done = computed(panel_over_floor(**variant), tmp_path, texel_density=16.0, rays=16, d_max=1.0)
    np.testing.assert_allclose(done.world.positions, plain_panel.world.positions, atol=1e-9)
    np.testing.assert_allclose(done.texels.geometric_normal(), plain_panel.texels.geometric_normal(),
                               atol=1e-9)
    assert _differing(done, plain_panel) == 0


# ------------------------------------------------------------------------------------------------
# meshes the way exporters leave them


def test_mesh_defects_bake_to_open_sky_and_are_counted(tmp_path):
    """Coplanar panels facing up — duplicate vertices, zero-area triangles, inverted, zero and
    missing normals, coincident (z-fighting) copies — see nothing but sky: every ray of every
    texel escapes (W = R_ave exactly), every panel has its texels, both coincident copies too,
    and the degenerate triangles own none. The report counts what was dropped or changed."""
    done = computed(defect_panels(), tmp_path, texel_density=16.0, rays=16)
    nodes = defect_panels().info["nodes"]
    per_node = np.bincount([done.scene.instances[i].node for i in done.texels.instance()],
                           minlength=len(nodes))
    assert (per_node[list(nodes.values())] >= 81).all()  # a 0.5 m panel at 16/m: 9 × 9 texels
    assert per_node[nodes["coincident"]] == 2 * per_node[nodes["clean"]]
    assert (done.terms.escaped == 1.0).all()
    np.testing.assert_allclose(_w(done), effective_r_ave(done.ambient, done.settings.rho).mean(), rtol=1e-12)
    assert not done.world.degenerate[done.texels.triangle].any()
    assert input_warnings(done.scene, done.world) == {
        "degenerate triangles (no area): given no texels": 3,
        "primitives without normals: flat normals computed": 1,
        "vertices with a zero-length (or NaN) normal: their triangles' own normal used": 4}


def test_load_time_warnings_and_cli_summary_list_every_skipped_entry(tmp_path, capsys):
    """Anything the loader left out or changed (``Scene.skipped``, e.g. a material baked as
    diffuse) is counted under the report's warnings, and the command line prints them."""
    scene = loaded(defect_panels(), tmp_path)
    note = Skipped(where="materials[0]", reason="material not understood: baked as diffuse")
    counted = input_warnings(replace(scene, skipped=(note, replace(note, where="materials[1]"))),
                             build_world(scene))
    assert counted["material not understood: baked as diffuse"] == 2
    result = baker.bake(saved(defect_panels(), tmp_path), tmp_path / "out.glb",
                        baker.Settings(rays=2, texel_density=8.0))
    assert result.report["warnings"]["degenerate triangles (no area): given no texels"] == 3
    print_summary(result)
    assert "warning: 3 × degenerate triangles (no area): given no texels" in capsys.readouterr().out


def test_non_manifold_edge_shades_both_sides(tmp_path):
    """Three faces on one edge (two flat panels and a fin standing on their shared edge): the
    flat panels are darker next to the fin than far from it, where they see open sky."""
    done = computed(non_manifold_fin(), tmp_path, texel_density=32.0, rays=32)
    w, x = _w(done), done.texels.position
    flat = np.abs(x[:, 1]) < 1e-9
    for side in (1, -1):
        near = flat & (side * x[:, 0] > 0) & (side * x[:, 0] < 0.1)
        far = flat & (side * x[:, 0] > 0.4)
        assert near.sum() > 10 and far.sum() > 10
        assert w[near].mean() < w[far].mean() - 0.02  # measured: 0.466 against 0.5
        assert w[far].max() <= effective_r_ave(done.ambient, done.settings.rho).mean() + 1e-12
    assert np.isfinite(w).all() and (w >= 0).all()


def test_a_triangle_smaller_than_a_texel_bakes_a_few_texels(tmp_path):
    """A 1 cm triangle at 10 texels per metre (a tenth of a texel): its chart is kept inside
    one texel, the atlas is that one texel, the triangle owns it and it sees open sky
    (W = R_ave)."""
    done = computed(single_triangle(0.01), tmp_path, texel_density=10.0, rays=8)
    assert (done.atlas.width, done.atlas.height, done.atlas.page_count) == (1, 1, 1)
    assert len(done.texels) == 1
    np.testing.assert_allclose(_w(done), effective_r_ave(done.ambient, done.settings.rho).mean(), rtol=1e-12)


@pytest.mark.parametrize("count", [10_000] if os.environ.get("BAKER_LONG") else [2_000])
def test_a_mesh_instanced_many_times(tmp_path, count):
    """One box mesh on ``count`` nodes (2,000; 10,000 with ``BAKER_LONG=1``: 240k texels, 21 s
    on 2 cores), each alone
    within d_max: every instance gets its own texels, the same number, and the same W up to
    noise (the instances' means all within 5 standard errors of the mean over all)."""
    done = computed(instanced_boxes(count), tmp_path, texel_density=5.0, rays=4, d_max=0.5)
    per_instance = np.bincount(done.texels.instance(), minlength=count)
    assert per_instance.min() == per_instance.max() > 0
    w = _w(done)
    means = np.bincount(done.texels.instance(), w) / per_instance
    se = np.sqrt(np.bincount(done.texels.instance(), done.terms.standard_error(
        effective_r_ave(done.ambient, done.settings.rho)) ** 2)) / per_instance
    assert (np.abs(means - means.mean()) <= 5 * se + 1e-12).all()


@pytest.mark.parametrize("side", [4096, pytest.param(8192, marks=pytest.mark.long)])
def test_a_sparse_page_of_8192_squared(tmp_path, side):
    """An L-shaped strip two texels wide whose chart only fits a ``side``² page (8192: 48.6k
    texels on an 8101² page: 7.9 s and 3.9 GB peak on 2 cores, most of it the float pages;
    4096 in the default suite): every texel baked, open sky (W = R_ave)."""
    length = (side - 92) / 8.0
    done = computed(l_strip(length, 0.25), tmp_path, texel_density=8.0, rays=4, d_max=1.0,
                    page_size=side)
    assert done.atlas.page_count == 1 and min(done.atlas.width, done.atlas.height) > 0.98 * side - 92
    np.testing.assert_allclose(_w(done), effective_r_ave(done.ambient, done.settings.rho).mean(), rtol=1e-12)
    assert np.isfinite(done.lightmaps.light).all()


def test_black_room_has_no_obscurance(tmp_path):
    """Albedo exactly 0 everywhere: R_ave = 0 and every hit reflects nothing, so W = 0 exactly
    on every texel (no 0/0, no NaN from the R_ave series)."""
    done = computed(closed_room(albedo=0.0), tmp_path, texel_density=4.0, rays=8)
    assert (done.ambient.r_ave == 0).all() and np.isfinite(done.lightmaps.light).all()
    assert (_w(done) == 0).all()
