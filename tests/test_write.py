"""baker.output.write: lightmap UVs, images and materials added to the input glTF, nothing else changed.

The scenes are built by hand (a small glTF document, its ``Scene``, a hand-made ``Atlas`` with two
pages and PNG pages from pillow), so these tests do not depend on the loader or the unwrapper.
Every output must pass the Khronos glTF Validator without errors or warnings.
"""

from __future__ import annotations

import io
import json
import os
import struct
from pathlib import Path
from urllib.parse import unquote

import numpy as np
import pygltflib
import pytest
from PIL import Image as PILImage

from baker.run import atomic as staging
from baker.atlas.layout import Atlas, InstanceUV
from baker.image.encode import EncodedPage
from baker.errors import OutputError
from baker.gltf.container import read_document
from baker.gltf.scene import Image, Instance, Material, Primitive, Scene
from baker.output.write import WriteOptions, _shift_texcoords, write

import gltf_validator

FLOAT, UBYTE, USHORT, UINT = 5126, 5121, 5123, 5125
DTYPES = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}

# mesh 0: a quad with normals, UVs, 8-bit vertex colours and one (sparse) morph target
QUAD_POSITIONS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
QUAD_NORMALS = np.tile(np.array([0, 0, 1], np.float32), (4, 1))
QUAD_UV0 = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
QUAD_COLORS = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [10, 20, 30]], np.uint8)
QUAD_TRIANGLES = np.array([[0, 1, 2], [0, 2, 3]], np.int64)
MORPH_INDICES = np.array([1, 2], np.uint16)
MORPH_VALUES = np.array([[0, 0, 0.5], [0, 0, 0.25]], np.float32)
QUAD_MORPH = np.zeros((4, 3), np.float32)
QUAD_MORPH[MORPH_INDICES] = MORPH_VALUES
# mesh 1: a quad that already has two UV sets
TWO_UV1 = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]], np.float32)
# mesh 2: non-indexed triangles, positions only, no material
BARE_POSITIONS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
                          np.float32)
BARE_TRIANGLES = np.arange(6, dtype=np.int64).reshape(2, 3)


class _Doc:
    """A glTF JSON dict and its binary chunk under construction."""

    def __init__(self):
        self.blob = bytearray()
        self.json = {"asset": {"version": "2.0", "generator": "test_write",
                               "extras": {"author": "tests"}},
                     "bufferViews": [], "accessors": []}

    def view(self, payload: bytes, target=None, stride=None) -> int:
        self.blob += b"\0" * (-len(self.blob) % 4)
        view = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(payload)}
        if target:
            view["target"] = target
        if stride:
            view["byteStride"] = stride
        self.blob += payload
        self.json["bufferViews"].append(view)
        return len(self.json["bufferViews"]) - 1

    def accessor(self, values: np.ndarray, ctype: int, kind: str, target=34962, bounds=False,
                 normalized=False, stride=None) -> int:
        values = np.asarray(values, DTYPES[ctype]).reshape(len(values), -1)
        payload = values.tobytes()
        if stride:
            padded = np.zeros((len(values), stride), np.uint8)
            padded[:, :values.shape[1] * values.itemsize] = values.view(np.uint8)
            payload = padded.tobytes()
        accessor = {"bufferView": self.view(payload, target, stride), "componentType": ctype,
                    "count": len(values), "type": kind}
        if normalized:
            accessor["normalized"] = True
        if bounds:
            accessor["min"] = values.min(0).tolist()
            accessor["max"] = values.max(0).tolist()
        self.json["accessors"].append(accessor)
        return len(self.json["accessors"]) - 1

    def gltf(self, path: Path) -> None:
        """Write as .gltf with the buffer in ``<stem>.bin`` beside it."""
        self.json["buffers"] = [{"byteLength": len(self.blob), "uri": path.stem + ".bin"}]
        path.with_suffix(".bin").write_bytes(bytes(self.blob))
        path.write_text(json.dumps(self.json))

    def glb(self, path: Path) -> None:
        self.json["buffers"] = [{"byteLength": len(self.blob)}]
        text = json.dumps(self.json).encode()
        text += b" " * (-len(text) % 4)
        blob = bytes(self.blob) + b"\0" * (-len(self.blob) % 4)
        body = struct.pack("<II", len(text), 0x4E4F534A) + text
        body += struct.pack("<II", len(blob), 0x004E4942) + blob
        path.write_bytes(struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body)


def _input_doc() -> _Doc:
    doc = _Doc()
    a = doc.accessor
    pos = a(QUAD_POSITIONS, FLOAT, "VEC3", bounds=True)
    nor = a(QUAD_NORMALS, FLOAT, "VEC3")
    uv0 = a(QUAD_UV0, FLOAT, "VEC2")
    col = a(QUAD_COLORS, UBYTE, "VEC3", normalized=True, stride=4)
    idx = a(QUAD_TRIANGLES.ravel(), USHORT, "SCALAR", target=34963)
    morph = {"bufferView": None, "componentType": FLOAT, "count": 4, "type": "VEC3",
             "min": QUAD_MORPH.min(0).tolist(), "max": QUAD_MORPH.max(0).tolist(),
             "sparse": {"count": 2,
                        "indices": {"bufferView": doc.view(MORPH_INDICES.tobytes()),
                                    "componentType": USHORT},
                        "values": {"bufferView": doc.view(MORPH_VALUES.tobytes())}}}
    del morph["bufferView"]
    doc.json["accessors"].append(morph)
    morph = len(doc.json["accessors"]) - 1
    uv1 = a(TWO_UV1, FLOAT, "VEC2")
    bare = a(BARE_POSITIONS, FLOAT, "VEC3", bounds=True)
    texture = doc.view(_png(50))
    doc.json.update({
        "images": [{"bufferView": texture, "mimeType": "image/png"}],
        "textures": [{"source": 0}],
        "extensionsUsed": ["KHR_lights_punctual", "KHR_texture_transform"],
        "extensions": {"KHR_lights_punctual": {"lights": [{"type": "point", "intensity": 5}]}},
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2, 3, 4], "name": "level"}],
        "nodes": [
            {"mesh": 0, "name": "quad A", "extras": {"tag": "a"},
             "extensions": {"KHR_lights_punctual": {"light": 0}}},
            {"mesh": 0, "name": "quad B", "translation": [2, 0, 0]},
            {"mesh": 1, "name": "two uv", "translation": [0, 2, 0]},
            {"mesh": 2, "name": "mirrored", "scale": [-1, 1, 1], "translation": [4, 0, 0]},
            {"mesh": 0, "name": "quad unbaked", "translation": [0, -2, 0]},
        ],
        "meshes": [
            {"name": "quad", "weights": [0.0], "extras": {"targetNames": ["bulge"]},
             "primitives": [{"attributes": {"POSITION": pos, "NORMAL": nor, "TEXCOORD_0": uv0,
                                            "COLOR_0": col},
                             "indices": idx, "material": 0, "targets": [{"POSITION": morph}]}]},
            {"name": "two uv",
             "primitives": [{"attributes": {"POSITION": pos, "TEXCOORD_0": uv0,
                                            "TEXCOORD_1": uv1},
                             "indices": idx, "material": 1}]},
            {"name": "bare", "primitives": [{"attributes": {"POSITION": bare}}]},
        ],
        "materials": [
            {"name": "wall", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.7, 0.6, 1]},
             "extras": {"keep": True}},
            {"name": "floor", "doubleSided": True,  # textures on both UV sets
             "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}},
             "occlusionTexture": {"index": 0, "texCoord": 1},
             "emissiveTexture": {"index": 0, "extensions": {
                 "KHR_texture_transform": {"texCoord": 1, "scale": [2, 2]}}}},
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}],
    })
    return doc


def _input_glb(path: Path) -> None:
    _input_doc().glb(path)


def _material(index, name) -> Material:
    return Material(index=index, name=name, base_color=np.ones(4), base_color_texture=None,
                    emissive=np.zeros(3), emissive_texture=None)


def _scene(path: Path) -> Scene:
    """The Scene a loader would make of ``_input_glb``; nodes 0–3 baked, node 4 not."""
    document = read_document(path)
    f64 = np.float64
    primitives = (
        Primitive(mesh=0, index=0, positions=QUAD_POSITIONS.astype(f64),
                  normals=QUAD_NORMALS.astype(f64), texcoords=(QUAD_UV0.astype(f64),),
                  colors=None, triangles=QUAD_TRIANGLES, material=0, has_morph_targets=True),
        Primitive(mesh=1, index=0, positions=QUAD_POSITIONS.astype(f64), normals=None,
                  texcoords=(QUAD_UV0.astype(f64), TWO_UV1.astype(f64)), colors=None,
                  triangles=QUAD_TRIANGLES, material=1),
        Primitive(mesh=2, index=0, positions=BARE_POSITIONS.astype(f64), normals=None,
                  texcoords=(), colors=None, triangles=BARE_TRIANGLES, material=2),
    )

    def moved(x, y, sx=1.0):
        m = np.eye(4)
        m[0, 0], m[0, 3], m[1, 3] = sx, x, y
        return m

    instances = (
        Instance(node=0, primitive=0, world=moved(0, 0)),
        Instance(node=1, primitive=0, world=moved(2, 0)),
        Instance(node=2, primitive=1, world=moved(0, 2)),
        Instance(node=3, primitive=2, world=moved(4, 0, -1.0)),
        Instance(node=4, primitive=0, world=moved(0, -2), baked=False, reason="test"),
    )
    materials = (_material(0, "wall"), _material(1, "floor"), _material(None, "default"))
    buffers = tuple(document.binary_blob() if b.uri is None else (path.parent / b.uri).read_bytes()
                    for b in document.buffers)
    images = tuple(Image(pixels=np.full((1, 1, 4), 255, np.uint8),
                         data=(path.parent / image.uri).read_bytes() if image.uri else None)
                   for image in document.images or [])
    return Scene(path=path, document=document, primitives=primitives, instances=instances,
                 materials=materials, images=images, buffers=buffers)


def _atlas() -> Atlas:
    rng = np.random.default_rng(7)
    return Atlas(width=8, height=8, page_count=2, texel_density=8.0, padding=1, instances=(
        # quad A: split at the diagonal, one triangle on each page
        InstanceUV(instance=0, vertices=np.array([0, 1, 2, 0, 2, 3]),
                   triangles=np.array([[0, 1, 2], [3, 4, 5]]), uv=rng.random((6, 2)),
                   pages=np.array([0, 1])),
        # quad B: page 1, its second triangle without area (goes with page 1)
        InstanceUV(instance=1, vertices=np.array([3, 2, 1, 0]),
                   triangles=np.array([[3, 2, 1], [3, 1, 0]]), uv=rng.random((4, 2)),
                   pages=np.array([1, -1])),
        # the two-UV quad, its corners rotated (same winding)
        InstanceUV(instance=2, vertices=np.array([0, 1, 2, 3]),
                   triangles=np.array([[1, 2, 0], [0, 2, 3]]), uv=rng.random((4, 2)),
                   pages=np.array([0, 0])),
        # the mirrored bare mesh: the unwrapper saw it with two corners swapped
        InstanceUV(instance=3, vertices=np.array([0, 1, 2, 3, 4, 5]),
                   triangles=np.array([[0, 2, 1], [3, 5, 4]]), uv=rng.random((6, 2)),
                   pages=np.array([0, 0])),
    ))


def _png(value: int, mode: str = "RGB") -> bytes:
    stream = io.BytesIO()
    PILImage.new(mode, (8, 8), value if mode == "L" else (value, value // 2, 7)).save(
        stream, format="PNG")
    return stream.getvalue()


def _pages(occlusion: bool = False) -> list[EncodedPage]:
    return [EncodedPage(png=_png(200), intensity=2.5,
                        occlusion_png=_png(180, "L") if occlusion else None),
            EncodedPage(png=_png(90), intensity=1.0,
                        occlusion_png=_png(120, "L") if occlusion else None)]


def _read(document: pygltflib.GLTF2, blob: bytes, index: int) -> np.ndarray:
    """An output accessor as stored (dense, strided): (count, components)."""
    accessor = document.accessors[index]
    view = document.bufferViews[accessor.bufferView]
    dtype = np.dtype(DTYPES[accessor.componentType])
    components = COMPONENTS[accessor.type]
    stride = view.byteStride or dtype.itemsize * components
    start = (view.byteOffset or 0) + (accessor.byteOffset or 0)
    return np.ndarray((accessor.count, components), dtype, buffer=blob, offset=start,
                      strides=(stride, dtype.itemsize)).copy()


def _load(path: Path) -> tuple[pygltflib.GLTF2, bytes]:
    document = pygltflib.GLTF2.load(str(path))
    if path.suffix == ".glb":
        return document, document.binary_blob()
    return document, (path.parent / unquote(document.buffers[0].uri)).read_bytes()


def _assert_valid(path: Path) -> dict:
    report = gltf_validator.validate(path)
    assert not gltf_validator.issue_codes(report, 0), gltf_validator.describe(report, 0)
    assert not gltf_validator.issue_codes(report, 1), gltf_validator.describe(report, 1)
    return report


@pytest.fixture
def baked(tmp_path):
    source = tmp_path / "in" / "level.glb"
    source.parent.mkdir()
    _input_glb(source)
    scene = _scene(source)
    output = tmp_path / "level_baked.glb"
    info = write(scene, _atlas(), _pages(), output, WriteOptions())
    return source, output, info


def test_input_is_valid(tmp_path):
    path = tmp_path / "level.glb"
    _input_glb(path)
    _assert_valid(path)


def test_output_validates_and_records_encoding(baked):
    _, output, info = baked
    report = _assert_valid(output)
    assert report["info"]["maxUVs"] == 3
    document, _ = _load(output)
    assert "MOZ_lightmap" in document.extensionsUsed
    assert "MOZ_lightmap" not in (document.extensionsRequired or [])
    assert document.asset.extras["author"] == "tests"
    assert document.asset.extras["baker"]["lightmap_encoding"] == "linear"
    assert document.asset.extras["baker"]["lightmap_extension"] == "MOZ_lightmap"
    assert info.lightmap_texcoord == {0: 1, 1: 1, 2: 1, 3: 1}
    assert any("TEXCOORD_1 moved up" in note for note in info.notes)
    assert len(document.buffers) == 1


def test_untouched_parts_survive(baked):
    _, output, _ = baked
    document, _ = _load(output)
    assert document.nodes[0].extras == {"tag": "a"}
    assert [n.name for n in document.nodes] == ["quad A", "quad B", "two uv", "mirrored",
                                               "quad unbaked"]
    assert document.cameras[0].perspective.yfov == 0.8
    assert document.nodes[4].mesh == 0  # the unbaked node keeps the original mesh
    original = document.meshes[0].primitives[0]
    assert original.material == 0 and original.attributes.TEXCOORD_1 is None
    assert document.materials[0].extras == {"keep": True}


def test_each_baked_node_has_its_own_mesh(baked):
    _, output, _ = baked
    document, _ = _load(output)
    meshes = [document.nodes[i].mesh for i in range(4)]
    assert len(set(meshes)) == 4
    assert 0 not in meshes  # mesh 0 is shared with the unbaked node: copied
    assert meshes[2] == 1  # mesh 1 is used by node 2 only: rewritten in place
    assert document.meshes[meshes[0]].weights == [0.0]
    assert document.meshes[meshes[0]].extras == {"targetNames": ["bulge"]}


def test_split_by_page_and_lightmap_material(baked):
    _, output, _ = baked
    document, _ = _load(output)
    quad_a = document.meshes[document.nodes[0].mesh].primitives
    quad_b = document.meshes[document.nodes[1].mesh].primitives
    assert len(quad_a) == 2 and len(quad_b) == 1
    for primitive, page in zip(quad_a + quad_b, (0, 1, 1)):
        material = document.materials[primitive.material]
        lightmap = material.extensions["MOZ_lightmap"]
        assert material.name == f"wall (lightmap page {page})"
        assert material.pbrMetallicRoughness.baseColorFactor == [0.8, 0.7, 0.6, 1]
        assert lightmap["intensity"] == (2.5, 1.0)[page]
        image = document.images[document.textures[lightmap["index"]].source]
        assert image.mimeType == "image/png" and image.name == f"lightmap page {page}"
        assert primitive.mode == 4
    bare = document.meshes[document.nodes[3].mesh].primitives[0]
    assert document.materials[bare.material].name == "default (lightmap page 0)"


def test_texcoord_names_a_set_the_primitive_has(baked):
    _, output, _ = baked
    document, _ = _load(output)
    for node in document.nodes[:4]:
        for primitive in document.meshes[node.mesh].primitives:
            texcoord = document.materials[primitive.material].extensions["MOZ_lightmap"][
                "texCoord"]
            assert getattr(primitive.attributes, f"TEXCOORD_{texcoord}") is not None


def test_attributes_are_gathered_through_vertices(baked):
    _, output, _ = baked
    document, blob = _load(output)
    atlas = _atlas()
    for node, unwrap in ((0, atlas.instances[0]), (1, atlas.instances[1])):
        corners_seen = 0
        for primitive in document.meshes[document.nodes[node].mesh].primitives:
            indices = _read(document, blob, primitive.indices)[:, 0].reshape(-1, 3)
            positions = _read(document, blob, primitive.attributes.POSITION)
            lightmap_uv = _read(document, blob, primitive.attributes.TEXCOORD_1)
            # which split vertex each output vertex is: match on the lightmap UVs
            split = np.array([np.flatnonzero(np.all(unwrap.uv.astype(np.float32) == uv, 1))[0]
                              for uv in lightmap_uv])
            original = unwrap.vertices[split]
            np.testing.assert_array_equal(positions, QUAD_POSITIONS[original])
            np.testing.assert_array_equal(_read(document, blob, primitive.attributes.NORMAL),
                                          QUAD_NORMALS[original])
            np.testing.assert_array_equal(_read(document, blob, primitive.attributes.TEXCOORD_0),
                                          QUAD_UV0[original])
            np.testing.assert_array_equal(_read(document, blob, primitive.attributes.COLOR_0),
                                          QUAD_COLORS[original])
            morph = _read(document, blob, primitive.targets[0]["POSITION"])
            np.testing.assert_array_equal(morph, QUAD_MORPH[original])
            assert document.accessors[primitive.attributes.COLOR_0].normalized
            # the triangles are the file's triangles, corners in the file's order
            for triangle in original[indices]:
                assert any(np.array_equal(np.roll(triangle, r), t)
                           for t in QUAD_TRIANGLES for r in range(3))
            corners_seen += indices.size
        assert corners_seen == 6  # no triangle lost, page -1 included


def test_mirrored_instance_keeps_file_winding(baked):
    _, output, _ = baked
    document, blob = _load(output)
    primitive = document.meshes[document.nodes[3].mesh].primitives[0]
    indices = _read(document, blob, primitive.indices)[:, 0].reshape(-1, 3)
    positions = _read(document, blob, primitive.attributes.POSITION)
    np.testing.assert_array_equal(positions[indices], BARE_POSITIONS[BARE_TRIANGLES])
    # no TEXCOORD_0 in the input: the lightmap set is written as TEXCOORD_0 and TEXCOORD_1
    assert primitive.attributes.TEXCOORD_0 is not None
    assert primitive.attributes.TEXCOORD_1 is not None


def test_existing_texcoord_1_moves_to_2_and_lightmap_goes_to_1(baked):
    """Hubs reads lightmaps from TEXCOORD_1 whatever texCoord says: the input's second set
    moves up, and every texture of the material copy that read it follows."""
    _, output, _ = baked
    document, blob = _load(output)
    primitive = document.meshes[document.nodes[2].mesh].primitives[0]
    material = document.materials[primitive.material]
    assert material.extensions["MOZ_lightmap"]["texCoord"] == 1
    assert material.doubleSided
    assert material.occlusionTexture.texCoord == 2
    assert material.pbrMetallicRoughness.baseColorTexture.texCoord in (None, 0)
    assert material.emissiveTexture.extensions["KHR_texture_transform"]["texCoord"] == 2
    positions = _read(document, blob, primitive.attributes.POSITION)
    order = [np.flatnonzero(np.all(QUAD_POSITIONS == p, 1))[0] for p in positions]
    uv2 = _read(document, blob, primitive.attributes.TEXCOORD_2)
    assert uv2.tobytes() == TWO_UV1[order].tobytes()
    lightmap = _read(document, blob, primitive.attributes.TEXCOORD_1)
    np.testing.assert_array_equal(lightmap, _atlas().instances[2].uv[order].astype(np.float32))
    # the input's material, which an unbaked primitive could still use, is unchanged
    assert document.materials[1].occlusionTexture.texCoord == 1


@pytest.mark.parametrize("extensions", [[1], 5, "x"])
def test_a_texture_reference_whose_extensions_are_not_an_object_still_moves_up(extensions):
    """An extension's own textureInfo (unchecked JSON, here KHR_materials_clearcoat's) whose
    ``extensions`` is not an object: its texCoord moves up with the others and the value
    stays. The shift read it with ``.get`` and ended the bake in an internal error."""
    material = {"occlusionTexture": {"index": 1, "texCoord": 1},
                "extensions": {"KHR_materials_clearcoat": {"clearcoatTexture": {
                    "index": 0, "texCoord": 1, "extensions": extensions}}}}
    _shift_texcoords(material)
    clearcoat = material["extensions"]["KHR_materials_clearcoat"]["clearcoatTexture"]
    assert clearcoat == {"index": 0, "texCoord": 2, "extensions": extensions}
    assert material["occlusionTexture"]["texCoord"] == 2


def test_texcoord_sets_stay_where_variants_would_break(tmp_path):
    """A primitive with KHR_materials_variants keeps its sets (its variants' materials point at
    them); the lightmap goes to the first free set and a note says Hubs will not read it."""
    doc = _input_doc()
    primitive = doc.json["meshes"][1]["primitives"][0]
    primitive["extensions"] = {"KHR_materials_variants": {"mappings": [
        {"material": 0, "variants": [0]}]}}
    doc.json["extensions"]["KHR_materials_variants"] = {"variants": [{"name": "plain"}]}
    doc.json["extensionsUsed"].append("KHR_materials_variants")
    source = tmp_path / "level.glb"
    doc.glb(source)
    output = tmp_path / "out.glb"
    info = write(_scene(source), _atlas(), _pages(), output, WriteOptions())
    _assert_valid(output)
    document, blob = _load(output)
    primitive = document.meshes[document.nodes[2].mesh].primitives[0]
    assert document.materials[primitive.material].extensions["MOZ_lightmap"]["texCoord"] == 2
    assert _read(document, blob, primitive.attributes.TEXCOORD_1).tobytes() != b""
    assert info.lightmap_texcoord[2] == 2
    assert any("KHR_materials_variants" in note and "Hubs" in note for note in info.notes)


@pytest.mark.parametrize("baked_lights", ["remove", "keep", "indirect"])
def test_baked_lights_are_removed_or_kept(tmp_path, baked_lights):
    source = tmp_path / "level.glb"
    _input_glb(source)
    output = tmp_path / "out.glb"
    info = write(_scene(source), _atlas(), _pages(), output,
                 WriteOptions(baked_lights=baked_lights))
    _assert_valid(output)
    document, _ = _load(output)
    kept = baked_lights != "remove"
    assert ("KHR_lights_punctual" in (document.extensions or {})) == kept
    assert ("KHR_lights_punctual" in document.extensionsUsed) == kept
    assert ("KHR_lights_punctual" in (document.nodes[0].extensions or {})) == kept
    assert document.asset.extras["baker"]["baked_lights"] == baked_lights
    assert any("light(s) removed" in note for note in info.notes) == (not kept)


def test_occlusion_also_and_occlusion_carrier(tmp_path):
    source = tmp_path / "level.glb"
    _input_glb(source)
    scene = _scene(source)
    for mode in ("also", "only"):
        output = tmp_path / f"level_{mode}.glb"
        options = (WriteOptions(occlusion="also") if mode == "also" else
                   WriteOptions(carrier="occlusion", baked_lights="keep"))
        write(scene, _atlas(), _pages(occlusion=True), output, options)
        _assert_valid(output)
        document, _ = _load(output)
        for node in document.nodes[:4]:
            for primitive in document.meshes[node.mesh].primitives:
                material = document.materials[primitive.material]
                occlusion = material.occlusionTexture
                assert getattr(primitive.attributes, f"TEXCOORD_{occlusion.texCoord}") is not None
                assert ("MOZ_lightmap" in material.extensions) == (mode == "also")
        assert ("MOZ_lightmap" in (document.extensionsUsed or [])) == (mode == "also")


def test_gltf_output_writes_bin_and_round_trips(tmp_path, baked):
    source, glb_output, _ = baked
    scene = _scene(source)
    output = tmp_path / "out" / "level baked.gltf"
    output.parent.mkdir()
    write(scene, _atlas(), _pages(), output, WriteOptions(encoding="srgb"))
    assert (output.parent / "level baked.bin").is_file()
    assert sorted(p.name for p in output.parent.iterdir()) == ["level baked.bin",
                                                              "level baked.gltf"]
    _assert_valid(output)
    document, blob = _load(output)
    assert document.asset.extras["baker"]["lightmap_encoding"] == "srgb"
    glb_document, glb_blob = _load(glb_output)
    assert len(document.accessors) == len(glb_document.accessors)
    for i in range(len(document.accessors)):
        if document.accessors[i].bufferView is None:
            continue  # the input's sparse morph target, kept as it was
        np.testing.assert_array_equal(_read(document, blob, i), _read(glb_document, glb_blob, i))


def _textured_gltf(source_dir: Path) -> Path:
    """``source_dir``/level.gltf whose base colour texture is the file textures/brick.png."""
    (source_dir / "textures").mkdir(parents=True)
    (source_dir / "textures" / "brick.png").write_bytes(_png(128))
    doc = _input_doc()
    doc.json["images"] = [{"uri": "textures/brick.png"}]
    doc.json["textures"] = [{"source": 0}]
    doc.json["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    source = source_dir / "level.gltf"
    doc.gltf(source)
    return source


def test_gltf_output_copies_referenced_images(tmp_path):
    source = _textured_gltf(tmp_path / "src")
    _assert_valid(source)
    scene = _scene(source)
    output = tmp_path / "out" / "level.gltf"
    output.parent.mkdir()
    write(scene, _atlas(), _pages(), output, WriteOptions())
    # a name baker makes, never the input's path (which could lead anywhere under the output)
    assert sorted(p.name for p in output.parent.iterdir()) == ["level.bin", "level.gltf",
                                                              "level_image0.png"]
    assert (output.parent / "level_image0.png").read_bytes() == _png(128)
    assert json.loads(output.read_text())["images"][0]["uri"] == "level_image0.png"
    _assert_valid(output)


@pytest.mark.parametrize("beside", [True, False])
def test_a_glb_output_holds_the_images_its_input_names_by_uri(tmp_path, beside):
    """A .gltf whose texture is a file beside it, baked to a .glb (in its folder or another):
    the .glb is one file, its image a bufferView with its mimeType, its bytes the file's."""
    source = _textured_gltf(tmp_path / "src")
    output = (source.parent if beside else tmp_path / "out") / "level_baked.glb"
    output.parent.mkdir(exist_ok=True)
    before = sorted(p.name for p in output.parent.iterdir())
    write(_scene(source), _atlas(), _pages(), output, WriteOptions())
    assert sorted(p.name for p in output.parent.iterdir()) == sorted(before + [output.name])
    data = output.read_bytes()
    gltf = json.loads(data[20:20 + struct.unpack("<I", data[12:16])[0]])
    (image,) = [i for i in gltf["images"] if i.get("name") is None]
    assert "uri" not in image and image["mimeType"] == "image/png"
    view = gltf["bufferViews"][image["bufferView"]]
    blob = data[28 + struct.unpack("<I", data[12:16])[0]:]
    assert blob[view.get("byteOffset", 0):][:view["byteLength"]] == _png(128)
    _assert_valid(output)


def test_missing_folder_raises_and_writes_nothing(tmp_path, baked):
    source, _, _ = baked
    output = tmp_path / "nowhere" / "level.glb"
    with pytest.raises(OutputError) as raised:
        write(_scene(source), _atlas(), _pages(), output, WriteOptions())
    assert str(output.parent) in str(raised.value)
    assert raised.value.fix
    assert not output.parent.exists()


def test_failure_midway_leaves_existing_output_intact(tmp_path, baked, monkeypatch):
    source, _, _ = baked
    output = tmp_path / "level.gltf"
    bin_path = tmp_path / "level.bin"
    output.write_text("old gltf")
    bin_path.write_bytes(b"old bin")
    before = set(tmp_path.iterdir())

    replace, calls = os.replace, []

    def failing_replace(src, dst):  # the .bin goes into place, then the .gltf fails
        calls.append(dst)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        replace(src, dst)

    monkeypatch.setattr(staging.os, "replace", failing_replace)
    with pytest.raises(OutputError):
        write(_scene(source), _atlas(), _pages(), output, WriteOptions())
    assert output.read_text() == "old gltf"
    assert bin_path.read_bytes() == b"old bin"
    assert set(tmp_path.iterdir()) == before  # no temporary left behind
    assert calls[:2] == [bin_path, output]  # the .bin was put back


def test_existing_output_is_replaced(tmp_path, baked):
    source, _, _ = baked
    output = tmp_path / "level.glb"
    output.write_bytes(b"old")
    write(_scene(source), _atlas(), _pages(), output, WriteOptions())
    _assert_valid(output)
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root ignores permissions")
def test_unwritable_folder_raises_output_error(tmp_path, baked):
    source, _, _ = baked
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        with pytest.raises(OutputError) as raised:
            write(_scene(source), _atlas(), _pages(), folder / "level.glb", WriteOptions())
        assert "permission" in str(raised.value)
    finally:
        folder.chmod(0o700)


def test_permission_error_becomes_output_error(tmp_path, baked, monkeypatch):
    source, _, _ = baked
    output = tmp_path / "level.glb"

    def refused(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    scene = _scene(source)
    monkeypatch.setattr(staging.os, "open", refused)
    with pytest.raises(OutputError) as raised:
        write(scene, _atlas(), _pages(), output, WriteOptions())
    assert "permission" in str(raised.value) and str(output.parent) in raised.value.fix
    assert not output.exists()


@pytest.mark.parametrize("height, width", [(1, 1), (1, 7), (5, 3), (64, 10), (65, 10), (200, 130)])
def test_png_bytes_decode_to_the_image(height, width):
    """encode.png_bytes' own PNG (Up filter, bands deflated apart and joined) decodes with PIL
    to the very pixels, at band-sized, smaller and ragged heights, the same bytes every time."""
    from baker.image.encode import png_bytes

    rng = np.random.default_rng(height * 1000 + width)
    pixels = np.cumsum(rng.integers(0, 4, (height, width, 3)), axis=0).astype(np.uint8)
    png = png_bytes(pixels)
    decoded = PILImage.open(io.BytesIO(png))
    assert decoded.mode == "RGB"
    assert np.array_equal(np.asarray(decoded), pixels)
    assert png_bytes(pixels.copy()) == png


def test_compiled_quantiser_gives_quantise_bytes():
    """``encode._quantise_linear`` (one pass over a page) gives ``quantise``'s bytes: on the
    values either side of every code's rounding edge, out of range, and at random, for a few
    page scales."""
    from baker.image.encode import _quantise_linear, quantise

    rng = np.random.default_rng(7)
    edges = ((np.arange(256)[:, None] + np.array([-0.5, 0.5])) / 255).ravel()
    edges = np.concatenate([edges, np.nextafter(edges, 2), np.nextafter(edges, -2)])
    values = np.concatenate([rng.random(300_000) * 1.4 - 0.2, edges, [-0.0, 1.0, 2.0]])
    values = values[:len(values) // 3 * 3].reshape(1, -1, 3)
    for scale in (1.0, 0.37, 5.0):
        out = np.empty(values.shape, np.uint8)
        _quantise_linear(values * scale, scale, out)
        assert np.array_equal(out, quantise(values * scale / scale, "linear")), scale


def _glb_json(path: Path) -> dict:
    data = path.read_bytes()
    return json.loads(data[20:20 + struct.unpack("<I", data[12:16])[0]])


def test_instances_share_their_geometry_and_grow_the_output_by_little(tmp_path):
    """200 nodes of one box mesh: every instance's positions, normals and indices are written
    once and shared (one POSITION accessor in the whole file), so the output beyond its images
    grows by less than 1 KB per instance over the input (issue 43); it validates, and every
    instance keeps its own lightmap area."""
    import baker
    from assets.extreme_scenes import instanced_boxes

    count = 200
    source = instanced_boxes(count).save(tmp_path / "boxes.glb")
    out = tmp_path / "boxes_baked.glb"
    baker.bake(source, out, baker.Settings(texel_density=5.0, rays=4, d_max=0.5), state=False)
    data = _glb_json(out)
    primitives = [p for node in data["nodes"] if "mesh" in node
                  for p in data["meshes"][node["mesh"]]["primitives"]]
    assert len(primitives) == count
    assert len({p["attributes"]["POSITION"] for p in primitives}) == 1
    assert len({p["indices"] for p in primitives}) == 1
    images = sum(data["bufferViews"][image["bufferView"]]["byteLength"]
                 for image in data["images"])
    grown = out.stat().st_size - images - source.stat().st_size
    assert grown <= 1024 * count, grown / count
    report = gltf_validator.validate(out)
    assert not gltf_validator.issue_codes(report, gltf_validator.ERROR), \
        gltf_validator.describe(report, gltf_validator.ERROR)
    uvs = {p["attributes"]["TEXCOORD_1"] for p in primitives}
    copies = {p["material"] for p in primitives}
    assert len(uvs) * len(copies) >= count  # each instance reads its own place on the page


def test_an_instance_moved_as_a_block_reads_the_shared_uvs_through_a_transform(tmp_path):
    """Two instances of a box whose second's lightmap UVs are the first's scaled by 0.5 and
    moved (its charts packed as one block): it shares the first's UV accessor, and its material
    copy reads the page through a KHR_texture_transform that gives back its own UVs to 1e-6;
    the file validates and the preview reads the page where the viewer does."""
    import dataclasses

    from assets.extreme_scenes import instanced_boxes
    from baker.geometry.world import build_world
    from baker.gltf.load import load
    from baker.preview import read_lightmaps
    from tests.bakehelp import computed

    done = computed(instanced_boxes(2), tmp_path, texel_density=5.0, rays=4)
    first, second = done.atlas.instances
    moved = dataclasses.replace(second, vertices=first.vertices, triangles=first.triangles,
                                uv=first.uv * 0.5 + [0.25, 0.125], pages=first.pages)
    atlas = dataclasses.replace(done.atlas, instances=(first, moved))
    out = tmp_path / "out.glb"
    pages = [EncodedPage(png=_png(128), intensity=1.0)] * atlas.page_count
    write(done.scene, atlas, pages, out, WriteOptions(carrier="emissive", encoding="srgb"))
    data = _glb_json(out)
    (a,), (b,) = (data["meshes"][node["mesh"]]["primitives"]
                  for node in data["nodes"] if "mesh" in node)
    assert a["attributes"]["TEXCOORD_1"] == b["attributes"]["TEXCOORD_1"]
    info = data["materials"][b["material"]]["emissiveTexture"]
    transform = info["extensions"]["KHR_texture_transform"]
    np.testing.assert_allclose(transform["scale"], [0.5, 0.5], atol=1e-6)
    np.testing.assert_allclose(transform["offset"], [0.25, 0.125], atol=1e-6)
    assert "KHR_texture_transform" in data["extensionsUsed"]
    assert not gltf_validator.issue_codes(gltf_validator.validate(out), gltf_validator.ERROR)
    scene = load(out)
    world = build_world(scene)
    read = read_lightmaps(scene, world)
    tris = world.instance_triangles(1)
    expected = moved.uv[moved.triangles]
    np.testing.assert_allclose(read.uv[tris], expected.astype(np.float32), atol=1e-6)


def test_uv_transforms_are_found_only_where_the_uvs_moved_as_one_block():
    from baker.output.write import _uv_transform

    rng = np.random.default_rng(3)
    reference = rng.random((50, 2)).astype(np.float32)
    assert _uv_transform(reference, reference.astype(np.float64)) == {}
    found = _uv_transform(reference, reference * [0.5, 0.25] + [0.3, 0.6])
    np.testing.assert_allclose(found["scale"], [0.5, 0.25], atol=1e-6)
    np.testing.assert_allclose(found["offset"], [0.3, 0.6], atol=1e-6)
    shuffled = reference.astype(np.float64).copy()
    shuffled[:10] += 0.01  # one chart moved on its own
    assert _uv_transform(reference, shuffled) is None
    flat = reference.copy()
    flat[:, 1] = 0.5  # no extent on an axis: no scale to find
    assert _uv_transform(flat, flat * 2.0) is None


def test_a_page_s_vertices_and_rows_are_what_np_unique_gives():
    """``_compacted`` (the vertices a page's triangles use and the triangles as rows into them)
    is ``np.unique(..., return_inverse=True)`` of the page's triangles, on random primitives
    split over random pages."""
    from baker.output.write import _compacted

    rng = np.random.default_rng(11)
    for _ in range(200):
        count = int(rng.integers(1, 40))
        triangles = rng.integers(0, count, (int(rng.integers(0, 30)), 3))
        page_of = rng.integers(0, 3, len(triangles))
        page = int(rng.integers(0, 3))
        vertices, rows = _compacted(triangles, page_of, page, count)
        on_page = triangles[page_of == page]
        want, inverse = np.unique(on_page, return_inverse=True)
        assert np.array_equal(vertices, want)
        assert np.array_equal(rows, inverse.reshape(-1, 3))
