"""Materials in obscurances (issue 4): classification from glTF, alpha-cut surfaces, mirror and
glass chains with strategies (a)/(b)/(c), Russian roulette, which surfaces get texels, the plan."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import baker.light.hemisphere as integrate_module
from assets.material_scenes import (DIFFUSE_TRANSMISSION, TRANSMISSION, VOLUME, WAX,
                                    alpha_cut_quad, facing_mirrors, glass_slab, leaf, material_zoo,
                                    mirror_wall, wax_cylinder)
from baker.context import context_of
from baker.geometry.world import build_world
from baker.light.hemisphere import _Chains, _refract, _special_hits, hemisphere_rays, surfaces_of
from baker.light.integrate import integrate
from baker.gltf.materials import DIFFUSE, SPECULAR, TRANSLUCENT, classify, no_lightmap_reason
from baker.gltf.scene import Material
from baker.settings import Settings, resolve
from baker.geometry.surface import LUMINANCE
from baker.rays.trace import Tracer
from baker.gltf.load import load
from bakehelp import computed, loaded, saved
from baker.image.compose import effective_r_ave
from plane_reference import blocked
from gltf_validator import issue_codes, validate


def _material(**values) -> Material:
    fields = dict(index=0, name="m", base_color=np.array([0.8, 0.6, 0.4, 1.0]),
                  base_color_texture=None, emissive=np.zeros(3), emissive_texture=None,
                  metallic=0.0, roughness=1.0)
    fields.update(values)
    return Material(**fields)


# ------------------------------------------------------------------------------- classification

def test_diffuse_dielectric_keeps_its_base_colour():
    c = classify(_material())
    np.testing.assert_allclose(c.weights, [1, 0, 0, 0])
    np.testing.assert_allclose(c.diffuse, [0.8, 0.6, 0.4])
    assert c.stages() == set() and no_lightmap_reason(c) == ""


def test_smooth_metal_is_a_mirror_and_rough_metal_stays_diffuse():
    mirror = classify(_material(metallic=1.0, roughness=0.05))
    assert mirror.weights[SPECULAR] == 1.0 and mirror.weights[DIFFUSE] == 0.0
    assert "perfect mirror" in no_lightmap_reason(mirror)
    half = classify(_material(metallic=0.5, roughness=0.0))
    np.testing.assert_allclose(half.weights, [0.5, 0.5, 0, 0])
    np.testing.assert_allclose(half.diffuse, 0.5 * np.array([0.8, 0.6, 0.4]))  # base × (1 − m)
    rough = classify(_material(metallic=1.0, roughness=1.0))  # the glTF default material's
    assert rough.weights[DIFFUSE] == 1.0
    assert classify(_material(metallic=1.0, roughness=0.3), mirror_roughness=0.5).weights[SPECULAR] == 1


def test_transmission_and_ior_sample_values():
    c = classify(_material(roughness=0.0, transmission=1.0, ior=1.5))
    np.testing.assert_allclose(c.weights, [0, 0, 1, 0])
    assert c.ior == 1.5 and c.stages() == {"refraction"}
    assert "clear glass" in no_lightmap_reason(c)
    partly = classify(_material(roughness=0.0, transmission=0.4))
    np.testing.assert_allclose(partly.weights, [0.6, 0, 0.4, 0])  # diffuse = base × (1 − t)
    frosted = classify(_material(roughness=0.8, transmission=1.0))
    assert frosted.weights[TRANSLUCENT] == 1.0  # rough transmission scatters: translucent


def test_volume_and_diffuse_transmission_sample_values():
    c = classify(_material(thickness=1.0, attenuation_distance=0.006,
                           attenuation_color=np.array([0.5, 0.5, 0.5]),
                           diffuse_transmission=0.25,
                           diffuse_transmission_color=np.array([1.0, 0.5, 0.0])))
    np.testing.assert_allclose(c.weights, [0.75, 0, 0, 0.25])
    np.testing.assert_allclose(c.translucent_color, [0.8, 0.3, 0.0])
    assert (c.thickness, c.attenuation_distance) == (1.0, 0.006)
    assert c.stages() == {"translucency", "inner obscurances"}  # a closed volume
    assert c.inner and not c.leaf
    thin = classify(_material(diffuse_transmission=0.25, double_sided=True))
    assert thin.leaf and not thin.inner and thin.stages() == {"translucency", "leaves"}
    assert not classify(_material(diffuse_transmission=0.25)).leaf  # single-sided: no back


def test_alpha_modes():
    assert classify(_material(alpha_mode="MASK", alpha_cutoff=0.5)).alpha_tested is False
    cut = classify(_material(alpha_mode="MASK", base_color=np.array([1, 1, 1, 0.2])))
    assert cut.alpha_tested and cut.invisible and "never drawn" in no_lightmap_reason(cut)
    blend = classify(_material(alpha_mode="BLEND", base_color=np.array([1, 1, 1, 0.3])))
    assert blend.alpha_tested and not blend.invisible and blend.stages() == {"alpha testing"}
    opaque = classify(_material(alpha_mode="OPAQUE", base_color=np.array([1, 1, 1, 0.0])))
    assert not opaque.alpha_tested  # OPAQUE ignores alpha
    unlit = classify(_material(unlit=True))
    assert no_lightmap_reason(unlit) == "unlit material"


def test_loader_reads_every_extension(tmp_path):
    from assets.gltf_builder import GltfBuilder, quad

    b = GltfBuilder()
    for i, ext in enumerate((TRANSMISSION, VOLUME, DIFFUSE_TRANSMISSION)):
        m = b.material(f"m{i}", (0.5, 0.5, 0.5), roughness=0.0, extensions=ext)
        b.node(f"n{i}", b.shape_mesh(f"q{i}", quad(), material=m), translation=(2.0 * i, 0, 0))
    glass, volume, skin = loaded(b, tmp_path).materials[:3]
    assert (glass.transmission, glass.ior) == (1.0, 1.5)
    assert (volume.thickness, volume.attenuation_distance) == (1.0, 0.006)
    np.testing.assert_allclose(volume.attenuation_color, [0.5, 0.5, 0.5])
    assert skin.diffuse_transmission == 0.25
    np.testing.assert_allclose(skin.diffuse_transmission_color, [1.0, 0.5, 0.0])


# ------------------------------------------------------------------------------- alpha testing

def _vertical_rays(xs: np.ndarray, z: float = 0.0):
    origins = np.stack([xs, np.full(len(xs), 0.01), np.full(len(xs), z)], axis=1)
    return origins, np.tile([0.0, 1.0, 0.0], (len(xs), 1))


def test_rays_pass_the_hole_of_an_alpha_cut_quad_and_not_its_opaque_part(tmp_path):
    tracer = Tracer(build_world(loaded(alpha_cut_quad(), tmp_path)))
    xs = np.linspace(-0.95, 0.95, 40)
    origins, directions = _vertical_rays(xs[np.abs(xs) > 0.05])
    hole = origins[:, 0] < 0
    hits = tracer.cast(origins, directions, 10.0)
    assert (hits.triangle[hole] < 0).sum() == hole.sum()  # every ray under the hole escapes
    assert (hits.triangle[~hole] >= 0).sum() == (~hole).sum()  # none through the opaque half
    np.testing.assert_allclose(hits.distance[~hole], 0.49, atol=1e-5)
    blocked = tracer.occluded(origins, directions, 10.0)  # shadow rays too
    assert blocked.sum() == (~hole).sum() and not blocked[hole].any()


def test_blend_lets_rays_through_by_alpha_deterministically(tmp_path):
    from assets.gltf_builder import GltfBuilder, quad, rotation_matrix, transformed

    b = GltfBuilder()
    veil = b.material("veil", (0.5, 0.5, 0.5, 0.3), alpha_mode="BLEND", double_sided=True)
    sheet = transformed(quad(2.0, 2.0), rotation=rotation_matrix((1, 0, 0), 180),
                        translation=(0, 0.5, 0))
    b.node("veil", b.shape_mesh("veil", sheet, material=veil))
    tracer = Tracer(build_world(loaded(b, tmp_path)))
    origins, directions = _vertical_rays(np.linspace(-0.9, 0.9, 4000))
    through = tracer.cast(origins, directions, 10.0).triangle < 0
    assert abs(through.mean() - 0.7) < 3 * np.sqrt(0.21 / len(through))  # 1 − alpha
    again = tracer.cast(origins, directions, 10.0).triangle < 0
    np.testing.assert_array_equal(through, again)


def test_floor_under_the_hole_sees_the_sky(tmp_path):
    done = computed(alpha_cut_quad(), tmp_path, rays=64, texel_density=6, d_max=1.0)
    tx = done.texels
    floor = done.world.tri_instance[tx.triangle] == 0
    inner = floor & (np.abs(tx.position[:, 2]) < 0.5)
    hole = inner & (tx.position[:, 0] < -0.4) & (tx.position[:, 0] > -0.7)
    solid = inner & (tx.position[:, 0] > 0.4) & (tx.position[:, 0] < 0.7)
    assert hole.sum() > 5 and solid.sum() > 5
    escaped = done.terms.escaped
    assert escaped[hole].mean() > 0.9 and escaped[solid].mean() < 0.5  # the hole's half is open
    assert "rays pass" in done.plan.stages["alpha testing"]


# ------------------------------------------------------------------------------- mirrors, glass

def _near_and_far(done, wall_x):
    tx = done.texels
    floor = (done.world.tri_instance[tx.triangle] == 0) & (np.abs(tx.position[:, 2]) < 1.0)
    near = floor & (tx.position[:, 0] > wall_x - 0.3)
    return near, floor & (tx.position[:, 0] < -1.0)


@pytest.fixture(scope="module")
def mirror_bakes(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mirror")
    return {s: computed(mirror_wall(), folder, specular=s, rays=64, texel_density=6, d_max=1.0)
            for s in "abc"}


def test_mirror_strategy_b_is_less_dark_near_the_wall_than_a(mirror_bakes):
    w = {}
    for s, done in mirror_bakes.items():
        near, far = _near_and_far(done, 2.0)
        assert near.sum() > 10
        w[s] = done.terms.obscurance(done.ambient.r_ave)[near].mean()
    assert w["a"] + 0.03 < w["b"] <= w["c"] + 1e-12
    assert mirror_bakes["a"].terms.chain_rays.sum() > 0
    assert mirror_bakes["b"].terms.chain_rays.sum() > 0


def test_escapes_after_a_coloured_mirror_take_its_colour_per_channel(tmp_path):
    """A red mirror wall beside an open floor: a floor ray that meets the mirror within d_max
    and then escapes (strategy b: ρ = 1 past it) counts the mirror's colour × the escape's
    colour (white: an open scene without lights), channel by channel, not their mean: W_c =
    (1 − p) + p·c_c, p the cosine-weighted share of directions that meet the mirror, from an
    independent numpy tracer (tests/plane_reference.py), within 3σ per texel."""
    red = np.array([0.9, 0.1, 0.1])
    scene = mirror_wall(colour=tuple(red))
    rays, d_max = 256, 1.0
    done = computed(scene, tmp_path, rays=rays, texel_density=6, d_max=d_max)
    assert np.array_equal(effective_r_ave(done.ambient, "sqrt"), np.ones(3))
    w = done.terms.obscurance(np.ones(3))
    near, _ = _near_and_far(done, 2.0)
    checked, worst = 0, 0.0
    for k in np.flatnonzero(near):
        p = blocked(done.texels.position[k], [scene.info["rectangle"]], d_max).mean()
        expected = 1 - p + p * red
        sigma = np.abs(1 - red) * np.sqrt(max(p * (1 - p), 1 / rays) / rays) + 1 / 512
        worst = max(worst, float(np.max(np.abs(w[k] - expected) / sigma)))
        checked += p > 0.1
    assert checked > 10 and worst < 3.0, (checked, worst)


def test_strategy_c_casts_no_extra_ray(mirror_bakes):
    c, b = mirror_bakes["c"], mirror_bakes["b"]
    assert c.terms.chain_rays.sum() == 0 and c.terms.rays == b.terms.rays
    near, _ = _near_and_far(c, 2.0)
    assert c.terms.escaped[near].mean() > b.terms.escaped[near].mean()  # R_ave and ρ = 1


def test_refraction_matches_snell_and_total_internal_reflection():
    d = np.array([[1.0, -1.0, 0.0]]) / np.sqrt(2.0)
    up = np.array([[0.0, 1.0, 0.0]])
    out, refracted = _refract(d, up, np.array([1.5]), np.array([False]), np.array([0.99]))
    sin_t = np.sqrt(0.5) / 1.5
    np.testing.assert_allclose(out[0], [sin_t, -np.sqrt(1 - sin_t ** 2), 0.0], atol=1e-12)
    assert refracted[0]
    thin, _ = _refract(d, up, np.array([1.5]), np.array([True]), np.array([0.99]))
    np.testing.assert_allclose(thin, d)  # a thin wall does not bend the ray
    inside = np.array([[np.sin(np.radians(60)), 0.5, 0.0]])  # leaving glass at 60°: TIR
    out, refracted = _refract(inside, up, np.array([1.5]), np.array([False]), np.array([0.99]))
    np.testing.assert_allclose(out[0], [np.sin(np.radians(60)), -0.5, 0.0], atol=1e-12)
    assert not refracted[0]


def test_a_ray_through_a_glass_slab_finds_the_colour_along_the_refracted_path(tmp_path):
    """From (−1.95, 2) at 45° down +x: unbent, the ray lands at x = +0.05 (red); refracted by
    the 0.2-thick slab of IOR 1.5 it shifts by 0.2·(1 − tan θt) and lands at x = −0.0431 (green)."""
    scene = loaded(glass_slab(), tmp_path)
    world = build_world(scene)
    tracer = Tracer(world)
    settings = resolve(Settings(d_max=10.0, rays=1), 1.0, 1.0)
    n = 256
    origins = np.tile(np.array([-1.95, 2.0, 0.0]) - world.center, (n, 1)).astype(np.float32)
    directions = np.tile(np.array([1.0, -1.0, 0.0]) / np.sqrt(2), (n, 1)).astype(np.float32)
    hits = tracer.cast_local(origins, directions, np.full(n, 10.0, np.float32))
    out = np.zeros((n, 4))
    chains = _Chains(np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros((n, 3)))
    _special_hits(surfaces_of(context_of(scene, world, tracer, settings)), tracer, origins, directions, hits,
                  np.arange(n, dtype=np.uint64), 0, 1, settings, out, chains)
    landed = out[:, :3].sum(axis=1) > 0  # the rest escaped (Fresnel, ≈ 4 % per face) or
    assert landed.mean() > 0.75  # ended by Russian roulette (5 % from the second bounce)
    green = out[landed, 1] > out[landed, 0]
    assert green.mean() > 0.95  # red only after two internal reflections (F² ≈ 0.2 %)
    tan_t = np.tan(np.arcsin(np.sqrt(0.5) / 1.5))
    assert -1.95 + 1.0 + 0.2 * tan_t + 0.8 < 0 < -1.95 + 2.0  # the hand-computed landings
    assert chains.rays.sum() >= 2 * landed.sum()  # through the slab: two more rays each


def test_russian_roulette_is_unbiased_between_facing_mirrors(tmp_path, monkeypatch):
    done = computed(facing_mirrors(), tmp_path, rays=16, texel_density=8, d_max=3.0,
                    specular="a", max_depth=8)
    diffs = []
    for seed in range(12):
        settings = replace(done.settings, seed=seed)
        rr = integrate(done.context(settings), done.texels)
        with monkeypatch.context() as m:
            m.setattr(integrate_module, "_ROULETTE_FROM", 10 ** 6)
            exact = integrate(done.context(settings), done.texels)
        r_ave = done.ambient.r_ave
        diffs.append(float((rr.obscurance(r_ave) - exact.obscurance(r_ave)).mean()))
        if seed == 0:
            assert exact.capped.sum() > 0  # the deterministic chains reach the cap
            assert rr.chain_rays.sum() < exact.chain_rays.sum()  # roulette ends chains early
    diffs = np.array(diffs)
    assert abs(diffs.mean()) <= 3 * diffs.std(ddof=1) / np.sqrt(len(diffs)) + 1e-12


# ------------------------------------------------------------------------------- plan, texels

def test_surfaces_that_would_not_show_a_lightmap_get_none(tmp_path):
    b = material_zoo()
    done = computed(b, tmp_path, rays=8, texel_density=4)
    left = dict((where.split(" meshes")[0], reason) for where, reason in done.plan.left_out)
    boxes = b.info["boxes"]
    label = {kind: next(k for k in left if k.startswith(f"nodes[{node}]")) if any(
        k.startswith(f"nodes[{node}]") for k in left) else None for kind, node in boxes.items()}
    assert label["diffuse"] is None
    assert "perfect mirror" in left[label["mirror"]]
    assert "clear glass" in left[label["glass"]]
    assert left[label["unlit"]] == "unlit material"
    assert "fully translucent" in left[label["translucent"]]
    baked_triangles = np.unique(done.texels.triangle)
    baked_instances = set(np.unique(done.world.tri_instance[baked_triangles]).tolist())
    assert len(baked_instances) == 2  # the floor and the diffuse box
    stages = done.plan.stages
    assert "mirror" in stages["specular chains"] and "glass" in stages["refraction"]
    assert "wax" in stages["translucency"] and stages["alpha testing"].startswith("off")


def test_a_diffuse_scene_runs_no_material_stage(tmp_path):
    done = computed(mirror_wall(mirror=False), tmp_path, rays=16, texel_density=4)
    assert done.world.alpha is None and not surfaces_of(done.context()).special
    assert all(done.plan.stages[s].startswith("off") for s in
               ("specular chains", "refraction", "translucency", "alpha testing"))
    assert done.terms.chain_rays.sum() == 0 and done.terms.capped.sum() == 0


# ------------------------------------------------------------------------------- §4: inner, leaves

def _top_cap(done, node):
    tx = done.texels
    top = (done.world.tri_instance[tx.triangle] == node) & (tx.geometric_normal()[:, 1] > 0.99)
    return top, np.hypot(tx.position[:, 0], tx.position[:, 2])


def test_a_wax_cylinders_thin_rim_is_brighter_than_its_thick_core(tmp_path):
    b = wax_cylinder()
    done = computed(b, tmp_path, rays=64, texel_density=20, d_max=1.0)
    top, r = _top_cap(done, b.info["wax"])
    rim, core = top & (r > 0.42), top & (r < 0.15)
    assert rim.sum() > 50 and core.sum() > 20
    inner = done.terms.through_ave @ LUMINANCE
    assert 0 < inner[core].mean() and 1.5 * inner[core].mean() < inner[rim].mean()
    light = done.lightmaps.light[done.texels.pixels()] @ LUMINANCE
    assert light[core].mean() < light[rim].mean()  # the front's W is the same: open sky
    assert "wax" in done.plan.stages["inner obscurances"]
    assert done.plan.stages["leaves"].startswith("off")
    assert done.terms.chain_rays[rim].min() >= 64  # the inner rays are counted


@pytest.mark.parametrize("scale", [1.0, 2.0])
def test_inner_obscurance_of_a_wide_slab_matches_the_closed_form(tmp_path, scale):
    """Under the centre of a wide slab of height h, rays into it leave through the floor at
    d = h/cosθ; with reach R = the volume's thickness (mesh units, × the node's scale) and no
    absorption, W_in = ∫ (1 − sqrt(d/R)) 2μ dμ over μ = cosθ > a = h/R: 1 − (4/3)√a + a²/3."""
    slab = {"KHR_materials_diffuse_transmission": {"diffuseTransmissionFactor": 0.5},
            "KHR_materials_volume": {"thicknessFactor": 0.3}}
    b = wax_cylinder(radius=4.0, height=0.15, extensions=slab, scale=scale)
    done = computed(b, tmp_path, only_nodes={b.info["wax"]}, rays=256, texel_density=2 / scale,
                    d_max=1.0)
    top, r = _top_cap(done, b.info["wax"])
    centre = top & (r < 2.0 * scale)
    assert centre.sum() > 10
    t = classify(done.scene.materials[1]).translucency
    w_in = done.terms.through_ave[centre] / t
    a = 0.5
    np.testing.assert_allclose(w_in.mean(), 1 - 4 / 3 * np.sqrt(a) + a * a / 3, rtol=0.02)


def test_a_leaf_gets_its_front_plus_translucency_times_its_back(tmp_path):
    """The leaf's W against an opaque quad facing up (its front) and one turned over (its back),
    baked separately: W = front + t·back, t = diffuse transmission × its colour × base colour."""
    settings = dict(rays=128, texel_density=16, d_max=1.0)
    means = {}
    r_ave = None
    for facing in ("up", "up-opaque", "down-opaque"):
        b = leaf(facing=facing)
        done = computed(b, tmp_path / facing, only_nodes={b.info["leaf"]}, **settings)
        r_ave = done.ambient.r_ave if r_ave is None else r_ave  # the leaf scene's R_ave
        w = done.terms.obscurance(r_ave)
        means[facing] = w.mean(axis=0)
        if facing == "up":
            t = classify(done.scene.materials[1]).translucency
            np.testing.assert_allclose(t, 0.4 * np.array([1.0, 0.8, 0.5]) * [0.4, 0.8, 0.3])
            assert "leaf" in done.plan.stages["leaves"]
            assert done.plan.stages["inner obscurances"].startswith("off")
    front, back = means["up-opaque"], means["down-opaque"]
    assert back @ LUMINANCE < 0.8 * front @ LUMINANCE  # the back sees the floor: they differ
    np.testing.assert_allclose(means["up"], front + t * back, rtol=0.01)


def test_leaf_and_inner_terms_do_not_depend_on_chunks_or_threads(tmp_path):
    from assets.gltf_builder import quad, transformed

    b = wax_cylinder()
    sheet = transformed(quad(0.6, 0.6), translation=(1.0, 0.3, 0.0))
    b.node("leaf", b.shape_mesh("leaf", sheet, material=b.material(
        "leaf", (0.4, 0.8, 0.3), double_sided=True,
        extensions={"KHR_materials_diffuse_transmission": {"diffuseTransmissionFactor": 0.4}})))
    one = computed(b, tmp_path / "one", rays=16, texel_density=12, threads=1, chunk_texels=4096)
    two = computed(b, tmp_path / "two", rays=16, texel_density=12, threads=2, chunk_texels=37)
    assert (one.terms.through_hit != 0).any() and (one.terms.through_ave != 0).any()
    for name in ("w_hit", "escaped", "through_hit", "through_ave", "chain_rays"):
        np.testing.assert_array_equal(getattr(one.terms, name), getattr(two.terms, name))


# ------------------------------------------------------------------------------- not understood

def test_materials_baker_does_not_understand_bake_as_diffuse_with_a_warning(tmp_path):
    """Unknown extensions (not required), values that are not numbers or out of range, an
    unknown alphaMode: the bake goes on, the material bakes from what it understands, and each
    is a warning (``Scene.skipped``) that the report lists. Clearcoat/sheen/specular change only
    the view (``VIEW_ONLY_EXTENSIONS``): no warning."""
    import baker
    from assets.gltf_builder import GltfBuilder, box, quad

    b = GltfBuilder()
    floor = b.material("floor", (0.8, 0.8, 0.8))
    odd = b.material("odd", (0.6, 0.5, 0.4), metallic=0.0, roughness=0.2, extensions={
        "KHR_materials_clearcoat": {"clearcoatFactor": 1.0},
        "KHR_materials_sheen": {"sheenColorFactor": [1, 1, 1]},
        "KHR_materials_specular": {"specularFactor": 0.5},
        "VENDOR_materials_magic": {"sparkle": True},
        "KHR_materials_transmission": {"transmissionFactor": "lots"},
        "KHR_materials_diffuse_transmission": {"diffuseTransmissionFactor": 3.0},
        "KHR_materials_ior": {"ior": 0.5},
    })
    b._materials[odd].pbrMetallicRoughness.metallicFactor = -2.0
    b._materials[odd].alphaMode = "CUTOUT"
    b.node("floor", b.shape_mesh("floor", quad(3.0, 3.0), material=floor))
    b.node("odd", b.shape_mesh("odd", box((0.5, 0.5, 0.5)), material=odd),
           translation=(0.0, 0.25, 0.0))
    path = saved(b, tmp_path)
    scene = load(path)
    warned = {s.where: s.reason for s in scene.skipped}
    m = "materials[1]"
    assert "not understood" in warned[f"{m}.extensions.VENDOR_materials_magic"]
    for name in ("KHR_materials_clearcoat", "KHR_materials_sheen", "KHR_materials_specular"):
        assert f"{m}.extensions.{name}" not in warned
    assert "not a usable number" in warned[
        f"{m}.extensions.KHR_materials_transmission.transmissionFactor"]
    assert "outside [0, 1]: 1 is used" in warned[
        f"{m}.extensions.KHR_materials_diffuse_transmission.diffuseTransmissionFactor"]
    assert "outside [1, inf]: 1 is used" in warned[f"{m}.extensions.KHR_materials_ior.ior"]
    assert "outside [0, 1]: 0 is used" in warned[f"{m}.pbrMetallicRoughness.metallicFactor"]
    assert "baked as OPAQUE" in warned[f"{m}.alphaMode"]
    material = scene.materials[1]
    assert (material.metallic, material.transmission, material.ior, material.alpha_mode) == (
        0.0, 0.0, 1.0, "OPAQUE")
    assert len(scene.materials) == 3 and classify(scene.materials[0]).weights[DIFFUSE] == 1.0
    result = baker.bake(path, tmp_path / "out.glb", baker.Settings(rays=8, texel_density=4),
                        report_path=tmp_path / "report.json")
    reported = {entry["where"] for entry in result.report["plan"]["left_out"]}
    assert set(warned) <= reported
    assert set(warned.values()) <= set(result.report["warnings"])  # the report's warnings
    errors = [set(issue_codes(validate(p), 0).items()) for p in (path, tmp_path / "out.glb")]
    assert errors[1] <= errors[0], errors  # the bake adds no error to the file's own


def test_other_side_rays_are_what_a_rebake_must_test(tmp_path):
    """A crate under a leaf is met by the leaf's back-face rays, not by its own (front) rays; a
    wax cylinder's inner rays are as long as its d_in and reach its far side."""
    from assets.gltf_builder import box
    from baker.light.inner import other_side_rays

    b = leaf()
    b.node("crate", b.shape_mesh("crate", box((0.4, 0.1, 0.4)), material=b.material(
        "crate", (0.9, 0.2, 0.2))), translation=(0.0, 0.05, 0.0))
    b.node("wax", b.shape_mesh("wax", box((0.3, 0.3, 0.3)), material=b.material(
        "wax", (0.9, 0.8, 0.6), extensions=WAX)), translation=(1.5, 0.15, 0.0))
    done = computed(b, tmp_path, rays=16, texel_density=12, d_max=1.0)
    tracer, tx, s = Tracer(done.world), done.texels, done.settings
    node = done.world.tri_instance[tx.triangle]
    rows = np.flatnonzero((node == b.info["leaf"]) | (node == 0) | (node == 3))
    which, origins, directions, lengths = other_side_rays(done.context(), tx, rows,
                                                          tracer.center)
    owner = node[rows[which]]
    assert set(owner.tolist()) == {b.info["leaf"], 3}  # leaves and closed translucency only
    per_texel = np.repeat(owner, s.rays)
    np.testing.assert_array_equal(lengths[per_texel == b.info["leaf"]], np.float32(s.d_max))
    np.testing.assert_allclose(lengths[per_texel == 3], 0.25, rtol=1e-6)  # WAX's d_in
    hits = tracer.cast_local(origins, directions, lengths.copy())
    hit_node = np.where(hits.triangle >= 0, done.world.tri_instance[hits.triangle], -1)
    leaf_rays = per_texel == b.info["leaf"]
    assert (hit_node[leaf_rays] == 2).any()  # the back face sees the crate
    assert (hit_node[per_texel == 3] == 3).mean() > 0.5  # inner rays leave through the wax
    front_o, front_d = hemisphere_rays(tx, rows[which][owner == b.info["leaf"]], s.rays, s.seed,
                                       tracer.center, s.sampling)
    front = tracer.cast_local(front_o, front_d, np.full(len(front_o), s.d_max, np.float32))
    assert not (done.world.tri_instance[front.triangle[front.triangle >= 0]] == 2).any()


def test_leaves_and_wax_survive_the_bake_state(tmp_path):
    """Their terms are stored with the state: a relight (no ray) and a rebake of an unchanged
    scene give the full bake's bytes."""
    import baker
    from assets.gltf_builder import box

    def scene(intensity):
        b = leaf()
        b.node("wax", b.shape_mesh("wax", box((0.3, 0.3, 0.3)), material=b.material(
            "wax", (0.9, 0.8, 0.6), extensions=WAX)), translation=(1.5, 0.15, 0.0))
        lamp = b.light("point", intensity=intensity)
        b.node("lamp", translation=(0.0, 2.0, 0.0),
               extensions={"KHR_lights_punctual": {"light": lamp}})
        return b

    settings = baker.Settings(rays=8, texel_density=12, d_max=1.0)
    baker.bake(saved(scene(10.0), tmp_path, "a.glb"), tmp_path / "out.glb", settings)
    edited = saved(scene(30.0), tmp_path, "b.glb")
    full = baker.bake(edited, tmp_path / "full.glb", settings, state=False)
    assert full.report["plan"]["stages"]["leaves"].startswith("the back face")
    relit = baker.bake(edited, tmp_path / "out.glb", settings, relight=True)
    assert relit.rebake["rays"] == 0
    assert (tmp_path / "out.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()
    again = baker.bake(edited, tmp_path / "out.glb", settings, incremental="always")
    assert again.rebake["incremental"] is True
    assert (tmp_path / "out.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()


def test_triangle_means_are_each_triangles_own_to_the_bit(tmp_path):
    """``surface.triangle_means`` evaluates untextured triangles once per distinct material and
    corner colours, textured ones once per triangle of their primitive (three more instances
    of the textured quad, turned and scaled, are never looked up): every triangle still gets
    the bits of its own evaluation at its points — textured or not, with varying, uniform or
    no vertex colours, emissive or not."""
    from assets.gltf_builder import GltfBuilder, quad
    from assets.make_scenes import checker
    from baker.geometry.surface import MEAN_POINTS, albedo, emission, triangle_means
    from baker.gltf.load import load

    b = GltfBuilder()
    plain = b.material("plain", (0.7, 0.5, 0.3), emissive=(0.2, 0.1, 0.0))
    textured = b.material("tex", (1.0, 1.0, 1.0), base_color_image=checker(16, 4))
    positions, triangles, normals, uv0 = quad(1.0, 1.0)
    rng = np.random.default_rng(2)
    for k in range(6):
        colors = rng.uniform(0.2, 1.0, (4, 4)) if k % 3 else np.ones((4, 4)) * 0.5
        mesh = b.mesh(f"m{k}", positions, triangles, normals=normals, uv0=uv0, colors=colors,
                      material=textured if k == 5 else plain)
        b.node(f"n{k}", mesh, translation=(2.0 * k, 0.0, 0.0))
    for j in range(3):  # the textured quad (the last mesh) again, elsewhere
        b.node(f"copy{j}", mesh, translation=(0.0, 1.0 + j, 0.0), scale=(1.0 + j, 1.0, 0.5),
               rotation=(0.0, np.sin(0.3 * j), 0.0, np.cos(0.3 * j)))
    plain_mesh = b.mesh("bare", positions, triangles, normals=normals, material=plain)
    b.node("bare", plain_mesh, translation=(0.0, 0.0, 3.0))
    scene = load(b.save(tmp_path / "means.glb"))
    world = build_world(scene)
    t = len(world.triangles)
    tris, bary = np.repeat(np.arange(t), len(MEAN_POINTS)), np.tile(MEAN_POINTS, (t, 1))
    copies = np.concatenate([world.instance_triangles(i) for i, inst in enumerate(scene.instances)
                             if scene.document.nodes[inst.node].name.startswith("copy")])
    for lookup, texture_of in ((albedo, lambda m: m.base_color_texture),
                               (emission, lambda m: m.emissive_texture)):
        own = lookup(scene, world, tris, bary).reshape(t, len(MEAN_POINTS), 3).mean(axis=1)
        asked = []

        def counted(*args, lookup=lookup):
            asked.append(args[2])
            return lookup(*args)

        assert np.array_equal(triangle_means(scene, world, counted, texture_of), own)
        assert not np.isin(copies, np.concatenate(asked)).any()
        distinct = len(np.unique(own, axis=0))
        assert distinct > 8 if lookup is albedo else distinct == 2  # colours, texture: apart
