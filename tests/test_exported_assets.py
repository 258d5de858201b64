"""Real exporters' files: material extensions that only change what a viewer shows, the
spec-gloss workflow, texture transforms, and every file checked before any work (issue 23)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from assets.gltf_builder import GltfBuilder, box, quad
from baker.errors import InputError, SettingsError
from baker.gltf.extensions import VIEW_ONLY_EXTENSIONS
from baker.gltf.load import load
from baker.gltf.materials import DIFFUSE, classify
from baker.settings import Settings
from baker.pipeline.full import compute

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


# ------------------------------------------------------------------------ KHR_texture_transform

TRANSFORM = {"offset": [0.25, -0.5], "rotation": 0.7, "scale": [1.5, 0.75]}


def _transformed_uv(uv: np.ndarray, transform: dict = TRANSFORM) -> np.ndarray:
    """The extension's map as its authors' implementations apply it (u' = u·cos + v·sin,
    v' = v·cos − u·sin, of the scaled UVs, then the offset), written out on its own."""
    (ox, oy), r, (sx, sy) = transform["offset"], transform["rotation"], transform["scale"]
    u, v = uv[:, 0] * sx, uv[:, 1] * sy
    return np.stack([u * np.cos(r) + v * np.sin(r) + ox, v * np.cos(r) - u * np.sin(r) + oy], 1)


def _textured_floor(folder, uv_of, transform: dict | None):
    """A floor with one random RGBA texture as base colour (alpha-tested) and emission, its
    UVs ``uv_of(stored UVs)``, the textures' KHR_texture_transform ``transform``."""
    rng = np.random.default_rng(5)
    pixels = rng.integers(0, 256, (8, 8, 4), dtype=np.uint8)
    b = GltfBuilder()
    floor = b.material("floor", (0.9, 0.8, 0.7), base_color_image=pixels, alpha_mode="MASK",
                       emissive=(0.3, 0.2, 0.1), double_sided=True)
    positions, triangles, normals, uv = quad(2.0, 2.0)
    b.node("floor", b.mesh("floor", positions, triangles, normals=normals, uv0=uv_of(uv),
                           material=floor))
    b.node("roof", b.shape_mesh("roof", quad(2.0, 2.0), material=b.material("roof")),
           translation=(0, 1.0, 0), rotation=(1.0, 0.0, 0.0, 0.0))
    path = b.save(folder / "scene.gltf")
    document = json.loads(path.read_text())
    material = document["materials"][0]
    material["emissiveTexture"] = dict(material["pbrMetallicRoughness"]["baseColorTexture"])
    if transform is not None:
        for info in (material["pbrMetallicRoughness"]["baseColorTexture"], material["emissiveTexture"]):
            info["extensions"] = {"KHR_texture_transform": transform}
        document["extensionsUsed"] = document.get("extensionsUsed", []) + ["KHR_texture_transform"]
    path.write_text(json.dumps(document))
    return path


def test_texture_transform_is_the_map_the_extension_defines(tmp_path):
    """A quarter turn, a scale and an offset: the UVs sampled are the closed form's."""
    from baker.geometry.world import build_world
    from baker.geometry.surface import texture_uv

    transform = {"offset": [0.25, 0.5], "rotation": np.pi / 2, "scale": [2.0, 1.0]}
    scene = load(_textured_floor(tmp_path, lambda uv: uv, transform))
    world = build_world(scene)
    ref = scene.materials[0].base_color_texture
    stored = world.texcoords[0][world.triangles[0]]  # triangle 0's corners
    sampled = texture_uv(world, ref, np.zeros(3, np.int64), np.eye(3))
    np.testing.assert_allclose(sampled, _transformed_uv(stored, transform), atol=1e-15)
    # u' = 0.25 + v (a quarter turn of (2u, v)), v' = 0.5 − 2u
    np.testing.assert_allclose(sampled, np.stack([0.25 + stored[:, 1], 0.5 - 2 * stored[:, 0]], 1),
                               atol=1e-15)


def test_a_transformed_texture_bakes_as_the_pre_transformed_one(tmp_path):
    """Albedo, alpha and emission of a texture with KHR_texture_transform equal those of the same
    texture without it on UVs transformed beforehand, at any point; so does the lightmap (the
    emissive texture lights the roof, the alpha-tested floor lets rays through)."""
    from baker.geometry.world import build_world
    from baker.geometry.surface import albedo, alpha, emission

    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
    scenes = [load(_textured_floor(tmp_path / "a", lambda uv: uv, TRANSFORM)),
              load(_textured_floor(tmp_path / "b", _transformed_uv, None))]
    assert scenes[0].materials[0].base_color_texture.transform is not None
    assert not [s for s in scenes[0].skipped if "KHR_texture_transform" in s.where]
    rng = np.random.default_rng(1)
    bary = rng.dirichlet(np.ones(3), 500)
    worlds = [build_world(s) for s in scenes]
    tris = np.flatnonzero(worlds[0].tri_material == 0)[rng.integers(0, 2, 500)]
    for sample in (albedo, alpha, emission):
        a, b = (sample(s, w, tris, bary) for s, w in zip(scenes, worlds))
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-5)  # the file's UVs are float32
        assert np.ptp(a) > 0.1  # the texture varies across the samples
    settings = Settings(rays=16, texel_density=8)
    light = [compute(s, settings).lightmaps.light for s in scenes]
    assert np.abs(light[0] - light[1]).max() < 1e-5 * light[1].max()  # measured: 4e-8 of 0.05


# ------------------------------------------------------------------- every file, before any work

@pytest.mark.parametrize("slot", ["normalTexture", "occlusionTexture", "emissiveTexture",
                                  "metallicRoughnessTexture", None])
def test_a_missing_image_file_fails_at_load_whatever_uses_it(tmp_path, slot):
    """An image file the scene names but the bake never samples (a normal map, an occlusion
    map, an unused image) is carried into the output: missing, it fails at load (before any
    ray), naming the image and the file, as a missing colour texture does."""
    pixels = np.full((2, 2, 4), 255, np.uint8)
    b = GltfBuilder()
    b.node("floor", b.shape_mesh("floor", quad(1.0, 1.0), material=b.material(
        "floor", base_color_image=pixels)))
    path = b.save(tmp_path / "scene.gltf")
    document = json.loads(path.read_text())
    document["images"].append({"uri": "gone%20away.png"})
    document["textures"].append({"source": 1})
    material = document["materials"][0]
    if slot == "metallicRoughnessTexture":
        material["pbrMetallicRoughness"][slot] = {"index": 1}
    elif slot is not None:
        material[slot] = {"index": 1}
    path.write_text(json.dumps(document))
    with pytest.raises(InputError) as error:
        load(path)
    assert error.value.where.endswith("images[1].uri")
    assert '"gone%20away.png" is not found' in error.value.message
    assert str(tmp_path / "gone away.png") in error.value.message


# ------------------------------------------------------------------------------ image decoding

def _texture_scene(folder, data: bytes, extension: str | None = None, name="albedo.png"):
    """A floor whose base colour texture's image is the file ``name`` holding ``data``, named by
    texture.source or, with ``extension``, by that extension's source only (so the extension
    is required, as glTF asks of a texture without a core source)."""
    pixels = np.full((2, 2, 4), 255, np.uint8)
    b = GltfBuilder()
    b.node("floor", b.shape_mesh("floor", quad(1.0, 1.0), material=b.material(
        "floor", (0.5, 0.5, 0.5), base_color_image=pixels)))
    path = b.save(folder / "scene.gltf")
    (folder / name).write_bytes(data)
    document = json.loads(path.read_text())
    document["images"] = [{"uri": name}]
    if extension is not None:
        document["textures"][0] = {"extensions": {extension: {"source": 0}}}
        document["extensionsUsed"] = document["extensionsRequired"] = [extension]
    path.write_text(json.dumps(document))
    return path


def _encoded(pixels: np.ndarray, format: str, **options) -> bytes:
    from PIL import Image as PILImage
    import io

    out = io.BytesIO()
    PILImage.fromarray(pixels).save(out, format, **options)
    return out.getvalue()


GRADIENT = np.stack(np.broadcast_arrays(np.arange(32)[None, :] * 8, np.arange(32)[:, None] * 8,
                                        np.full((32, 32), 100), np.full((32, 32), 255)),
                    -1).astype(np.uint8)


@pytest.mark.parametrize("format, kind", [("TIFF", "a TIFF image"), ("BMP", "a BMP image"),
                                          ("GIF", "a GIF image"), ("WEBP", "a WEBP image"),
                                          (None, "an EPS image")])
def test_an_image_glTF_does_not_allow_is_refused_by_its_real_kind(tmp_path, format, kind):
    """A TIFF, BMP, GIF, EPS or WebP file named .png as a texture's core source: refused, naming
    what it really is and what glTF allows; pillow never parses it."""
    data = (b"%!PS-Adobe-3.0 EPSF-3.0\n%%BoundingBox: 0 0 8 8\n" if format is None
            else _encoded(GRADIENT[..., :3], format))
    with pytest.raises(InputError) as error:
        load(_texture_scene(tmp_path, data))
    assert error.value.where.endswith("images[0]")
    assert f'"albedo.png" is {kind}' in error.value.message
    assert "PNG or JPEG only" in error.value.message


def test_webp_decodes_through_ext_texture_webp(tmp_path):
    scene = load(_texture_scene(tmp_path, _encoded(GRADIENT, "WEBP", lossless=True),
                                "EXT_texture_webp", "albedo.webp"))
    np.testing.assert_array_equal(scene.images[0].pixels, GRADIENT)
    assert scene.materials[0].base_color_texture is not None


def test_ktx2_decodes_through_khr_texture_basisu(tmp_path):
    """A UASTC KTX 2 texture (made with the alktx2 encoder, decoded with opengl-basisu): its
    pixels within 1 level of 255 of the source's, on average."""
    import alktx2

    data = alktx2.encode_raw_rgba_to_ktx2(GRADIENT.tobytes(), 32, 32, False, codec="uastc")
    scene = load(_texture_scene(tmp_path, data, "KHR_texture_basisu", "albedo.ktx2"))
    assert scene.materials[0].base_color_texture is not None
    error = np.abs(scene.images[0].pixels.astype(int) - GRADIENT).mean(axis=(0, 1))
    assert (error < 1.0).all(), error


def test_ktx2_without_its_decoder_uses_the_factor_with_a_warning(tmp_path, monkeypatch):
    import sys

    import alktx2

    data = alktx2.encode_raw_rgba_to_ktx2(GRADIENT.tobytes(), 32, 32, False)
    monkeypatch.setitem(sys.modules, "opengl_basisu", None)
    scene = load(_texture_scene(tmp_path, data, "KHR_texture_basisu", "albedo.ktx2"))
    assert scene.materials[0].base_color_texture is None
    (warning,) = [s.reason for s in scene.skipped if s.where == "textures[0]"]
    assert "opengl-basisu" in warning and 'pip install "baker[ktx2]"' in warning
    assert "factor used" in warning


def test_a_tiny_png_declaring_8192_by_4096_is_refused_before_decoding(tmp_path):
    """Its header says 128 MiB of RGBA; its 95 bytes cannot hold it (deflate: at most 1032
    bytes out per byte in): refused from the header, in milliseconds, nothing allocated."""
    import time
    import tracemalloc

    from tests.test_bad_input import huge_png

    data = huge_png(8192, 4096)
    path = _texture_scene(tmp_path, data)
    tracemalloc.start()
    start = time.perf_counter()
    with pytest.raises(InputError) as error:
        load(path)
    seconds = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert "declares 8192×4096 pixels" in error.value.message
    assert f"only {len(data)} bytes" in error.value.message
    assert seconds < 1.0 and peak < 64 << 20, (seconds, peak)


def _two_textures(folder: Path) -> Path:
    b = GltfBuilder()
    for k in range(2):
        b.node(f"floor{k}", b.shape_mesh(f"floor{k}", quad(1.0, 1.0), material=b.material(
            f"floor{k}", base_color_image=GRADIENT)), translation=(2.0 * k, 0, 0))
    return b.save(folder / "scene.glb")


def test_images_past_the_scene_budget_are_refused_before_any_is_decoded(tmp_path, monkeypatch):
    """Two 32×32 textures and a budget of 1500 pixels: the pixels of all the images together
    (2048) are refused from their headers, naming the figures and the largest, and not one
    image is decoded; a budget of exactly 2048 loads both."""
    import baker.gltf.budget as budget
    import baker.gltf.images as images

    decoded = []
    decode = images.decode
    monkeypatch.setattr(images, "decode", lambda *a, **k: decoded.append(a) or decode(*a, **k))
    monkeypatch.setattr(budget, "MAX_SCENE_PIXELS", 1500)
    path = _two_textures(tmp_path)
    with pytest.raises(InputError) as error:
        load(path)
    assert "2 images have 2,048 pixels in all" in error.value.message
    assert "(1,500:" in error.value.message and error.value.where == "images[0]"
    assert decoded == []
    monkeypatch.setattr(budget, "MAX_SCENE_PIXELS", 2048)
    scene = load(path)
    assert all(m.base_color_texture is not None for m in scene.materials[:2])
    assert len(decoded) == 2


def test_textures_past_the_sampled_budget_are_left_out_with_the_figure(tmp_path, monkeypatch):
    """Two 32×32 colour textures and 1500 pixels for the textures the bake keeps: the first
    is kept, the second (whose 1024 pixels would pass it) left out with a warning that names
    it and the budget, and still decoded once, to check it."""
    import baker.gltf.budget as budget
    import baker.gltf.images as images

    kept = []
    decode = images.decode
    monkeypatch.setattr(images, "decode", lambda *a, **k: kept.append(k.get("keep", a[-1]))
                        or decode(*a, **k))
    monkeypatch.setattr(budget, "MAX_SAMPLED_PIXELS", 1500)
    scene = load(_two_textures(tmp_path))
    assert scene.materials[0].base_color_texture is not None
    assert scene.materials[1].base_color_texture is None
    (warning,) = [s.reason for s in scene.skipped if s.where == "textures[1]"]
    assert "past 1,500 pixels" in warning and "(32×32)" in warning
    assert kept == [True, False]


# ---------------------------------------------------------------------------- animated nodes

def _animated_scene(folder, drop_moving: bool = False):
    """A floor, a body over it that an animation drives, and a wheel under the body: the
    scene's path and the three nodes. ``drop_moving``: the same file without the body (the
    wheel goes with it), the animation kept (its channel then drives an empty node)."""
    b = GltfBuilder()
    grey = b.material("grey")
    floor = b.node("floor", b.shape_mesh("floor", quad(3.0, 3.0), material=grey))
    body = b.node("body", b.shape_mesh("body", box((0.5, 0.2, 0.5)), material=grey),
                  translation=(0, 0.5, 0))
    wheel = b.node("wheel", b.shape_mesh("wheel", box((0.1, 0.3, 0.3)), material=grey),
                   translation=(0, 0.3, 0))
    path = b.save(folder / ("without.gltf" if drop_moving else "scene.gltf"))
    document = json.loads(path.read_text())
    document["nodes"][body]["children"] = [wheel]
    document["scenes"][0]["nodes"] = [floor] if drop_moving else [floor, body]
    times = len(document["accessors"])
    document["accessors"] += [{"bufferView": 0, "componentType": 5126, "count": 1,
                               "type": "SCALAR", "min": [0], "max": [0]},
                              {"bufferView": 0, "componentType": 5126, "count": 1, "type": "VEC3"}]
    document["animations"] = [{"name": "drive", "samplers": [
        {"input": times, "output": times + 1}], "channels": [
        {"sampler": 0, "target": {"node": body, "path": "translation"}}]}]
    path.write_text(json.dumps(document))
    return path, floor, body, wheel


def test_a_node_an_animation_moves_is_baked_in_its_rest_pose_with_a_warning(tmp_path):
    """The default (``--animated bake``): the wheel (under an animated parent) and the body
    (its own channel) are warned of and baked in their rest pose; the floor is not warned of."""
    path, _floor, body, wheel = _animated_scene(tmp_path)
    scene = load(path)
    warned = {s.where for s in scene.skipped if s.reason.startswith("node-animated")}
    assert warned == {f"nodes[{body}]", f"nodes[{wheel}]"}
    assert all(i.baked for i in scene.instances)
    assert Settings().animated == "bake"


ANIMATED_SETTINGS = dict(page_size=64, rays=16, shadow_rays=1, emissive_rays=1, threads=1,
                         texel_density=8.0)


def _floor_light(done) -> np.ndarray:
    """The baked texels' light (n, 3), in page order (the floor's alone where it is the only
    baked instance)."""
    return done.lightmaps.light[done.lightmaps.covered]


def test_animated_occlude_keeps_the_shadow_and_skip_bakes_as_without_the_nodes(tmp_path):
    """``occlude``: the moving nodes get no texels, are listed with the reason, and still
    darken the floor under them; ``skip``: no instance of them at all, and the floor's
    lightmap is bit-identical to the same file's without them."""
    path, floor, body, wheel = _animated_scene(tmp_path)
    without, *_ = _animated_scene(tmp_path, drop_moving=True)
    settings = Settings(**ANIMATED_SETTINGS)
    occluded = load(path, animated="occlude")
    moving = {i.node: i for i in occluded.instances if i.node != floor}
    assert set(moving) == {body, wheel}
    assert not any(i.baked for i in moving.values())
    assert all("occluder only" in i.reason and "--animated occlude" in i.reason
               for i in moving.values())
    skipped = load(path, animated="skip")
    assert {i.node for i in skipped.instances} == {floor}
    assert {s.where for s in skipped.skipped if "--animated skip" in s.reason} == {
        f"nodes[{body}]", f"nodes[{wheel}]"}
    shadowed, open_floor, alone = (compute(scene, settings) for scene in (
        occluded, skipped, load(without)))
    assert [len(d.plan.baked) for d in (shadowed, open_floor)] == [1, 1]
    assert any("--animated occlude" in reason for _where, reason in shadowed.plan.left_out)
    assert np.array_equal(_floor_light(open_floor), _floor_light(alone))
    under, bare = _floor_light(shadowed), _floor_light(open_floor)
    assert under.shape == bare.shape
    # The same rays, some stopped by the body's rest pose: darker under it, nowhere lighter.
    assert (under <= bare).all() and under.min() < 0.9 * bare.min()


def test_animated_bake_gives_the_moving_nodes_texels(tmp_path):
    """``bake``: the body and wheel are baked (three instances get texels)."""
    path, *_ = _animated_scene(tmp_path)
    done = compute(load(path, animated="bake"), Settings(**ANIMATED_SETTINGS))
    assert len(done.plan.baked) == 3
    assert any("baked in its rest pose" in reason for _where, reason in done.plan.left_out)


def test_the_animated_setting_reaches_the_bake_from_the_command_line(tmp_path, capsys):
    """``--animated skip`` through the CLI: the report lists the nodes as left out, and an
    unknown value is refused naming the choices."""
    from baker.cli.main import main

    path, _floor, body, _wheel = _animated_scene(tmp_path)
    report = tmp_path / "report.json"
    assert main(["bake", str(path), "-o", str(tmp_path / "out.glb"), "--animated", "skip",
                 "--page-size", "64", "--rays", "4", "--threads", "1",
                 "--report", str(report)]) == 0
    left = json.loads(report.read_text())["plan"]["left_out"]
    assert any(e["where"] == f"nodes[{body}]" and "--animated skip" in e["reason"] for e in left)
    with pytest.raises(SettingsError, match="animated must be one of bake, occlude, skip"):
        Settings(animated="freeze").check()
