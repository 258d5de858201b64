"""The default environment fits the scene: a lone prop is not tinted by its own colour, a prop
lit only by its decals is not black, a closed level keeps the model's R_ave (environment.py)."""

from __future__ import annotations

import numpy as np
import pytest

from assets import make_scenes
from assets.gltf_builder import GltfBuilder, box
from baker.errors import SettingsError
from baker.settings import Settings
from tests.bakehelp import computed

FAST = dict(rays=16, texel_density=10)


def _red_box() -> GltfBuilder:
    b = GltfBuilder()
    b.node("box", b.shape_mesh("box", box((1.0, 1.0, 1.0)), material=b.material(
        "red", (0.8, 0.05, 0.05))))
    return b


def _covered(done) -> np.ndarray:
    return done.lightmaps.light[done.lightmaps.covered]


def test_a_lone_convex_prop_bakes_to_one_not_to_its_own_colour(tmp_path):
    """Every ray from a convex box's faces escapes: W is what escaping rays count. By default
    (open, no light) that is white and I_A = 1, so the lightmap is exactly 1 in every channel;
    with the model's environment (--escape scene) it is R_ave, the box's own red."""
    done = computed(_red_box(), tmp_path / "auto", **FAST)
    assert done.ambient.source == "environment"
    np.testing.assert_allclose(_covered(done), 1.0, rtol=0, atol=1e-12)
    assert "open (100% of rays from its surfaces escape)" in done.plan.stages["escaping rays"]
    scene = computed(_red_box(), tmp_path / "scene", escape="scene", **FAST)
    np.testing.assert_allclose(_covered(scene), np.broadcast_to(scene.ambient.r_ave, (1, 3)) *
                               np.ones((len(_covered(scene)), 1)), rtol=0, atol=1e-12)
    np.testing.assert_allclose(scene.ambient.r_ave, [0.8, 0.05, 0.05], atol=1e-12)


def _decal_prop() -> GltfBuilder:
    """A grey box with a small glowing decal on top (0.46 % of the area), nothing else."""
    b = _red_box()
    decal = b.material("decal", (0.5, 0.5, 0.5), emissive=(1.0, 0.6, 0.2))
    b.node("decal", b.shape_mesh("decal", box((0.1, 0.02, 0.1)), material=decal),
           translation=(0.0, 0.51, 0.0))
    return b


def test_a_prop_lit_only_by_its_decals_is_not_black(tmp_path):
    """Emissive decals used to set I_A (here 6e-3 red, 2e-5 blue): almost every texel near black. By default
    I_A is 1 in a neutral environment, and the decal still lights the texels near it."""
    done = computed(_decal_prop(), tmp_path / "auto", **FAST)
    light = _covered(done) @ np.array([0.2126, 0.7152, 0.0722])
    assert done.ambient.source == "environment" and (light > 0.5).mean() > 0.95
    assert light.max() > 1.05  # the decal's direct light on top of the ambient 1 (1.08)
    old = computed(_decal_prop(), tmp_path / "scene", escape="scene", **FAST)
    assert old.ambient.source == "emission" and old.ambient.intensity.max() < 0.01
    assert ((_covered(old) @ np.array([0.2126, 0.7152, 0.0722])) < 0.05).mean() > 0.9
    assert "covering 0.46%" in old.plan.stages["ambient"] and "warning" in old.plan.stages["ambient"]


def test_a_closed_room_keeps_r_ave_and_says_why(tmp_path):
    done = computed(make_scenes.vase_room(), tmp_path, **FAST)
    assert done.ambient.escape is None
    assert "enclosed (0% of rays from its surfaces escape)" in done.plan.stages["escaping rays"]
    white = computed(make_scenes.vase_room(), tmp_path / "white", escape="white", **FAST)
    np.testing.assert_array_equal(white.ambient.escape, np.ones(3))


def test_escape_takes_one_of_three_values():
    with pytest.raises(SettingsError, match="escape must be one of auto, scene, white"):
        Settings(escape="sky").check()


def test_a_small_lamp_that_lights_the_room_is_no_decal(tmp_path):
    """The demo Cornell box's lamp covers 0.69 % of the surfaces but gives I_A of about 0.25:
    the plan warns of decals only where the ambient they give is faint."""
    done = computed(make_scenes.cornell_box(), tmp_path, **FAST)
    assert done.ambient.source == "emission"
    assert done.sources.emitters.area_share < 0.01
    assert float(done.ambient.intensity @ np.array([0.2126, 0.7152, 0.0722])) > 0.05
    assert "warning" not in done.plan.stages["ambient"]
