"""Directional lightmaps (``--directional``, light/directional.py) against closed forms.

- a point light and a sun give every texel g = l / cosθ_l: the decoded irradiance at any
  normal n is the closed form I·(n·l)/r² (E·n·l for the sun); a uniform sky gives g = n₀/2,
  its closed form (1 + n·n₀)/2;
- a scene without a normal map gets no directional page, and says so in the plan;
- the output carries BAKER_lightmap_directional on the normal-mapped material, validator-clean,
  its pages at most 2.5× the plain bake's bytes;
- a rebake after a move and a relight give the full bake's bytes; adaptive rounds and the
  path-traced GI keep directions too, with error estimates.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pygltflib
import pytest

import baker
from assets.gltf_builder import box
from assets.light_scenes import normal_mapped_floor, open_floor, window_room
from baker.atlas.rasterise import flat_pages
from baker.errors import SettingsError
from baker.geometry.surface import LUMINANCE
from baker.light.directional import decode_vectors, fit, shading_factor, uniform_aim
from tests.bakehelp import computed, saved
from tests.directional_measure import (
    page_pngs,
    point_light,
    reliefs,
    top_view,
    window_light,
)

import gltf_validator
from test_browser import browser  # noqa: F401 (the headless Chromium fixture)

FAST = dict(texel_density=12.0, rays=16, page_size=128, directional=True)


def _fitted(done) -> np.ndarray:
    """(N, 3) each texel's own g (``fit``) from its direct light alone (I_A 0)."""
    return fit(done.direct.irradiance() @ LUMINANCE, done.direct.aim(), done.texels.normal)


def _g(done) -> np.ndarray:
    """(N, 3) each texel's g as its directional page holds it (pooled with its neighbours',
    before 8-bit encoding)."""
    return decode_vectors(flat_pages(done.lightmaps.direction)[done.texels.pixel_index(
        slice(None))])


def test_a_point_light_and_a_sun_give_their_closed_forms(tmp_path):
    """One light, nothing else (I_A 0): U = E·l, so g = l / cosθ_l at every texel, and the
    decoded irradiance at a tilted normal is the closed form to rounding."""
    light = np.array([1.2, 1.0, 0.3])
    done = computed(normal_mapped_floor(), tmp_path / "point", ambient=0.0, **FAST)
    position = done.texels.position
    towards = light - position
    r = np.linalg.norm(towards, axis=1)
    l = towards / r[:, None]
    np.testing.assert_allclose(_fitted(done), l / l[:, 1:2], atol=1e-9)
    tilted = np.array([math.sin(0.4), math.cos(0.4), 0.0])
    normals = np.broadcast_to(tilted, position.shape)
    decoded = done.direct.irradiance()[:, 0] * shading_factor(normals, done.texels.normal,
                                                              _fitted(done))
    np.testing.assert_allclose(decoded, 4.0 * np.maximum(l @ tilted, 0) / r ** 2, rtol=1e-9)
    # the page pools each texel's 3×3 neighbours: a slowly varying g, within 0.02 inside
    inside = np.all(np.abs(position[:, [0, 2]]) < 0.9, axis=1)
    np.testing.assert_allclose(_g(done)[inside], (l / l[:, 1:2])[inside], atol=0.02)
    sun = np.array([-0.6, -0.8, 0.0])
    done = computed(normal_mapped_floor("directional", direction=sun), tmp_path / "sun",
                    ambient=0.0, **FAST)
    np.testing.assert_allclose(_g(done), np.broadcast_to(-sun / 0.8, (len(done.texels), 3)),
                               atol=1e-9)


def test_a_uniform_sky_gives_half_the_normal():
    """Light uniform over the hemisphere: U = (2/3)·E·n₀, and the fit gives g = n₀/2,
    E(n) = E·(1 + n·n₀)/2, the closed form for a tilted plane under a uniform sky; one direction
    (U = E·l) gives l/cosθ; light along n₀ alone, n₀."""
    n0 = np.array([[0.0, 1.0, 0.0]])
    np.testing.assert_allclose(fit(np.array([2.0]), uniform_aim(np.array([2.0]), n0), n0),
                               [[0.0, 0.5, 0.0]], atol=1e-12)
    l = np.array([[0.6, 0.8, 0.0]])
    np.testing.assert_allclose(fit(np.array([3.0]), 3.0 * l, n0), l / 0.8, atol=1e-12)
    np.testing.assert_allclose(fit(np.array([3.0]), 3.0 * n0, n0), n0, atol=1e-12)


def test_a_floor_under_the_sky_is_uniform_within_noise(tmp_path):
    """The sky's cosine rays estimate U = (2/3)·E·n₀ on an open floor: g's mean is n₀/2."""
    b = open_floor()
    done = computed(b, tmp_path, sky=(1.0, 1.0, 1.0), ambient=0.0, sky_rays=64,
                    **{**FAST, "directional": True})
    assert not done.settings.directional_pages  # no normal map: the plan leaves them out
    mapped = computed(normal_mapped_floor(intensity=0.0), tmp_path / "mapped",
                      sky=(1.0, 1.0, 1.0), ambient=0.0, sky_rays=64, **FAST)
    g = _g(mapped)
    np.testing.assert_allclose(g.mean(axis=0), [0.0, 0.5, 0.0], atol=0.02)
    assert mapped.tally.aim_rmse() > 0  # the sky's rays are noisy: its error estimate says so


def test_no_normal_map_no_directional_pages(tmp_path):
    scene = saved(open_floor(), tmp_path)
    out = tmp_path / "out.glb"
    result = baker.bake(scene, out, baker.Settings(directional=True, page_size=64, rays=4),
                        state=False)
    assert result.plan.stages["directional"] == ("left out: directional pages, the scene has "
                                                 "no normal map")
    assert result.report["directional"] == {"pages": False, "extension": None,
                                            "reason": result.plan.stages["directional"]}
    document = pygltflib.GLTF2.load(str(out))
    assert "BAKER_lightmap_directional" not in (document.extensionsUsed or [])
    with pytest.raises(SettingsError, match="leave out --carrier"):
        baker.Settings(directional=True, carrier="emissive").check()
    assert baker.Settings(directional=True).chosen_carrier() == "moz"  # moz unless told
    assert baker.Settings().chosen_carrier() == "emissive"


def test_the_output_carries_directional_pages_validator_clean(tmp_path):
    """The normal-mapped material gets BAKER_lightmap_directional beside its MOZ_lightmap, on
    the same UV set; the file passes the Khronos validator with no error or warning; the
    directional pages take at most 2.5× the plain bake's PNG bytes (issue 42)."""
    scene = saved(normal_mapped_floor(), tmp_path)
    settings = dict(texel_density=32.0, rays=16, sky=(0.3, 0.35, 0.4))
    plain, directional = tmp_path / "plain.glb", tmp_path / "directional.glb"
    baker.bake(scene, plain, baker.Settings(carrier="moz", **settings), state=False)
    result = baker.bake(scene, directional, baker.Settings(directional=True, **settings),
                        state=False)
    report = gltf_validator.validate(directional)
    for severity in (gltf_validator.ERROR, gltf_validator.WARNING):
        assert not gltf_validator.issue_codes(report, severity), \
            gltf_validator.describe(report, severity)
    document = pygltflib.GLTF2.load(str(directional))
    carried = [m.extensions for m in document.materials if "MOZ_lightmap" in m.extensions]
    assert carried and carried[0]["BAKER_lightmap_directional"]["texCoord"] == \
        carried[0]["MOZ_lightmap"]["texCoord"]
    assert "BAKER_lightmap_directional" in document.extensionsUsed
    assert "BAKER_lightmap_directional" not in (document.extensionsRequired or [])
    assert document.asset.extras["baker"]["directional_extension"] == "BAKER_lightmap_directional"
    info = result.report["directional"]
    textures = info["png_bytes"] + info["lightmap_png_bytes"]
    plain_textures = sum(len(b) for b in page_pngs(plain))
    assert textures == sum(len(b) for b in page_pngs(directional))
    assert textures <= 2.5 * plain_textures, (textures, plain_textures)
    assert info["aim_rmse_estimate"] > 0


def _with_box(at: tuple[float, float, float]):
    b = normal_mapped_floor()
    grey = b.material("grey", (0.6, 0.6, 0.6))
    b.node("box", b.shape_mesh("box", box((0.3, 0.3, 0.3)), material=grey), translation=at)
    return b


def test_a_rebake_gives_the_full_bakes_bytes(tmp_path):
    """A box moved on the normal-mapped floor: the rebake's output is the full bake's bytes,
    directional pages included."""
    settings = baker.Settings(directional=True, texel_density=12.0, rays=16, page_size=128)
    first = saved(_with_box((0.2, 0.15, -0.3)), tmp_path, "a.glb")
    moved = saved(_with_box((-0.3, 0.15, 0.2)), tmp_path, "b.glb")
    out, full = tmp_path / "out.glb", tmp_path / "full.glb"
    baker.bake(first, out, settings)
    again = baker.bake(moved, out, settings, incremental="always")
    assert again.rebake["incremental"] and again.rebake["dirty_texels"] > 0
    baker.bake(moved, full, settings)
    assert out.read_bytes() == full.read_bytes()


def test_relight_recomposes_the_directions(tmp_path):
    """Two lights; the second's intensity changed: ``relight`` recomposes (no ray) the very
    bytes a full bake of the new intensities writes, directional pages included."""
    def scene(second: float):
        b = normal_mapped_floor(intensity=3.0)
        index = b.light("point", intensity=second)
        b.node("second", translation=(-1.0, 0.8, -0.5),
               extensions={"KHR_lights_punctual": {"light": index}})
        return b

    settings = baker.Settings(directional=True, texel_density=12.0, rays=4, page_size=128)
    out, full = tmp_path / "out.glb", tmp_path / "full.glb"
    baker.bake(saved(scene(1.0), tmp_path, "a.glb"), out, settings)
    relit = baker.bake(saved(scene(5.0), tmp_path, "b.glb"), out, settings, relight=True)
    assert relit.rebake["incremental"] and relit.rebake["rays"] == 0
    baker.bake(tmp_path / "b.glb", full, settings, state=False)
    assert out.read_bytes() == full.read_bytes()


def test_adaptive_rounds_and_gi_keep_directions(tmp_path):
    """--target-error: the texels' rounds sum the directions as they sum the light, and a
    second bake gives the same bytes; --method gi: the paths' first directions give the
    indirect light's U, and a wall beside the floor tilts g towards it."""
    b = normal_mapped_floor(intensity=0.0)
    white = b.material("wall", (0.9, 0.9, 0.9), emissive=(1.0, 1.0, 1.0))
    b.node("wall", b.shape_mesh("wall", box((0.05, 1.0, 2.0)), material=white),
           translation=(1.1, 0.5, 0.0))
    adaptive = computed(b, tmp_path / "adaptive", target_error=0.05, max_rays=64,
                        **{**FAST, "rays": 8})
    assert adaptive.terms.counts.max() > adaptive.terms.counts.min()
    g = _g(adaptive)
    assert np.mean(g[:, 0]) > 0.05  # the glowing wall at +x pulls the direction its way
    gi = computed(b, tmp_path / "gi", method="gi", **{**FAST, "rays": 16})
    assert np.mean(_g(gi)[:, 0]) > 0.05
    assert gi.tally.aim_rmse() > 0


def test_a_point_light_on_a_bumped_floor_in_the_browser(browser, tmp_path):
    """Issue 42's measure under a point light: ``baker view`` (three.js and our plugin, in
    headless Chromium) shows the bumps as the closed form I·(n·l)/r² has them, per pixel
    (relief correlation ≥ 0.95; measured 0.9997), where the plain lightmap's face is flat
    (its relief does not vary: 0); ``baker preview`` computes the same pixels (≥ 0.999)."""
    found = reliefs(browser, normal_mapped_floor(), top_view(2.6), tmp_path,
                     lambda p, n: point_light(p, n, (1.2, 1.0, 0.3), 4.0))
    assert found["browser, plain"] == 0.0
    assert found["browser"] >= 0.95 and found["preview"] >= 0.95
    assert found["browser, against E(n0)"] >= 0.95
    assert found["browser ~ preview"] >= 0.999
    assert found["directional bytes"] <= 2.5 * found["plain bytes"], found


@pytest.mark.long
def test_a_window_on_a_bumped_floor_in_the_browser(browser, tmp_path):
    """The same under a window: a closed room lit only by a uniform sky through an opening in
    one wall, whose light at a normal n is L·n·Φ (Lambert's polygon). The relief over the plain
    bake's picture, where the lightmap's noise cancels, ≥ 0.95 (measured 0.999); over the
    closed form at n₀ the sky's 256 rays' noise stays in (0.91)."""
    room = window_room()
    found = reliefs(browser, room, top_view(5.5, fov=40.0), tmp_path,
                     lambda p, n: window_light(p, n, room.info["window"], 1.0),
                     sky=(1.0, 1.0, 1.0), sky_rays=256)
    assert found["browser, plain"] == 0.0
    assert found["browser"] >= 0.95 and found["preview"] >= 0.95
    assert found["browser ~ preview"] >= 0.999


def test_the_study_measures_the_directions(tmp_path):
    """``baker study --directional``: the obscurance's first moment U of each run against the
    reference's, falling with the rays, its halves' estimate tracking it."""
    from baker.study import run_study

    b = _with_box((0.0, 0.15, 0.0))
    done = computed(b, tmp_path, texel_density=8.0, rays=1, page_size=64, directional=True)
    study = run_study(done, (16, 64, 256), ("sobol",), reference_rays=2048)
    rows = {r.rays: r for r in study.directional}
    assert set(rows) == {16, 64, 256} and rows[256].rmse < rows[16].rmse / 3
    for row in rows.values():
        assert 0.5 < row.estimated_rmse / row.rmse < 2.0, row
    assert "U sobol" in study.table()
