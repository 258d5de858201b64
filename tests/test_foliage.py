"""Foliage fast mode (baker/light/foliage.py): what is foliage, the closed-form terms, the fit
and its reported error against the traced obscurance, and the rebake's answer."""

from dataclasses import replace

import numpy as np
import pytest

import baker
from assets.foliage_scenes import tree, tree_and_boxes
from assets.light_scenes import _add_light
from baker.context import context_of
from baker.errors import InputError, SettingsError
from baker.geometry.surface import LUMINANCE
from baker.geometry.world import build_world
from baker.image.compose import effective_r_ave
from baker.light.foliage import find_foliage
from baker.pipeline import parts
from baker.rays.trace import Tracer
from baker.rebake.state import default_path
from baker.settings import Settings, resolve
from tests.bakehelp import loaded, saved

# escape "scene": the environment the errors below were measured in (R_ave, not the neutral
# white an open unlit scene gets by default, against which the leaves' fit errs 20.4 % of W,
# just past the 20 % bound of test_the_reported_error_is_the_error_against_tracing)
SETTINGS = dict(rays=32, texel_density=6.0, page_size=512, escape="scene")


def _tree():
    return tree(leaf_count=1500, grass_count=300)


@pytest.fixture(scope="module")
def bakes(tmp_path_factory):
    """The small tree baked traced and in foliage approx mode: (traced, approx) ``Computed``."""
    from baker.pipeline.full import compute

    scene = loaded(_tree(), tmp_path_factory.mktemp("tree"))
    traced = compute(scene, baker.Settings(**SETTINGS))
    approx = compute(scene, baker.Settings(**SETTINGS, foliage="approx"))
    return scene, traced, approx


def _w(done) -> np.ndarray:
    return done.terms.obscurance(effective_r_ave(done.ambient, done.settings.rho)) @ LUMINANCE


def _foliage_of(scene):
    """``find_foliage`` of a loaded scene, with the default settings."""
    world = build_world(scene)
    return find_foliage(context_of(scene, world, Tracer(world), resolve(Settings(), 1.0, 1.0)))


def test_foliage_is_found_from_materials_and_extras(tmp_path):
    b = _tree()
    scene = loaded(b, tmp_path)
    found = {node: (kind, len(tris)) for node, kind, tris, _ in _foliage_of(scene)}
    nodes = b.info["nodes"]
    assert found == {nodes["crown"]: ("crown", 2 * 1500), nodes["grass"]: ("grass", 2 * 300)}
    b._nodes[nodes["crown"]].extras = {"foliage": "none"}  # a node may say it is not foliage
    b._nodes[nodes["trunk"]].extras = {"foliage": "crown", "foliage_density": 2.0}
    scene = loaded(b, tmp_path)
    found = _foliage_of(scene)
    assert [(n, k, d) for n, k, _, d in found] == [(nodes["trunk"], "crown", 2.0),
                                                   (nodes["grass"], "grass", None)]


@pytest.mark.parametrize("extras, what", [({"foliage": "tree"}, "foliage"),
                                          ({"foliage_density": -1}, "foliage_density")])
def test_bad_extras_name_the_node(tmp_path, extras, what):
    b = _tree()
    b._nodes[b.info["nodes"]["crown"]].extras = extras
    path = saved(b, tmp_path)
    with pytest.raises(InputError) as error:
        baker.bake(path, tmp_path / "out.glb", baker.Settings(**SETTINGS, foliage="approx"))
    assert f"nodes[{b.info['nodes']['crown']}].extras.{what}" in str(error.value.where)
    assert not (tmp_path / "out.glb").exists()


@pytest.mark.parametrize("settings", [dict(foliage="fast"), dict(foliage_density=0.0)])
def test_bad_settings(settings):
    with pytest.raises(SettingsError):
        baker.Settings(**settings).check()


def test_leaves_and_grass_cast_no_ray_and_the_rest_is_traced(bakes):
    scene, traced, approx = bakes
    assert np.array_equal(traced.texels.key, approx.texels.key)
    group = approx.foliage.texel_groups(approx.texels)
    assert (group >= 0).sum() > 1000 and (group < 0).sum() > 1000
    assert np.all(approx.terms.counts[group >= 0] == 0)
    assert np.all(approx.terms.counts[group < 0] == SETTINGS["rays"])
    assert approx.tally.rays == SETTINGS["rays"] * int((group < 0).sum())
    assert traced.foliage is None


def test_the_reported_error_is_the_error_against_tracing(bakes):
    """The held-out RMSE and bias, measured on 128 texels a crown, predict the error over all
    the crown's texels (against a traced bake with the same rays), and the fit is good."""
    scene, traced, approx = bakes
    group = approx.foliage.texel_groups(approx.texels)
    w_traced, w_approx = _w(traced), _w(approx)
    crown = approx.foliage.crowns[0]
    assert crown.kind == "crown" and crown.source == "fit" and crown.density > 0
    assert crown.fit.count == 128 and crown.fit.residual < 0.2
    mine = group == 0
    diff = w_approx[mine] - w_traced[mine]
    rmse, held = float(np.sqrt(np.mean(diff ** 2))), crown.errors["held_out"]
    assert held.texels == 128
    assert 0.5 * rmse < held.rmse < 2.0 * rmse
    assert abs(held.bias - diff.mean()) < 2 * held.rmse / np.sqrt(held.texels) + 1e-3
    # within 20 % of the leaves' W (at 32 rays the traced W's own noise is most of that)
    assert rmse < 0.2 * float(np.mean(w_traced[mine]))
    report = approx.foliage.report()
    assert set(report["error"]) == {"fit", "held_out"} and report["rays"] > 0


def test_the_crown_shades_the_ground_below_it(bakes):
    """Ground texels under the crown: traced without the leaves and darkened in closed form,
    their mean W within 15 % of the traced one, and darker than the open ground."""
    scene, traced, approx = bakes
    ground = traced.world.tri_instance[traced.texels.triangle] == 0
    radius = np.hypot(traced.texels.position[:, 0], traced.texels.position[:, 2])
    under, open_ground = ground & (radius > 0.5) & (radius < 1.5), ground & (radius > 5.5)
    w_traced, w_approx = _w(traced), _w(approx)
    assert w_approx[under].mean() == pytest.approx(w_traced[under].mean(), rel=0.15)
    assert w_approx[under].mean() < w_approx[open_ground].mean()


def test_density_override_from_setting_and_extras(tmp_path):
    from baker.pipeline.full import compute

    b = _tree()
    b._nodes[b.info["nodes"]["crown"]].extras = {"foliage_density": 0.5}
    scene = loaded(b, tmp_path)
    done = compute(scene, baker.Settings(**SETTINGS, foliage="approx", foliage_density=0.2))
    crown = done.foliage.crowns[0]
    assert (crown.density, crown.source) == (0.5, "extras")
    b._nodes[b.info["nodes"]["crown"]].extras = {}
    done = compute(loaded(b, tmp_path), baker.Settings(**SETTINGS, foliage="approx",
                                                        foliage_density=0.2))
    assert (done.foliage.crowns[0].density, done.foliage.crowns[0].source) == (0.2, "setting")


def test_approx_bake_in_parts_gives_the_bytes_of_one_part(tmp_path, monkeypatch):
    path = saved(_tree(), tmp_path)
    settings = baker.Settings(**SETTINGS, foliage="approx")
    (tmp_path / "whole").mkdir()
    (tmp_path / "parts").mkdir()
    whole = baker.bake(path, tmp_path / "whole" / "baked.glb", settings)
    part = whole.texels // 4 + 1  # at least four parts
    monkeypatch.setattr(parts, "PART_TEXELS", part)
    split = baker.bake(path, tmp_path / "parts" / "baked.glb", settings)
    assert split.texels == whole.texels > 3 * part
    assert (tmp_path / "parts" / "baked.glb").read_bytes() == (
        tmp_path / "whole" / "baked.glb").read_bytes()
    assert split.report["foliage"] == whole.report["foliage"]


def _tree_and_boxes(moves: dict[str, tuple]):
    return tree_and_boxes(moves, leaf_count=1500, grass_count=300)


@pytest.mark.parametrize("moves", [
    {"crown": (0.4, 0.0, 0.2), "trunk": (0.4, 0.0, 0.2)},  # the tree: its crown refitted
    {"near": (2.3, 0.25, 0.3)},  # an object within the crown's reach: the fit's texels see it
    {"far": (5.0, 0.25, -5.0)},  # far from the tree
], ids=["tree", "near", "far"])
def test_a_rebake_in_foliage_mode_gives_the_bytes_of_a_full_bake(tmp_path, moves):
    settings = baker.Settings(**{**SETTINGS, "rays": 16}, foliage="approx", shadow_rays=1)
    baker.bake(saved(_tree_and_boxes({}), tmp_path, "base.glb"), tmp_path / "out.glb", settings)
    edited = saved(_tree_and_boxes(moves), tmp_path, "edited.glb")
    again = baker.bake(edited, tmp_path / "out.glb", settings, incremental="always")
    assert again.rebake["incremental"] is True, again.rebake
    full = baker.bake(edited, tmp_path / "full.glb", settings)
    assert (tmp_path / "out.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()
    assert default_path(tmp_path / "out.glb").read_bytes() == default_path(
        tmp_path / "full.glb").read_bytes()
    assert again.report["foliage"] == full.report["foliage"]


@pytest.mark.parametrize("extras", [{"foliage": "none"}, {"foliage": "grass"},
                                    {"foliage_density": 50.0}])
def test_a_rebake_after_the_foliage_hints_changed_is_a_full_bake(tmp_path, extras):
    """The crown's node told otherwise by its extras (not foliage, grass, or a density): the
    fingerprints held no foliage hint, and such an edit rebaked as "nothing changed", its
    leaves still the old crown (the output not a full bake's). Now it is a full bake, and says
    why; an edit of other extras stays an incremental one."""
    settings = baker.Settings(**{**SETTINGS, "rays": 8}, foliage="approx", shadow_rays=1)
    b = _tree_and_boxes({})
    baker.bake(saved(b, tmp_path, "base.glb"), tmp_path / "out.glb", settings)
    b._nodes[b.info["nodes"]["crown"]].extras = extras
    edited = saved(b, tmp_path, "edited.glb")
    again = baker.bake(edited, tmp_path / "out.glb", settings, incremental="always")
    assert "foliage hints of node 'crown'" in again.rebake["full_bake_reason"]
    baker.bake(edited, tmp_path / "full.glb", settings)
    assert (tmp_path / "out.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()
    b._nodes[b.info["nodes"]["crown"]].extras = dict(extras, note="any other value")
    other = baker.bake(saved(b, tmp_path, "other.glb"), tmp_path / "out.glb", settings,
                       incremental="always")
    assert other.rebake["incremental"] is True, other.rebake


def test_relight_keeps_working_in_foliage_mode(tmp_path):
    def lit(intensity):
        b = _tree()
        _add_light(b, "point", (3.0, 6.0, 2.0), (0.0, -1.0, 0.0), intensity=intensity)
        return b

    settings = baker.Settings(**{**SETTINGS, "rays": 16}, foliage="approx", shadow_rays=1)
    baker.bake(saved(lit(20.0), tmp_path, "base.glb"), tmp_path / "out.glb", settings)
    brighter = saved(lit(35.0), tmp_path, "brighter.glb")
    relit = baker.bake(brighter, tmp_path / "out.glb", settings, relight=True)
    assert relit.rebake["incremental"] is True
    baker.bake(brighter, tmp_path / "full.glb", settings)
    assert (tmp_path / "out.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()
    assert default_path(tmp_path / "out.glb").read_bytes() == default_path(
        tmp_path / "full.glb").read_bytes()


def test_a_crown_without_texels_takes_its_density_from_its_leaf_area(tmp_path):
    """Leaves that get no texels (here: not baked) still shade the ground, with αρ from their
    leaf area: V = exp(−σR) where the cap is the whole shell, σ = area / volume / 2."""
    from baker.pipeline.full import compute

    b = _tree()
    scene = loaded(b, tmp_path)
    crown_node = b.info["nodes"]["crown"]
    scene = replace(scene, instances=tuple(
        replace(i, baked=False, reason="not under test") if i.node == crown_node else i
        for i in scene.instances))
    done = compute(scene, baker.Settings(**SETTINGS, foliage="approx"))
    crown = done.foliage.crowns[0]
    assert crown.source == "leaf area" and crown.errors["held_out"].texels == 0
    assert len(crown.shells) == 1
    shell = crown.shells[0]
    tris = np.flatnonzero(done.foliage.group == 0)
    sigma = done.world.areas(tris).sum() / shell.volume / 2
    edge = shell.center - shell.axes[0] * shell.radii[0]  # facing the centre: the whole shell
    v = crown.visibility(edge[None], shell.axes[:1])[0]
    assert v == pytest.approx(np.exp(-sigma * shell.radius), rel=1e-9)
    ground = done.world.tri_instance[done.texels.triangle] == 0
    radius = np.hypot(done.texels.position[:, 0], done.texels.position[:, 2])
    w = _w(done)
    assert w[ground & (radius > 0.5) & (radius < 1.5)].mean() < w[ground & (radius > 5.5)].mean()
