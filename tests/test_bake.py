"""End to end: glTF in, baked glTF out, as a user runs it."""

import json

import numpy as np
import pygltflib
import pytest
from PIL import Image, ImageDraw
import io

import baker
from assets.make_scenes import cornell_box, three_instances, vase_room
from baker.gltf.accessors import read_accessor
from baker.gltf.load import load
from tests.bakehelp import REAL_SCENES, carried, page_uv, saved
from tests.gltf_validator import describe, issue_codes, validate

FAST = dict(texel_density=8.0, rays=16)


def _bake(builder, tmp_path, name="out.glb", **settings):
    source = saved(builder, tmp_path, "in.glb")
    out = tmp_path / name
    result = baker.bake(source, out, baker.Settings(**{**FAST, **settings}),
                        report_path=tmp_path / "report.json")
    return source, out, result


def _new_problems(source, out):
    """Kinds of validator errors/warnings in ``out`` that ``source`` did not have already.

    Kinds, not counts: a mesh copied per baked node repeats the source's own warnings.
    """
    before, after = validate(source), validate(out)
    new = {}
    for severity in (0, 1):
        extra = set(issue_codes(after, severity)) - set(issue_codes(before, severity))
        if extra:
            new[severity] = (extra, describe(after, severity))
    return new


def _lightmap_texcoords_exist(path):
    """Every carrier's texCoord (bakehelp.carried) names a TEXCOORD set of each primitive that
    uses it."""
    doc = pygltflib.GLTF2().load(str(path))
    checked = 0
    for mesh in doc.meshes:
        for prim in mesh.primitives:
            if prim.material is None:
                continue
            ext = carried(doc.materials[prim.material])
            if ext is None:
                continue
            assert getattr(prim.attributes, f"TEXCOORD_{ext['texCoord']}") is not None
            checked += 1
    return checked


def test_cornell_box_bakes_validates_and_bleeds_colour(tmp_path):
    source, out, result = _bake(cornell_box(), tmp_path, rays=64)
    assert _new_problems(source, out) == {}
    assert _lightmap_texcoords_exist(out) >= 8
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["texels"] == result.texels > 1000
    assert report["rays"] == result.texels * 64
    assert report["settings"]["d_max"] > 0 and report["ambient"]["source"] == "emission"
    assert set(report["stage_seconds"]) >= {"load", "unwrap", "rasterise", "trace", "write"}
    # The embedded pages are real lightmaps: not flat.
    doc = pygltflib.GLTF2().load(str(out))
    blob = doc.binary_blob()
    image = doc.images[-1]
    view = doc.bufferViews[image.bufferView]
    pixels = np.asarray(Image.open(io.BytesIO(blob[view.byteOffset:view.byteOffset + view.byteLength])))
    assert pixels.std() > 5


def test_same_bake_twice_gives_identical_bytes(tmp_path):
    _, first, _ = _bake(cornell_box(), tmp_path, "a.glb")
    _, second, _ = _bake(cornell_box(), tmp_path, "b.glb")
    assert first.read_bytes() == second.read_bytes()


def test_threads_and_chunks_do_not_change_the_lightmaps(tmp_path):
    _, one, _ = _bake(cornell_box(), tmp_path, "one.glb", threads=1, chunk_texels=100000)
    _, two, _ = _bake(cornell_box(), tmp_path, "two.glb", threads=2, chunk_texels=4096)
    _, tiny, _ = _bake(cornell_box(), tmp_path, "tiny.glb", threads=2, chunk_texels=7)
    assert one.read_bytes() == two.read_bytes() == tiny.read_bytes()


def test_a_mesh_on_three_nodes_gets_three_lightmap_areas(tmp_path):
    builder = three_instances()
    source, out, _ = _bake(builder, tmp_path, texel_density=24.0, rays=64)
    doc = pygltflib.GLTF2().load(str(out))
    boxes = builder.info["boxes"]
    meshes = {name: doc.nodes[node].mesh for name, node in boxes.items()}
    assert len(set(meshes.values())) == 3  # each instance got its own mesh
    # Each box's lightmap triangles, drawn on its page, cover texels no other box covers.
    buffers = [doc.binary_blob()]
    masks = {}
    for name, mesh in meshes.items():
        prim = doc.meshes[mesh].primitives[0]
        ext = carried(doc.materials[prim.material])
        page = doc.textures[ext["index"]].source
        size = _image_size(doc, page)
        uv = page_uv(read_accessor(doc, buffers, getattr(prim.attributes,
                                                         f"TEXCOORD_{ext['texCoord']}")), ext)
        corners = read_accessor(doc, buffers, prim.indices).reshape(-1, 3)
        mask = Image.new("1", size)
        draw = ImageDraw.Draw(mask)
        for triangle in uv[corners] * size:
            draw.polygon([tuple(p) for p in triangle], fill=1)
        masks[name] = (page, np.asarray(mask))
    assert all(mask.sum() > 20 for _, mask in masks.values())
    for a in masks:
        for b in masks:
            if a < b and masks[a][0] == masks[b][0]:
                shared = (masks[a][1] & masks[b][1]).sum()
                assert shared == 0, f"{a} and {b} share {shared} lightmap texels"


def _image_size(doc, image):
    """(width, height) of an image embedded in a .glb's binary chunk."""
    view = doc.bufferViews[doc.images[image].bufferView]
    blob = doc.binary_blob()[view.byteOffset:view.byteOffset + view.byteLength]
    return Image.open(io.BytesIO(blob)).size


def test_instances_differ_where_their_surroundings_differ(tmp_path):
    from baker.pipeline.full import compute
    from baker.image.compose import effective_r_ave

    builder = three_instances()
    scene = load(saved(builder, tmp_path))
    done = compute(scene, baker.Settings(texel_density=24.0, rays=64, d_max=0.5))
    w = done.terms.obscurance(effective_r_ave(done.ambient, "sqrt")).mean(axis=1)
    node_of = np.array([scene.instances[i].node for i in done.texels.instance()])
    up = done.texels.geometric_normal()[:, 1] > 0.9  # the boxes' top faces
    mean = {name: w[(node_of == node) & up].mean() for name, node in builder.info["boxes"].items()}
    assert mean["open"] > mean["corner"] + 0.02
    assert mean["open"] > mean["shelf"] + 0.1


def test_gltf_in_gltf_out_with_its_bin(tmp_path):
    source = vase_room().save(tmp_path / "room.gltf")
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    out = out_dir / "room_baked.gltf"
    baker.bake(source, out, baker.Settings(**FAST), lightmaps_dir=tmp_path / "pages")
    assert (out_dir / "room_baked.bin").exists()
    assert _new_problems(source, out) == {}
    pages = sorted((tmp_path / "pages").glob("*.png"))
    assert pages and Image.open(pages[0]).size[0] > 8


@pytest.mark.parametrize("name", sorted(REAL_SCENES))
def test_real_scenes_bake_and_validate(tmp_path, name):
    source = REAL_SCENES[name]
    out = tmp_path / (name + source.suffix)
    result = baker.bake(source, out, baker.Settings(page_size=256, rays=8))
    assert _new_problems(source, out) == {}
    if result.texels:
        assert _lightmap_texcoords_exist(out) >= 1


def test_real_scene_facts_show_in_the_plan(tmp_path):
    instancing = baker.bake(REAL_SCENES["SimpleInstancing"], tmp_path / "i.glb",
                            baker.Settings(page_size=64, rays=4))
    reasons = [r for _, r in instancing.plan.left_out]
    assert sum("GPU-instanced" in r for r in reasons) == 125
    lamp = baker.bake(REAL_SCENES["LightsPunctualLamp"], tmp_path / "l.gltf",
                      baker.Settings(page_size=256, rays=4))
    assert "punctual lights" in lamp.plan.stages
    multi = baker.bake(REAL_SCENES["MultiUVTest"], tmp_path / "m.glb",
                       baker.Settings(page_size=128, rays=4))
    # its second UV set moves up so that the lightmap is TEXCOORD_1, where Hubs reads it
    assert any("TEXCOORD_1 moved up" in note for note in multi.report["notes"])
    document = pygltflib.GLTF2.load(str(tmp_path / "m.glb"))
    for material in document.materials:
        if carried(material) is not None:
            assert carried(material)["texCoord"] == 1


def test_files_written_beside_the_output_get_the_usual_permissions(tmp_path):
    """The state, its timing record, the report and the page files are written through a
    temporary file (created 0600) and renamed: they end with 0666 less the umask, like the
    output itself, so that others in an asset pipeline can read them."""
    import os
    import stat

    mask = os.umask(0o022)
    try:
        source, out, _ = _bake(cornell_box(), tmp_path)
        baker.bake(source, tmp_path / "second.glb", baker.Settings(**FAST),
                   lightmaps_dir=tmp_path / "pages")
    finally:
        os.umask(mask)
    written = [out, tmp_path / "out.glb.bake", tmp_path / "out.glb.bake.json",
               tmp_path / "report.json", *sorted((tmp_path / "pages").iterdir())]
    for path in written:
        assert stat.S_IMODE(path.stat().st_mode) == 0o644, path


def test_the_bake_in_memory_stage_by_stage_gives_the_bytes_of_baker_bake(tmp_path):
    """``baker.load`` → ``baker.compute`` → ``baker.encode`` → ``baker.write``, the public
    stages, write the file ``baker.bake`` writes, byte for byte."""
    source = saved(cornell_box(), tmp_path)
    settings = baker.Settings(rays=4, page_size=128)
    baker.bake(source, tmp_path / "whole.glb", settings, state=False)
    done = baker.compute(baker.load(source), settings)
    baker.write(done, baker.encode(done), tmp_path / "staged.glb")
    assert (tmp_path / "staged.glb").read_bytes() == (tmp_path / "whole.glb").read_bytes()
