"""An index that names an object the file does not have is an InputError naming it, whether or
not a node uses the object that holds it (baker.gltf.references)."""

from __future__ import annotations

import json

import pytest

import baker
from assets.gltf_builder import GltfBuilder, box
from baker.cli.main import main
from baker.gltf.load import load


def _scene(tmp_path):
    """A .gltf of one textured box (so every kind of object is there) and its JSON."""
    import numpy as np

    b = GltfBuilder()
    texture = np.full((4, 4, 3), 200, np.uint8)
    b.node("box", b.shape_mesh("box", box((1.0, 1.0, 1.0)),
                               material=b.material("m", base_color_image=texture)))
    path = b.save(tmp_path / "scene.gltf")
    return path, json.loads(path.read_text())


def _unused_mesh(d, attributes):
    d["meshes"].append({"primitives": [{"attributes": attributes}]})
    return f"meshes[{len(d['meshes']) - 1}].primitives[0].attributes.POSITION"


# Each edit adds an object no node uses (or a field no load reads) holding a bad index, and
# returns the JSON path of that index and the array it names.
EDITS = {
    "accessor": lambda d: (_unused_mesh(d, {"POSITION": 7}), "accessors"),
    "bufferView": lambda d: (d["accessors"].append(
        {"bufferView": 40, "componentType": 5126, "count": 1, "type": "VEC3"})
        or f"accessors[{len(d['accessors']) - 1}].bufferView", "bufferViews"),
    "buffer": lambda d: (d["bufferViews"].append({"buffer": 3, "byteLength": 4})
                         or f"bufferViews[{len(d['bufferViews']) - 1}].buffer", "buffers"),
    "material": lambda d: (d["meshes"].append({"primitives": [
        {"attributes": {"POSITION": 0}, "material": 9}]})
        or f"meshes[{len(d['meshes']) - 1}].primitives[0].material", "materials"),
    "texture": lambda d: (d["materials"].append(
        {"pbrMetallicRoughness": {"baseColorTexture": {"index": 12}}})
        or f"materials[{len(d['materials']) - 1}].pbrMetallicRoughness.baseColorTexture.index",
        "textures"),
    "extension texture": lambda d: (d["materials"].append(
        {"extensions": {"KHR_materials_clearcoat": {"clearcoatTexture": {"index": 5}}}})
        or f"materials[{len(d['materials']) - 1}].extensions.KHR_materials_clearcoat"
           ".clearcoatTexture.index", "textures"),
    "image": lambda d: (d["textures"].append({"source": 4})
                        or f"textures[{len(d['textures']) - 1}].source", "images"),
    "sampler": lambda d: (d["textures"].append({"source": 0, "sampler": 6})
                          or f"textures[{len(d['textures']) - 1}].sampler", "samplers"),
    "variant material": lambda d: (d["meshes"][0]["primitives"][0].setdefault(
        "extensions", {}).update(KHR_materials_variants={"mappings": [
            {"material": 0, "variants": [0]}, {"material": 99, "variants": [1]}]})
        or "meshes[0].primitives[0].extensions.KHR_materials_variants.mappings[1].material",
        "materials"),
    "mesh": lambda d: (d["nodes"].append({"mesh": 8})
                       or f"nodes[{len(d['nodes']) - 1}].mesh", "meshes"),
    "node": lambda d: (d["nodes"].append({"children": [0, 30]})
                       or f"nodes[{len(d['nodes']) - 1}].children[1]", "nodes"),
    "camera": lambda d: (d["nodes"].append({"camera": 2})
                         or f"nodes[{len(d['nodes']) - 1}].camera", "cameras"),
    "skin": lambda d: (d["nodes"].append({"skin": 0})
                       or f"nodes[{len(d['nodes']) - 1}].skin", "skins"),
    "skin joint": lambda d: (d.setdefault("skins", []).append({"joints": [0, 77]})
                             or f"skins[{len(d['skins']) - 1}].joints[1]", "nodes"),
    "scene": lambda d: (d.update(scene=3) or "scene", "scenes"),
    "animation": lambda d: (d.setdefault("animations", []).append(
        {"channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
         "samplers": [{"input": 90, "output": 0}]})
        or f"animations[{len(d['animations']) - 1}].samplers[0].input", "accessors"),
}


@pytest.mark.parametrize("kind", list(EDITS))
def test_a_bad_index_in_an_unused_object_is_named(tmp_path, kind):
    path, document = _scene(tmp_path)
    where, target = EDITS[kind](document)
    path.write_text(json.dumps(document))
    with pytest.raises(baker.InputError) as raised:
        load(path)
    error = raised.value
    assert error.where == where and error.file == str(path)
    assert f"{where} → {target}[" in error.message and error.fix


@pytest.mark.parametrize("index", [0.0, 1.5, "0", True])
def test_an_index_that_is_not_an_integer_is_named_as_such(tmp_path, index):
    """A node's mesh given as 0.0, 1.5, "0" or true (the file has mesh 0): refused at it,
    saying it is not an integer, where "objects the file does not have" alone misled."""
    path, document = _scene(tmp_path)
    document["nodes"][0]["mesh"] = index
    path.write_text(json.dumps(document))
    with pytest.raises(baker.InputError) as raised:
        load(path)
    assert raised.value.where == "nodes[0].mesh"
    assert f"nodes[0].mesh → meshes[{index!r}] (not an integer; 1 meshes" in raised.value.message


def test_every_bad_index_is_counted_and_the_first_ones_named(tmp_path):
    path, document = _scene(tmp_path)
    wheres = [EDITS[kind](document)[0] for kind in ("accessor", "texture", "camera", "image",
                                                    "mesh", "sampler", "buffer")]
    path.write_text(json.dumps(document))
    with pytest.raises(baker.InputError) as raised:
        load(path)
    message = raised.value.message
    assert message.startswith("7 reference(s)") and message.endswith("and 2 more")
    assert sum(where in message for where in wheres) == 5


def test_the_issues_file_is_refused_and_nothing_is_written(tmp_path, capsys):
    """The issue's case: a mesh whose POSITION is accessor 7 in a file with no accessors baked
    with exit 0 into an output the Khronos validator rejects; now exit 1, nothing written."""
    path, document = _scene(tmp_path)
    _unused_mesh(document, {"POSITION": 7})
    path.write_text(json.dumps(document))
    before = sorted(p.name for p in tmp_path.iterdir())
    code = main(["bake", str(path), "-o", str(tmp_path / "baked.glb"), "--rays", "2",
                 "--page-size", "32"])
    err = capsys.readouterr().err
    assert code == 1 and "accessors[7]" in err and "fix:" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before
