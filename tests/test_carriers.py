"""How the bake reaches a viewer (issue 20): carriers, baked lights, visibility, settings.

- occlusion writes visibility: 1 where nothing occludes (glTF's meaning), not R-weighted W;
- the emissive carrier's pages are R·E/π + emission, R the bake's own albedo at the texel;
- baked lights "indirect" leaves exactly the punctual lights' direct light out;
- every carrier's output passes the Khronos validator and previews as the moz one does;
- settings that cannot fit together are clean errors, before any work.
"""

from __future__ import annotations

import numpy as np
import pygltflib
import pytest

import baker
from assets.light_scenes import lit_floor
from assets.make_scenes import cornell_box, open_plane
from baker.atlas.rasterise import flat_pages, texel_barycentrics
from baker.cli.main import main
from baker.errors import SettingsError
from baker.geometry.surface import LUMINANCE, albedo, emission
from baker.gltf.load import load
from baker.image.carriers import emissive_lightmaps
from baker.light.inner import OTHER_SIDE
from baker.preview import render
from tests.bakehelp import REAL_SCENES, composed, computed, saved

import gltf_validator


def test_visibility_is_one_where_nothing_occludes(tmp_path):
    """An open plane: every ray escapes, so the visibility is exactly 1 while W is R_ave."""
    done = computed(open_plane(albedo=0.6), tmp_path, texel_density=8, rays=16, occlusion="also")
    covered = done.lightmaps.covered
    assert covered.any()
    np.testing.assert_array_equal(done.lightmaps.visibility[covered], 1.0)
    w = done.terms.obscurance(done.ambient.r_ave)
    np.testing.assert_allclose(w, 0.6)  # W is weighted by R: what a viewer must not darken by


def test_visibility_is_the_escaped_fraction(tmp_path):
    """In the Cornell box, each texel's visibility is its fraction of rays that escape d_max."""
    done = computed(cornell_box(), tmp_path, texel_density=6, rays=16, occlusion="also")
    texels = done.texels
    front = (texels.key & OTHER_SIDE) == 0
    page = flat_pages(done.lightmaps.visibility)[texels.pixel_index(np.flatnonzero(front))]
    # the same, but where post-processing filled an invalid texel or stitched a seam
    same = page[:, 0] == np.minimum(done.terms.escaped[front], 1.0)
    assert same.mean() > 0.99 and np.all((page >= 0) & (page <= 1))
    assert page[:, 0].min() < 0.9  # corners are occluded


def test_emissive_pages_are_albedo_times_irradiance_over_pi(tmp_path):
    """The Cornell room, all dielectric: each front texel's radiance is its base colour ×
    irradiance / π plus its own emission (the lamp's texels)."""
    done = computed(cornell_box(), tmp_path, texel_density=6, rays=16)
    out = emissive_lightmaps(done.scene, done.world, done.atlas, done.coverage, done.lightmaps,
                             done.settings.padding, None)
    texels = done.texels
    rows = np.flatnonzero((texels.key & OTHER_SIDE) == 0)
    index = texels.pixel_index(rows)
    bary = texel_barycentrics(done.atlas, done.world, texels)[rows]
    tris = texels.triangle[rows]
    expected = (albedo(done.scene, done.world, tris, bary)
                * flat_pages(done.lightmaps.light)[index] / np.pi
                + emission(done.scene, done.world, tris, bary))
    np.testing.assert_allclose(flat_pages(out.light)[index], expected)
    assert emission(done.scene, done.world, tris, bary).max() > 0  # the lamp's own texels
    # the barycentrics are the texels' sample points (validity moves some of those later)
    corners = done.world.positions[done.world.triangles[tris]]
    points = np.einsum("kc,kcj->kj", bary, corners)
    unmoved = np.linalg.norm(points - texels.position[rows], axis=1) < 1e-9
    assert unmoved.mean() > 0.9
    # padding around the charts is filled, as the lightmap's is
    assert np.count_nonzero(out.light.max(axis=-1) > 0) > len(rows)


@pytest.mark.parametrize("metallic", [1.0, 0.25])
def test_a_metal_sends_its_surroundings_and_a_kept_light_only_its_highlight(tmp_path, metallic):
    """A rough floor of base colour 0.5 and metallic 1 or 0.25 under a point light: viewers
    shade (1 − m) of it as diffuse and m as metal. The page is base × E / π when the light is
    dropped (the metal part reflecting its surroundings as the bake models a rough metal), and
    base × (E − (m × the light's direct E)) / π when the light is kept (its highlight is then the
    viewer's)."""
    scene = lit_floor("point", intensity=20.0)
    scene._materials[0].pbrMetallicRoughness.metallicFactor = metallic
    done = computed(scene, tmp_path, texel_density=6, rays=16)
    rows = np.flatnonzero((done.texels.key & OTHER_SIDE) == 0)
    index = done.texels.pixel_index(rows)
    irradiance = flat_pages(done.lightmaps.light)[index]
    direct = done.direct.punctual[rows] @ done.direct.light_colours
    assert (direct > 0.3 * irradiance).all()  # the light gives much of the floor's light

    def page(kept):
        out = emissive_lightmaps(done.scene, done.world, done.atlas, done.coverage,
                                 done.lightmaps, done.settings.padding, kept)
        return flat_pages(out.light)[index]

    np.testing.assert_allclose(page(None), 0.5 * irradiance / np.pi)
    np.testing.assert_allclose(page(done.direct),
                               0.5 * (irradiance - metallic * direct) / np.pi, atol=1e-12)


def test_indirect_leaves_out_exactly_the_punctual_direct_light(tmp_path):
    scene = lit_floor("point", intensity=20.0)
    removed = computed(scene, tmp_path / "a", texel_density=6, rays=16, carrier="moz")
    indirect = computed(scene, tmp_path / "b", texel_density=6, rays=16, carrier="moz",
                        baked_lights="indirect")
    covered = removed.lightmaps.covered
    direct_only = composed(removed, removed.direct, visibility=False)
    no_direct = composed(removed, None, visibility=False)
    assert np.array_equal(indirect.ambient.intensity, removed.ambient.intensity)  # I_A kept
    # the composed pages (before post-processing) relate exactly; post-processing is the same
    difference = (direct_only.light - no_direct.light)[covered]
    assert difference.min() >= 0 and difference.max() > 1.0
    np.testing.assert_allclose(indirect.lightmaps.light[covered],
                               removed.lightmaps.light[covered] - difference, atol=1e-9)


@pytest.mark.parametrize("carrier", ["moz", "emissive", "occlusion"])
def test_each_carrier_validates_and_previews(tmp_path, carrier):
    """Every carrier's file passes the validator; the moz and emissive ones preview alike
    (both show R·E/π; emissive through 8-bit sRGB), occlusion shows albedo × visibility / π."""
    source = saved(cornell_box(), tmp_path)
    settings = dict(texel_density=6, rays=16)
    out = tmp_path / f"{carrier}.glb"
    result = baker.bake(source, out, baker.Settings(carrier=carrier, **settings), state=False)
    report = gltf_validator.validate(out)
    assert not gltf_validator.issue_codes(report, 0), gltf_validator.describe(report, 0)
    assert not gltf_validator.issue_codes(report, 1), gltf_validator.describe(report, 1)
    assert result.report["carrier"] == carrier
    document = pygltflib.GLTF2.load(str(out))
    recorded = document.asset.extras["baker"]
    assert recorded["carrier"] == carrier
    assert recorded["lightmap_encoding"] == ("srgb" if carrier == "emissive" else "linear")
    copies = [m for m in document.materials if "(lightmap page" in (m.name or "")]
    assert copies
    for material in copies:
        extensions = material.extensions or {}
        assert ("MOZ_lightmap" in extensions) == (carrier == "moz")
        assert (material.occlusionTexture is not None) == (carrier == "occlusion")
        if carrier == "emissive":
            assert material.pbrMetallicRoughness.baseColorFactor[:3] == [0, 0, 0]
            assert material.emissiveTexture.texCoord == 1
    if carrier == "occlusion":
        return
    moz = tmp_path / "reference.glb"
    baker.bake(source, moz, baker.Settings(carrier="moz", **settings), state=False)
    size = (120, 90)
    reference = render(load(moz), "lit", size, exposure=2.0)
    picture = render(load(out), "lit", size, exposure=2.0)
    both = reference.lightmapped & picture.lightmapped
    assert both.mean() > 0.3
    a, b = (p.radiance[both] @ LUMINANCE for p in (reference, picture))
    ratio = np.median(b[a > 1e-3] / a[a > 1e-3])
    assert abs(ratio - 1) < 0.03, ratio


def test_metals_are_reported_for_moz_only(tmp_path):
    settings = dict(texel_density=4.0, rays=8)
    moz = baker.bake(REAL_SCENES["MultiUVTest"], tmp_path / "moz.glb",
                     baker.Settings(carrier="moz", **settings), state=False)
    assert any("diffuse part" in note and "--carrier emissive" in note
               for note in moz.report["notes"]), moz.report["notes"]
    emissive = baker.bake(REAL_SCENES["MultiUVTest"], tmp_path / "e.glb",
                          baker.Settings(carrier="emissive", **settings), state=False)
    assert not any("diffuse part" in note for note in emissive.report["notes"])


@pytest.mark.parametrize("settings, words", [
    (dict(carrier="emissive", encoding="linear"), "sRGB"),
    (dict(carrier="occlusion", occlusion="also"), "occlusion"),
    (dict(carrier="occlusion", baked_lights="indirect"), "indirect"),
    (dict(occlusion="only"), "--carrier occlusion"),
    (dict(carrier="lightmap"), "carrier"),
])
def test_settings_that_do_not_fit_are_clean_errors(settings, words):
    with pytest.raises(SettingsError) as error:
        baker.Settings(**settings).check()
    assert words in str(error.value)


def test_cli_carrier_error_writes_nothing(tmp_path, capsys):
    source = saved(open_plane(), tmp_path)
    out = tmp_path / "out.glb"
    assert main(["bake", str(source), "-o", str(out), "--carrier", "emissive",
                 "--encoding", "linear"]) == 1
    assert "sRGB" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("metal_rows, noted", [(16, True), (4, False)])
def test_the_metals_note_reads_the_metallic_texture(tmp_path, metal_rows, noted):
    """A quad of metallicFactor 1 whose metallicRoughnessTexture is metal (blue 255) on
    ``metal_rows`` of its 16 rows and dielectric (blue 0) on the rest, rough everywhere (green
    255): viewers light the lightmap on 1 − metal_rows/16 of it, so it is noted as dark at 0 %
    and not at 75 % (the factor alone says 0 % for both)."""
    b = open_plane(size=2.0)
    pixels = np.zeros((16, 16, 3), np.uint8)
    pixels[..., 1] = 255  # rough (G): baker bakes a rough metal as diffuse
    pixels[:metal_rows, :, 2] = 255
    pbr = b._materials[0].pbrMetallicRoughness
    pbr.metallicFactor = 1.0
    pbr.metallicRoughnessTexture = pygltflib.TextureInfo(index=b._image_texture(pixels, "mr"))
    source = b.save(tmp_path / "metal.glb")
    done = baker.bake(source, tmp_path / "out.glb",
                      baker.Settings(texel_density=8.0, rays=4, carrier="moz"), state=False)
    notes = [note for note in done.report["notes"] if "diffuse part" in note]
    assert bool(notes) == noted, done.report["notes"]
    if noted:
        assert "× its texture" in notes[0] and "0% of its base colour" in notes[0], notes


def test_the_transmission_texture_shares_the_page_and_what_shows_through(tmp_path):
    """A rough quad of transmissionFactor 0.5 whose transmissionTexture is clear (red 255) on
    its top 8 of 16 rows and opaque (red 0) on the rest: viewers multiply the factor by the
    texture's red (three.js's transmissionMap), so they light all of the opaque half's diffuse
    part with the lightmap and half of the other's, and let the scene through that half only.
    The emissive page is base × (1 − t) × E / π, and the preview lets base × t through (the
    factor alone made the whole quad half clear)."""
    from assets.gltf_builder import GltfBuilder, quad
    from baker.geometry.surface import base_colour, transmission_at
    from baker.preview import _see_through

    b = GltfBuilder()
    pixels = np.zeros((16, 16, 3), np.uint8)
    pixels[:8, :, 0] = 255
    texture = b._image_texture(pixels, "transmission")
    pane = b.material("pane", (0.8, 0.6, 0.4), metallic=0.0, roughness=1.0, extensions={
        "KHR_materials_transmission": {"transmissionFactor": 0.5,
                                       "transmissionTexture": {"index": texture}}})
    b.node("pane", b.shape_mesh("pane", quad(2.0, 2.0), material=pane))
    done = computed(b, tmp_path, texel_density=8, rays=4)
    rows = np.flatnonzero((done.texels.key & OTHER_SIDE) == 0)
    index = done.texels.pixel_index(rows)
    bary = texel_barycentrics(done.atlas, done.world, done.texels)[rows]
    tris = done.texels.triangle[rows]
    clear = transmission_at(done.scene, done.world, tris, bary)
    assert (abs(clear - 0.5) < 0.01).mean() > 0.3 and (clear < 0.01).mean() > 0.3
    base = base_colour(done.scene, done.world, tris, bary)
    out = emissive_lightmaps(done.scene, done.world, done.atlas, done.coverage, done.lightmaps,
                             done.settings.padding, None)
    irradiance = flat_pages(done.lightmaps.light)[index]
    np.testing.assert_allclose(flat_pages(out.light)[index],
                               base * (1.0 - clear)[:, None] * irradiance / np.pi, atol=1e-12)
    own, behind = _see_through(done.scene, done.world, tris, bary)
    np.testing.assert_allclose(behind, base * clear[:, None], atol=1e-12)
    assert (own == 1).all()


def test_a_mixed_material_s_copy_reflects_f0_mixed_texel_by_texel(tmp_path):
    """A quad whose metallic varies by texture (metallicFactor 0.7, every blue level and base
    colour level present, ior 1.8, a base colour factor with alpha 0.5): its emissive copy is
    all metal with a base colour texture of F0 = mix(((ior − 1)/(ior + 1))², base × factor,
    metallic) per texel, sRGB-encoded, its alpha the base alpha × 0.5, and a metallicRoughness
    texture of blue 255 with the other channels kept: each of the 65,536 (metallic, base)
    level pairs checked against the formula evaluated texel by texel here."""
    import io

    from PIL import Image
    from assets.gltf_builder import GltfBuilder, quad

    rng = np.random.default_rng(7)
    levels = np.arange(256, dtype=np.uint8)
    base = np.zeros((256, 256, 4), np.uint8)
    base[..., :3] = rng.permuted(np.broadcast_to(levels[None, :, None], (256, 256, 3)), axis=1)
    base[..., 3] = levels[:, None]
    metal_rough = rng.integers(0, 256, (256, 256, 3)).astype(np.uint8)
    metal_rough[..., 2] = levels[:, None]  # row y: metallic level y, against every base level
    b = GltfBuilder()
    material = b.material("mixed", (0.9, 0.8, 0.7), metallic=0.7, roughness=1.0,
                          extensions={"KHR_materials_ior": {"ior": 1.8}})
    pbr = b._materials[material].pbrMetallicRoughness
    pbr.baseColorFactor = [0.9, 0.8, 0.7, 0.5]
    pbr.baseColorTexture = pygltflib.TextureInfo(index=b._image_texture(base, "base"))
    pbr.metallicRoughnessTexture = pygltflib.TextureInfo(index=b._image_texture(metal_rough, "mr"))
    b.node("quad", b.shape_mesh("quad", quad(2.0, 2.0), material=material))
    out = tmp_path / "out.glb"
    baker.bake(b.save(tmp_path / "mixed.glb"), out, baker.Settings(texel_density=4.0, rays=2),
               state=False)
    document = pygltflib.GLTF2().load(str(out))
    blob = document.binary_blob()

    def pixels(texture_info) -> np.ndarray:
        view = document.bufferViews[document.images[document.textures[texture_info.index].source]
                                    .bufferView]
        data = blob[view.byteOffset or 0:(view.byteOffset or 0) + view.byteLength]
        return np.asarray(Image.open(io.BytesIO(data)))

    copy = next(m for m in document.materials if m.pbrMetallicRoughness.baseColorTexture
                and m.pbrMetallicRoughness.baseColorTexture.index != pbr.baseColorTexture.index)
    assert copy.pbrMetallicRoughness.metallicFactor == 1.0  # all metal: no diffuse left
    assert copy.pbrMetallicRoughness.baseColorFactor == [1.0, 1.0, 1.0, 1.0]
    colour = pixels(copy.pbrMetallicRoughness.baseColorTexture)
    f0 = ((1.8 - 1.0) / (1.8 + 1.0)) ** 2
    metallic = np.clip(0.7 * metal_rough[..., 2:3] / 255.0, 0.0, 1.0)
    e = base[..., :3] / 255.0
    linear = np.where(e <= 0.04045, e / 12.92, ((e + 0.055) / 1.055) ** 2.4) * [0.9, 0.8, 0.7]
    reflectance = np.clip((1.0 - metallic) * f0 + metallic * linear, 0.0, 1.0)
    encoded = np.where(reflectance <= 0.0031308, 12.92 * reflectance,
                       1.055 * reflectance ** (1 / 2.4) - 0.055)
    np.testing.assert_array_equal(colour[..., :3], np.round(encoded * 255.0))
    np.testing.assert_array_equal(colour[..., 3], np.round(base[..., 3] * 0.5))
    rough = pixels(copy.pbrMetallicRoughness.metallicRoughnessTexture)
    np.testing.assert_array_equal(rough[..., :2], metal_rough[..., :2])
    assert (rough[..., 2] == 255).all()


@pytest.mark.parametrize("extensions, f0", [
    ({}, 0.04),
    ({"KHR_materials_ior": {"ior": 1.8}}, (0.8 / 2.8) ** 2),
    ({"KHR_materials_ior": {"ior": 1.8},
      "KHR_materials_specular": {"specularFactor": 0.5, "specularColorFactor": [1.0, 0.5, 0.25]}},
     (0.8 / 2.8) ** 2 * 0.5 * np.array([1.0, 0.5, 0.25])),
    ({"KHR_materials_ior": {"ior": "x"}}, 0.04),
    ({"KHR_materials_ior": 5, "KHR_materials_specular": {"specularFactor": [0.5]}}, 0.04)])
def test_a_mixed_material_without_textures_reflects_its_own_f0(tmp_path, extensions, f0):
    """metallicFactor 0.4 and no texture: the emissive copy is all metal with base colour
    F0 = 0.6 · ((ior − 1)/(ior + 1))² × KHR_materials_specular + 0.4 · base colour, its
    extensions for the dielectric gone (a metal reads neither); they used to be dropped before
    they were read, so every such copy reflected as at ior 1.5. An ior or a factor that is not
    a number is the default's, as the load warns (the writer read them again from the JSON,
    unchecked: a string ior was an internal error)."""
    from assets.gltf_builder import GltfBuilder, quad

    b = GltfBuilder()
    material = b.material("mixed", (0.9, 0.6, 0.3), metallic=0.4, roughness=1.0,
                          extensions=extensions or None)
    b.node("quad", b.shape_mesh("quad", quad(2.0, 2.0), material=material))
    out = tmp_path / "out.glb"
    baker.bake(b.save(tmp_path / "mixed.glb"), out, baker.Settings(texel_density=4.0, rays=2),
               state=False)
    copy = next(m for m in pygltflib.GLTF2().load(str(out)).materials
                if m.name.startswith("mixed ("))
    pbr = copy.pbrMetallicRoughness
    assert pbr.metallicFactor == 1.0 and not (copy.extensions or {}).keys() & set(extensions)
    np.testing.assert_allclose(pbr.baseColorFactor[:3],
                               0.6 * np.asarray(f0) + 0.4 * np.array([0.9, 0.6, 0.3]), rtol=1e-12)


@pytest.mark.parametrize("alpha_mode", ["OPAQUE", "BLEND"])
def test_a_specular_glossiness_copy_loses_its_diffuse_where_viewers_read_it(tmp_path, alpha_mode):
    """KHR_materials_pbrSpecularGlossiness replaces the core terms in the viewers that read it
    (Babylon.js, Blender, glTFast): the emissive copy's diffuseFactor is black with its alpha
    kept, its diffuseTexture gone when opaque (kept for its alpha when blended), its specular
    and glossiness as they were. It used to keep the diffuse, which those viewers lit a second
    time on top of the baked emission."""
    from assets.gltf_builder import GltfBuilder, quad

    b = GltfBuilder()
    texture = b._image_texture(np.full((4, 4, 4), 255, np.uint8), "diffuse")
    spec_gloss = {"diffuseFactor": [0.2, 0.8, 0.2, 0.5], "diffuseTexture": {"index": texture},
                  "specularFactor": [0.3, 0.2, 0.1], "glossinessFactor": 0.25}
    material = b.material("sg", (0.9, 0.9, 0.9), alpha_mode=alpha_mode,
                          extensions={"KHR_materials_pbrSpecularGlossiness": dict(spec_gloss)})
    b.node("quad", b.shape_mesh("quad", quad(2.0, 2.0), material=material))
    out = tmp_path / "out.glb"
    done = baker.bake(b.save(tmp_path / "sg.glb"), out,
                      baker.Settings(texel_density=4.0, rays=4, sky=(1.0, 1.0, 1.0)), state=False)
    copy = next(m for m in pygltflib.GLTF2().load(str(out)).materials if m.name.startswith("sg ("))
    kept = copy.extensions["KHR_materials_pbrSpecularGlossiness"]
    assert kept["diffuseFactor"] == [0.0, 0.0, 0.0, 0.5]
    assert ("diffuseTexture" in kept) == (alpha_mode == "BLEND")
    assert {k: kept[k] for k in ("specularFactor", "glossinessFactor")} == {
        k: spec_gloss[k] for k in ("specularFactor", "glossinessFactor")}
    assert copy.pbrMetallicRoughness.baseColorFactor[:3] == [0.0, 0.0, 0.0]
    assert done.report["settings"]["carrier"] == "emissive"
    report = gltf_validator.validate(out)
    assert not gltf_validator.issue_codes(report, 0), gltf_validator.describe(report, 0)


@pytest.mark.parametrize("variants", [[1], 5, "x"])
def test_a_primitive_s_variants_that_are_not_an_object_are_as_none(tmp_path, variants):
    """A primitive whose KHR_materials_variants is not the extension's object: the bake goes
    on as for a primitive without it, and the output keeps the value as it was. The writer
    read its mappings with ``.get`` and ended in an internal error."""
    from assets.gltf_builder import GltfBuilder, quad

    b = GltfBuilder()
    mesh = b.shape_mesh("card", quad(2.0, 2.0), material=b.material("red", (0.8, 0.1, 0.1)))
    b.node("card", mesh)
    b._meshes[mesh].primitives[0].extensions = {"KHR_materials_variants": variants}
    out = tmp_path / "out.glb"
    baker.bake(b.save(tmp_path / "variants.glb"), out,
               baker.Settings(texel_density=4.0, rays=4, carrier="moz"), state=False)
    primitive = pygltflib.GLTF2().load(str(out)).meshes[0].primitives[0]
    assert primitive.extensions["KHR_materials_variants"] == variants


@pytest.mark.parametrize("carrier", ["moz", "occlusion", "emissive"])
def test_material_variants_keep_the_bake_where_the_carrier_allows(tmp_path, carrier):
    """A quad with KHR_materials_variants (red by default and as variant 0, blue as variant
    1): under moz and occlusion, whose page is the same for every material, each variant maps
    to a lightmap copy of its own material on the primitive's page and UV set (a viewer that
    switches variants, as <model-viewer> does, keeps the bake); under the emissive carrier,
    whose page holds the default material's colour, the variants keep their own materials and
    the report says so. The variants used to map to the input's materials under every
    carrier, which show no bake."""
    from assets.gltf_builder import GltfBuilder, quad

    b = GltfBuilder()
    red, blue = b.material("red", (0.8, 0.1, 0.1)), b.material("blue", (0.1, 0.1, 0.8))
    mesh = b.shape_mesh("card", quad(2.0, 2.0), material=red)
    b.node("card", mesh)
    b._meshes[mesh].primitives[0].extensions = {"KHR_materials_variants": {"mappings": [
        {"material": blue, "variants": [1]}, {"material": red, "variants": [0]}]}}
    b._extensions_used.add("KHR_materials_variants")
    source = b.save(tmp_path / "variants.glb")
    document = pygltflib.GLTF2().load(str(source))
    document.extensions = {"KHR_materials_variants": {"variants": [{"name": "red"},
                                                                   {"name": "blue"}]}}
    document.save(str(source))
    out = tmp_path / "out.glb"
    done = baker.bake(source, out, baker.Settings(texel_density=4.0, rays=4, carrier=carrier),
                      state=False)
    baked = pygltflib.GLTF2().load(str(out))
    primitive = baked.meshes[0].primitives[0]
    mappings = primitive.extensions["KHR_materials_variants"]["mappings"]
    by_variant = {mapping["variants"][0]: baked.materials[mapping["material"]]
                  for mapping in mappings}
    default = baked.materials[primitive.material]
    assert default.name == "red (lightmap page 0)"
    if carrier == "emissive":
        assert [m.name for m in by_variant.values()] == ["blue", "red"]
        assert any("KHR_materials_variants" in note for note in done.report["notes"])
        return
    assert by_variant[0] is default and by_variant[1].name == "blue (lightmap page 0)"
    assert by_variant[1].pbrMetallicRoughness.baseColorFactor[:3] == [0.1, 0.1, 0.8]
    slot = {"moz": lambda m: m.extensions["MOZ_lightmap"],
            "occlusion": lambda m: {"index": m.occlusionTexture.index,
                                    "texCoord": m.occlusionTexture.texCoord}}[carrier]
    assert slot(by_variant[1])["index"] == slot(default)["index"]
    assert slot(by_variant[1])["texCoord"] == slot(default)["texCoord"] == 1
    report = gltf_validator.validate(out)
    assert not gltf_validator.issue_codes(report, 0), gltf_validator.describe(report, 0)
