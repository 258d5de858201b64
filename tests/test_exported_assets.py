"""Real exporters' files: material extensions that only change what a viewer shows, the
spec-gloss workflow, texture transforms, and every file checked before any work (issue 23)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from assets.gltf_builder import GltfBuilder, box, quad
from baker.errors import InputError
from baker.load import VIEW_ONLY_EXTENSIONS, load
from baker.materials import DIFFUSE, classify
from baker.settings import Settings
from baker.bake import compute

VIEW_ONLY = {
    "KHR_materials_clearcoat": {"clearcoatFactor": 1.0, "clearcoatRoughnessFactor": 0.1},
    "KHR_materials_iridescence": {"iridescenceFactor": 1.0},
    "KHR_materials_sheen": {"sheenColorFactor": [1, 0.5, 0.2], "sheenRoughnessFactor": 0.4},
    "KHR_materials_specular": {"specularFactor": 0.3},
    "KHR_materials_anisotropy": {"anisotropyStrength": 0.6},
    "KHR_materials_dispersion": {"dispersion": 0.1},
}


def _prop(extensions: dict | None = None) -> GltfBuilder:
    """A box on a floor, the box's material carrying ``extensions``."""
    b = GltfBuilder()
    floor = b.material("floor", (0.7, 0.7, 0.7))
    coat = b.material("coat", (0.6, 0.3, 0.2), extensions=extensions)
    b.node("floor", b.shape_mesh("floor", quad(3.0, 3.0), material=floor))
    b.node("box", b.shape_mesh("box", box((0.6, 0.6, 0.6)), material=coat), translation=(0, 0.3, 0))
    return b


def _required(path, names) -> None:
    """Rewrite a .gltf so that it requires ``names`` (and uses them)."""
    document = json.loads(path.read_text())
    document["extensionsUsed"] = sorted(set(document.get("extensionsUsed", [])) | set(names))
    document["extensionsRequired"] = sorted(names)
    path.write_text(json.dumps(document))


def test_view_only_extensions_in_extensions_required_bake_as_without_them(tmp_path):
    """Clearcoat, iridescence, sheen, specular, anisotropy, dispersion change only the view:
    required or not, the file bakes, warns of none of them, and gives the lightmap of the same
    file without them, to the bit."""
    assert set(VIEW_ONLY) <= VIEW_ONLY_EXTENSIONS
    for folder in ("with", "plain"):
        (tmp_path / folder).mkdir()
    coated = _prop(VIEW_ONLY).save(tmp_path / "with" / "scene.gltf")
    _required(coated, VIEW_ONLY)
    scene = load(coated)
    assert not [s for s in scene.skipped if "extensions" in s.where], scene.skipped
    settings = Settings(rays=8, texel_density=6)
    with_them = compute(scene, settings)
    without = compute(load(_prop().save(tmp_path / "plain" / "scene.gltf")), settings)
    np.testing.assert_array_equal(with_them.lightmaps.light, without.lightmaps.light)


def test_spec_gloss_albedo_is_its_diffuse_factor_and_texture(tmp_path):
    """KHR_materials_pbrSpecularGlossiness (required): the diffuse albedo is diffuseFactor ×
    diffuseTexture, a dielectric of roughness 1 − glossiness; the core terms are not read."""
    b = _prop()
    path = b.save(tmp_path / "scene.gltf")
    document = json.loads(path.read_text())
    document["materials"][1]["pbrMetallicRoughness"] = {"baseColorFactor": [0, 1, 0, 1],
                                                       "metallicFactor": 1.0}
    document["materials"][1]["extensions"] = {"KHR_materials_pbrSpecularGlossiness": {
        "diffuseFactor": [0.2, 0.4, 0.6, 1.0], "specularFactor": [1, 1, 1],
        "glossinessFactor": 0.25}}
    path.write_text(json.dumps(document))
    _required(path, ["KHR_materials_pbrSpecularGlossiness"])
    material = load(path).materials[1]
    np.testing.assert_array_equal(material.base_color, [0.2, 0.4, 0.6, 1.0])
    assert (material.metallic, material.roughness) == (0.0, 0.75)
    c = classify(material)
    assert c.weights[DIFFUSE] == 1.0
    np.testing.assert_array_equal(c.diffuse, [0.2, 0.4, 0.6])


def test_spec_gloss_diffuse_texture_is_the_base_colour_texture(tmp_path):
    pixels = np.zeros((4, 4, 4), np.uint8)
    pixels[..., 0], pixels[..., 3] = 200, 255
    b = GltfBuilder()
    textured = b.material("textured", (1, 1, 1), base_color_image=pixels)
    b.node("floor", b.shape_mesh("floor", quad(1.0, 1.0), material=textured))
    path = b.save(tmp_path / "scene.gltf")
    document = json.loads(path.read_text())
    pbr = document["materials"][0].pop("pbrMetallicRoughness")
    document["materials"][0]["extensions"] = {"KHR_materials_pbrSpecularGlossiness": {
        "diffuseTexture": pbr["baseColorTexture"]}}
    path.write_text(json.dumps(document))
    scene = load(path)
    ref = scene.materials[0].base_color_texture
    assert ref is not None and ref.image == 0
    assert (scene.images[0].pixels[..., 0] == 200).all()


def test_a_required_extension_baker_lacks_is_named_for_what_it_is(tmp_path):
    path = _prop().save(tmp_path / "scene.gltf")
    _required(path, ["VENDOR_materials_glitter", "EXT_texture_avif"])
    with pytest.raises(InputError) as error:
        load(path)
    message = str(error.value)
    assert "VENDOR_materials_glitter: a material extension" in message
    assert "EXT_texture_avif: a texture format" in message
    assert "Draco" not in message
