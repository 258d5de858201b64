"""Tests of baker.gltf.load: glTF decoding, node flattening and the errors a technical artist sees.

Each test builds a small document with pygltflib objects (``Doc`` below), writes it to tmp_path and
checks numbers computed by hand. The real sample scenes in tests/scenes must all load.
"""

from __future__ import annotations

import base64
import dataclasses
import io
import json
import math
import struct
from pathlib import Path

import numpy as np
import pygltflib
import pytest
from PIL import Image as PILImage

from baker.gltf import container
from baker.errors import InputError
from baker.gltf.accessors import read_accessor
from baker.gltf.load import load
from baker.gltf.read_meshes import expand_triangles
from baker.gltf.scene import CLAMP_TO_EDGE, MIRRORED_REPEAT

from tests.bakehelp import SHARED_SCENES

SCENES = SHARED_SCENES

BYTE, UBYTE, SHORT, USHORT, UINT, FLOAT = 5120, 5121, 5122, 5123, 5125, 5126
DTYPES = {BYTE: "<i1", UBYTE: "<u1", SHORT: "<i2", USHORT: "<u2", UINT: "<u4", FLOAT: "<f4"}
TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}
TRIANGLE = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]


# ------------------------------------------------------------------------------------------------
# Building documents


class Doc:
    """A glTF document under construction: pygltflib objects plus one binary buffer."""

    def __init__(self):
        scenes = [pygltflib.Scene(nodes=[])]
        self.gltf = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0"), scenes=scenes, scene=0)
        self.blob = bytearray()

    def view(self, data: bytes, stride: int | None = None) -> int:
        """Append ``data`` (4-byte aligned) as a new bufferView; return its index."""
        self.blob += b"\0" * (-len(self.blob) % 4)
        view = pygltflib.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=len(data))
        view.byteStride = stride
        self.gltf.bufferViews.append(view)
        self.blob += data
        return len(self.gltf.bufferViews) - 1

    def accessor(self, values, ctype: int = FLOAT, normalized: bool = False, **extra) -> int:
        """Store (count, ncomp) ``values`` tightly packed as ``ctype``; return the accessor index."""
        values = np.asarray(values)
        values = values.reshape(len(values), -1)
        view = self.view(values.astype(DTYPES[ctype]).tobytes())
        type_ = TYPES[values.shape[1]]
        count = len(values)
        return self.add_accessor(
            bufferView=view, componentType=ctype, count=count, type=type_, normalized=normalized, **extra
        )

    def add_accessor(self, **fields) -> int:
        self.gltf.accessors.append(pygltflib.Accessor(**fields))
        return len(self.gltf.accessors) - 1

    def mesh(self, *primitives: pygltflib.Primitive) -> int:
        self.gltf.meshes.append(pygltflib.Mesh(primitives=list(primitives)))
        return len(self.gltf.meshes) - 1

    def primitive(self, positions, indices=None, mode=None, material=None, **attributes):
        """A primitive over new accessors; ``attributes`` maps names to accessor indices."""
        position = self.accessor(np.asarray(positions, float))
        index = None if indices is None else self.accessor(np.asarray(indices), UINT)
        attributes = pygltflib.Attributes(POSITION=position, **attributes)
        return pygltflib.Primitive(attributes=attributes, indices=index, mode=mode, material=material)

    def node(self, root: bool = True, **fields) -> int:
        self.gltf.nodes.append(pygltflib.Node(**fields))
        index = len(self.gltf.nodes) - 1
        if root:
            self.gltf.scenes[0].nodes.append(index)
        return index

    def json(self, buffer_uri: str | None) -> dict:
        self.gltf.buffers = [pygltflib.Buffer(uri=buffer_uri, byteLength=len(self.blob))]
        return json.loads(self.gltf.gltf_to_json())

    def save(self, path: Path, how: str = "glb") -> Path:
        """Write as ``glb``, ``bin`` (.gltf + external .bin) or ``datauri`` (.gltf, base64 buffer)."""
        if how == "glb":
            path.write_bytes(glb_bytes(self.json(None), bytes(self.blob)))
        elif how == "bin":
            bin_name = path.stem + " data.bin"
            (path.parent / bin_name).write_bytes(bytes(self.blob))
            path.write_text(json.dumps(self.json(bin_name.replace(" ", "%20"))))
        else:
            uri = "data:application/gltf-buffer;base64," + base64.b64encode(bytes(self.blob)).decode()
            path.write_text(json.dumps(self.json(uri)))
        return path


def glb_bytes(document: dict, blob: bytes) -> bytes:
    """A GLB container around a JSON document and a binary chunk."""
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
    chunks += struct.pack("<II", len(blob), 0x004E4942) + blob
    return b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks


def png_bytes(pixels: np.ndarray) -> bytes:
    out = io.BytesIO()
    PILImage.fromarray(pixels).save(out, format="PNG")
    return out.getvalue()


def translate(t) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = t
    return m


def scale(s) -> np.ndarray:
    return np.diag([*s, 1.0])


def rotate(axis: str, degrees: float) -> np.ndarray:
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    m = np.eye(4)
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


def quaternion(axis: str, degrees: float) -> list[float]:
    half = math.radians(degrees) / 2
    q = [0.0, 0.0, 0.0, math.cos(half)]
    q["xyz".index(axis)] = math.sin(half)
    return q


# ------------------------------------------------------------------------------------------------
# Nodes and transforms


def test_nested_trs_and_column_major_matrix_give_the_hand_computed_world(tmp_path):
    doc = Doc()
    mesh = doc.mesh(doc.primitive(TRIANGLE))
    shear = np.array([[1, 0.5, 0, 0], [0, 1, 0, 0], [0, 0.25, 1, 0], [0, 0, 0, 1]])
    local_b = translate([5, 6, 7]) @ shear
    grandchild = doc.node(root=False, mesh=mesh, translation=[0, 0, -1], scale=[-1, 1, 1])
    child = doc.node(root=False, matrix=local_b.T.ravel().tolist(), children=[grandchild])  # column-major
    root = doc.node(translation=[1, 2, 3], rotation=quaternion("z", 90), scale=[2, -1, 3], children=[child])
    scene = load(doc.save(tmp_path / "nested.glb"))

    world_a = translate([1, 2, 3]) @ rotate("z", 90) @ scale([2, -1, 3])
    world_c = world_a @ local_b @ translate([0, 0, -1]) @ scale([-1, 1, 1])
    (instance,) = scene.instances
    assert (instance.node, instance.baked, instance.reason) == (grandchild, True, "")
    np.testing.assert_allclose(instance.world, world_c, atol=1e-12)
    assert instance.world.dtype == np.float64
    # scale -1 · -1 keeps a positive determinant: 2·1·3 (root) · 1 (shear) · 1 (mirror pair)
    assert np.linalg.det(instance.world[:3, :3]) == pytest.approx(6.0)
    assert root == 2  # the root is not the first node: the walk starts from scenes[0].nodes


def test_without_scenes_every_root_node_is_placed_and_cycles_are_refused(tmp_path):
    doc = Doc()
    mesh = doc.mesh(doc.primitive(TRIANGLE))
    doc.node(root=False, mesh=mesh, translation=[1, 0, 0], children=[1])
    doc.node(root=False, mesh=mesh, scale=[1, 1, -2])
    doc.gltf.scenes, doc.gltf.scene = [], None
    scene = load(doc.save(tmp_path / "noscene.glb"))
    assert [i.node for i in scene.instances] == [0, 1]
    np.testing.assert_allclose(scene.instances[1].world, translate([1, 0, 0]) @ scale([1, 1, -2]))

    doc.gltf.nodes[1].children = [0]  # 0 → 1 → 0
    doc.gltf.scenes, doc.gltf.scene = [pygltflib.Scene(nodes=[0])], 0
    with pytest.raises(InputError, match="cycle") as error:
        load(doc.save(tmp_path / "cycle.glb"))
    assert "nodes[0]" in str(error.value)


# ------------------------------------------------------------------------------------------------
# Accessors


def test_interleaved_view_normalized_attributes_and_sparse_substitution(tmp_path):
    doc = Doc()
    vertex = np.dtype([("p", "<f4", 3), ("uv", "<u2", 2), ("rgba", "<u1", 4)])  # 20-byte stride
    data = np.zeros(3, vertex)
    data["p"] = TRIANGLE
    data["uv"] = [[0, 65535], [32768, 0], [65535, 13107]]
    data["rgba"] = [[255, 0, 51, 255], [0, 255, 0, 102], [1, 2, 3, 4]]
    view = doc.view(data.tobytes(), stride=vertex.itemsize)
    position = doc.add_accessor(bufferView=view, byteOffset=0, componentType=FLOAT, count=3, type="VEC3")
    uv0 = doc.add_accessor(
        bufferView=view, byteOffset=12, componentType=USHORT, normalized=True, count=3, type="VEC2"
    )
    color = doc.add_accessor(
        bufferView=view, byteOffset=16, componentType=UBYTE, normalized=True, count=3, type="VEC4"
    )
    uv1 = doc.accessor([[255, 0], [0, 255], [51, 102]], UBYTE, normalized=True)
    primitive = pygltflib.Primitive(
        attributes=pygltflib.Attributes(POSITION=position, TEXCOORD_0=uv0, TEXCOORD_1=uv1, COLOR_0=color)
    )
    doc.node(mesh=doc.mesh(primitive))
    # extra accessors read directly below
    signed = doc.accessor([[-128, -127, 0, 127]], BYTE, normalized=True)
    short = doc.accessor([[-32768, 16384, 32767]], SHORT, normalized=True)
    sparse_values = doc.view(np.array([[9, 9, 9], [7, 7, 7]], "<f4").tobytes())
    sparse_indices = doc.view(np.array([2, 0], "<u2").tobytes())
    sparse = pygltflib.Sparse(
        count=2,
        indices=pygltflib.AccessorSparseIndices(bufferView=sparse_indices, componentType=USHORT),
        values=pygltflib.AccessorSparseValues(bufferView=sparse_values),
    )
    on_view = doc.add_accessor(bufferView=view, componentType=FLOAT, count=3, type="VEC3", sparse=sparse)
    viewless = doc.add_accessor(componentType=FLOAT, count=4, type="VEC3", sparse=sparse)
    path = doc.save(tmp_path / "attributes.glb")
    scene = load(path)

    (prim,) = scene.primitives
    np.testing.assert_array_equal(prim.positions, TRIANGLE)
    np.testing.assert_allclose(prim.texcoords[0], [[0, 1], [32768 / 65535, 0], [1, 0.2]])
    np.testing.assert_allclose(prim.texcoords[1], [[1, 0], [0, 1], [0.2, 0.4]])
    expected_colors = [[1, 0, 0.2, 1], [0, 1, 0, 0.4], np.array([1, 2, 3, 4]) / 255]
    np.testing.assert_allclose(prim.colors, expected_colors)
    np.testing.assert_array_equal(prim.triangles, [[0, 1, 2]])

    buffers = scene.buffers
    read = lambda index: read_accessor(scene.document, buffers, index)  # noqa: E731
    np.testing.assert_allclose(read(signed), [[-1, -1, 0, 1]])
    np.testing.assert_allclose(read(short), [[-1, 16384 / 32767, 1]])
    np.testing.assert_array_equal(read(on_view), [[7, 7, 7], [1, 0, 0], [9, 9, 9]])
    np.testing.assert_array_equal(read(viewless), [[7, 7, 7], [0, 0, 0], [9, 9, 9], [0, 0, 0]])


def test_indices_are_int64_and_matrix_columns_are_aligned(tmp_path):
    doc = Doc()
    indices = doc.accessor(np.array([[0], [70000], [5]]), UINT)
    # MAT2 of bytes: each 2-byte column starts on a 4-byte boundary → 8 bytes per element
    view = doc.view(bytes([1, 2, 0, 0, 3, 4, 0, 0]))
    mat2 = doc.add_accessor(bufferView=view, componentType=BYTE, count=1, type="MAT2")
    path = doc.save(tmp_path / "raw.glb")
    scene = load(path)
    buffers = scene.buffers
    values = read_accessor(scene.document, buffers, indices)
    assert values.dtype == np.int64 and values.shape == (3, 1)
    np.testing.assert_array_equal(values[:, 0], [0, 70000, 5])
    np.testing.assert_array_equal(read_accessor(scene.document, buffers, mat2), [[1, 2, 3, 4]])


# ------------------------------------------------------------------------------------------------
# Primitives


def test_strips_fans_and_non_indexed_primitives_expand_to_known_triangles(tmp_path):
    doc = Doc()
    zigzag = [[0, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0], [2, 0, 0], [2, 1, 0]]
    strip = doc.primitive(zigzag, mode=5)  # non-indexed strip
    fan = doc.primitive(zigzag[:5], indices=[4, 3, 2, 1, 0], mode=6)
    listed = doc.primitive(zigzag)  # non-indexed triangle list
    lines = doc.primitive(zigzag, mode=1)
    points = doc.primitive(zigzag, mode=0)
    doc.node(mesh=doc.mesh(strip, fan, listed, lines, points))
    scene = load(doc.save(tmp_path / "modes.glb"))

    strip_tris, fan_tris, list_tris = (p.triangles for p in scene.primitives)
    np.testing.assert_array_equal(strip_tris, [[0, 1, 2], [1, 3, 2], [2, 3, 4], [3, 5, 4]])
    np.testing.assert_array_equal(fan_tris, [[3, 2, 4], [2, 1, 4], [1, 0, 4]])
    np.testing.assert_array_equal(list_tris, [[0, 1, 2], [3, 4, 5]])
    # a strip keeps one winding: every triangle of the flat zig-zag faces the same way
    p = np.asarray(zigzag, float)[strip_tris]
    normals_z = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[:, 2]
    assert (normals_z < 0).all()

    assert [(i.primitive, i.node) for i in scene.instances] == [(0, 0), (1, 0), (2, 0)]
    assert [s.where for s in scene.skipped] == ["meshes[0].primitives[3]", "meshes[0].primitives[4]"]
    assert scene.skipped[0].reason == "mode LINES: not triangles"
    assert scene.skipped[1].reason == "mode POINTS: not triangles"


def test_expand_triangles_drops_an_incomplete_last_triangle_and_short_strips():
    np.testing.assert_array_equal(expand_triangles(np.arange(7), 4), [[0, 1, 2], [3, 4, 5]])
    assert expand_triangles(np.arange(2), 5).shape == (0, 3)
    assert expand_triangles(np.arange(0), 6).shape == (0, 3)


def test_a_mesh_on_two_nodes_shares_its_primitives(tmp_path):
    doc = Doc()
    mesh = doc.mesh(doc.primitive(TRIANGLE), doc.primitive(TRIANGLE, indices=[0, 2, 1]))
    a = doc.node(mesh=mesh, translation=[1, 0, 0])
    b = doc.node(mesh=mesh, translation=[0, 0, 4])
    scene = load(doc.save(tmp_path / "shared.glb"))
    assert len(scene.primitives) == 2
    assert [(i.node, i.primitive) for i in scene.instances] == [(a, 0), (a, 1), (b, 0), (b, 1)]
    np.testing.assert_array_equal(scene.instances[3].world[:3, 3], [0, 0, 4])
    assert scene.instances[0].world is not scene.instances[2].world


def test_texcoord_sets_stop_at_the_first_gap(tmp_path):
    doc = Doc()
    uv = doc.accessor(np.zeros((3, 2)))
    doc.node(mesh=doc.mesh(doc.primitive(TRIANGLE, TEXCOORD_1=uv)))
    scene = load(doc.save(tmp_path / "gap.glb"))
    assert scene.primitives[0].texcoords == ()
    assert scene.skipped[0].where == "meshes[0].primitives[0].attributes.TEXCOORD_1"


@pytest.mark.parametrize("how", ["glb", "bin", "datauri"])
def test_glb_external_bin_and_data_uri_give_the_same_arrays(tmp_path, how):
    doc = Doc()
    positions = np.array([[0, 0, 0], [1.5, 0, 0], [0, 2.25, 0], [3, 3, -1]])
    uv = doc.accessor([[0, 0], [1, 0], [0, 1], [0.5, 0.25]])
    doc.node(mesh=doc.mesh(doc.primitive(positions, indices=[0, 1, 2, 2, 1, 3], TEXCOORD_0=uv)))
    scene = load(doc.save(tmp_path / f"same.{'glb' if how == 'glb' else 'gltf'}", how))
    (prim,) = scene.primitives
    np.testing.assert_array_equal(prim.positions, positions)
    np.testing.assert_array_equal(prim.triangles, [[0, 1, 2], [2, 1, 3]])
    np.testing.assert_array_equal(prim.texcoords[0], [[0, 0], [1, 0], [0, 1], [0.5, 0.25]])
    assert prim.normals is None and prim.colors is None
    assert prim.material == len(scene.materials) - 1 and scene.materials[-1].index is None


# ------------------------------------------------------------------------------------------------
# Instancing, skins, materials, images


def test_gpu_instancing_gives_one_unbaked_instance_per_transform(tmp_path):
    doc = Doc()
    mesh = doc.mesh(doc.primitive(TRIANGLE))
    t = doc.accessor([[0, 0, 0], [1, 2, 3], [-4, 0, 0]])
    r = doc.accessor([quaternion("y", 0), quaternion("y", 90), quaternion("x", 180)])
    s = doc.accessor([[1, 1, 1], [2, 2, 2], [1, -1, 0.5]])
    extension = {"attributes": {"TRANSLATION": t, "ROTATION": r, "SCALE": s}}
    extensions = {"EXT_mesh_gpu_instancing": extension}
    node = doc.node(mesh=mesh, translation=[10, 0, 0], scale=[2, 2, 2], extensions=extensions)
    doc.gltf.extensionsUsed = doc.gltf.extensionsRequired = ["EXT_mesh_gpu_instancing"]
    scene = load(doc.save(tmp_path / "gpu.glb"))

    node_world = translate([10, 0, 0]) @ scale([2, 2, 2])
    expected = [
        node_world,
        node_world @ translate([1, 2, 3]) @ rotate("y", 90) @ scale([2, 2, 2]),
        node_world @ translate([-4, 0, 0]) @ rotate("x", 180) @ scale([1, -1, 0.5]),
    ]
    assert len(scene.instances) == 3
    for k, instance in enumerate(scene.instances):
        assert (instance.node, instance.gpu_instance, instance.baked) == (node, k, False)
        assert instance.reason == "GPU-instanced (EXT_mesh_gpu_instancing): occluder only"
        np.testing.assert_allclose(instance.world, expected[k], atol=1e-12)


def test_materials_textures_images_skins_and_unlit(tmp_path):
    import alktx2

    doc = Doc()
    pixels = np.zeros((2, 3, 4), np.uint8)
    pixels[0] = [255, 0, 0, 255]  # top row red
    pixels[1] = [0, 0, 255, 128]
    glow = np.full((4, 4, 4), 200, np.uint8)
    ktx2 = alktx2.encode_raw_rgba_to_ktx2(glow.tobytes(), 4, 4, False, codec="uastc")
    gltf = doc.gltf
    gltf.images = [
        pygltflib.Image(bufferView=doc.view(png_bytes(pixels)), mimeType="image/png", name="checker"),
        pygltflib.Image(bufferView=doc.view(ktx2), mimeType="image/ktx2"),
        pygltflib.Image(uri="normal.png"),  # decoded to check it, not kept: not a colour texture
    ]
    gltf.samplers = [pygltflib.Sampler(wrapS=CLAMP_TO_EDGE, wrapT=MIRRORED_REPEAT)]
    gltf.textures = [
        pygltflib.Texture(source=0, sampler=0),
        pygltflib.Texture(extensions={"KHR_texture_basisu": {"source": 1}}),
        pygltflib.Texture(source=2),
    ]
    gltf.materials = [
        pygltflib.Material(
            name="painted",
            pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(
                baseColorFactor=[0.5, 0.25, 1, 1],
                metallicFactor=0.0,
                baseColorTexture=pygltflib.TextureInfo(
                    index=0, extensions={"KHR_texture_transform": {"texCoord": 1, "scale": [2, 2]}}
                ),
            ),
            emissiveFactor=[1, 0.5, 0],
            emissiveTexture=pygltflib.TextureInfo(index=1, texCoord=1),
            normalTexture=pygltflib.NormalMaterialTexture(index=2),
            extensions={"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}},
            alphaMode="MASK",
            doubleSided=True,
        ),
        pygltflib.Material(name="flat", extensions={"KHR_materials_unlit": {}}),
    ]
    mesh = doc.mesh(
        doc.primitive(TRIANGLE, material=0), doc.primitive(TRIANGLE, material=1), doc.primitive(TRIANGLE)
    )
    doc.node(mesh=mesh)
    skinned = doc.node(mesh=mesh, skin=0)
    gltf.skins = [pygltflib.Skin(joints=[skinned])]
    (tmp_path / "normal.png").write_bytes(png_bytes(np.full((2, 2, 4), 128, np.uint8)))
    scene = load(doc.save(tmp_path / "materials.glb"))

    painted, flat, default = scene.materials
    np.testing.assert_array_equal(painted.base_color, [0.5, 0.25, 1, 1])
    np.testing.assert_array_equal(painted.emissive, [4, 2, 0])
    texture = painted.base_color_texture
    assert (texture.image, texture.texcoord) == (0, 1)  # KHR_texture_transform's texCoord wins
    assert texture.transform == (2.0, 0.0, 0.0, -0.0, 2.0, 0.0)  # scale [2, 2]: u' = 2u, v' = 2v
    assert (texture.wrap_s, texture.wrap_t) == (CLAMP_TO_EDGE, MIRRORED_REPEAT)
    assert painted.emissive_texture.image == 1  # KTX 2, through KHR_texture_basisu
    assert np.abs(scene.images[1].pixels.astype(int) - 200).max() <= 2
    assert scene.images[2].pixels.shape == (1, 1, 4)  # the normal map: checked, not kept
    assert (painted.metallic, painted.roughness) == (0.0, 1.0)
    assert (painted.alpha_mode, painted.alpha_cutoff) == ("MASK", 0.5)
    assert painted.double_sided and not painted.unlit
    assert painted.extensions == ("KHR_materials_emissive_strength",)
    assert flat.unlit and flat.extensions == ("KHR_materials_unlit",)
    assert default.index is None and (default.metallic, default.roughness) == (1.0, 1.0)
    np.testing.assert_array_equal(default.base_color, [1, 1, 1, 1])

    decoded = scene.images[0].pixels
    assert decoded.shape == (2, 3, 4) and decoded.dtype == np.uint8
    np.testing.assert_array_equal(decoded, pixels)  # row 0 is the top row
    assert scene.images[0].name == "checker"
    assert scene.images[2].pixels.shape == (1, 1, 4)  # placeholder, index kept

    reasons = [(i.node, i.primitive, i.baked, i.reason) for i in scene.instances]
    assert reasons == [
        (0, 0, True, ""),
        (0, 1, False, "unlit material"),
        (0, 2, True, ""),
        (1, 0, False, "skinned: occluder only (rest pose)"),
        (1, 1, False, "skinned: occluder only (rest pose); unlit material"),
        (1, 2, False, "skinned: occluder only (rest pose)"),
    ]
    assert [p.material for p in scene.primitives] == [0, 1, 2]


def test_undecodable_colour_image_names_the_image(tmp_path):
    doc = Doc()
    (tmp_path / "albedo.png").write_bytes(b"\x89PNG\r\n\x1a\n not really")
    doc.gltf.images = [pygltflib.Image(uri="albedo.png")]
    doc.gltf.textures = [pygltflib.Texture(source=0)]
    doc.gltf.materials = [
        pygltflib.Material(
            pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(baseColorTexture=pygltflib.TextureInfo(index=0)),
        )
    ]
    doc.node(mesh=doc.mesh(doc.primitive(TRIANGLE, material=0)))
    with pytest.raises(InputError) as error:
        load(doc.save(tmp_path / "bad_image.glb"))
    assert "images[0]" in str(error.value) and "albedo.png" in str(error.value) and error.value.fix


# ------------------------------------------------------------------------------------------------
# Errors


def _valid(tmp_path: Path, how: str = "glb", positions=TRIANGLE, indices=None) -> Path:
    """A one-triangle scene saved as ``how`` (see Doc.save)."""
    doc = Doc()
    doc.node(mesh=doc.mesh(doc.primitive(positions, indices=indices)))
    return doc.save(tmp_path / f"scene.{'glb' if how == 'glb' else 'gltf'}", how)


def _edit_json(path: Path, change) -> Path:
    document = json.loads(path.read_text())
    change(document)
    path.write_text(json.dumps(document))
    return path


def _truncated(tmp_path):
    path = _valid(tmp_path)
    path.write_bytes(path.read_bytes()[:-10])
    return path, "GLB"


def _malformed_json(tmp_path):
    path = tmp_path / "broken.gltf"
    path.write_text('{\n  "asset": {"version": "2.0"},\n  "nodes": [}\n')
    return path, "line 3"


def _version_one(tmp_path):
    path = _valid(tmp_path, "datauri")
    return _edit_json(path, lambda d: d["asset"].update(version="1.0")), "asset.version"


def _index_out_of_range(tmp_path):
    return _valid(tmp_path, indices=[0, 1, 3]), "meshes[0].primitives[0].indices"


def _nan_position(tmp_path):
    path = _valid(tmp_path, positions=[[0, 0, 0], [np.nan, 0, 0], [0, 1, 0]])
    return path, "meshes[0].primitives[0].attributes.POSITION"


def _unsupported_required(tmp_path):
    path = _valid(tmp_path, "datauri")
    change = lambda d: d.update(extensionsRequired=["ACME_materials_glitter"])  # noqa: E731
    return _edit_json(path, change), "extensionsRequired"


def _missing_bin(tmp_path):
    path = _valid(tmp_path, "bin")
    (tmp_path / "scene data.bin").unlink()
    return path, "buffers[0]"


def _short_bin(tmp_path):
    path = _valid(tmp_path, "bin")
    (tmp_path / "scene data.bin").write_bytes(b"\0" * 8)
    return path, "buffers[0]"


def _bad_data_uri(tmp_path):
    path = _valid(tmp_path, "datauri")
    change = lambda d: d["buffers"][0].update(uri="data:application/octet-stream;base64,@@@")  # noqa: E731
    return _edit_json(path, change), "buffers[0]"


def _accessor_past_view(tmp_path):
    path = _valid(tmp_path, "datauri")
    return _edit_json(path, lambda d: d["accessors"][0].update(count=4)), "accessors[0]"


def _view_past_buffer(tmp_path):
    path = _valid(tmp_path, "datauri")
    return _edit_json(path, lambda d: d["bufferViews"][0].update(byteLength=4096)), "bufferViews[0]"


def _not_gltf(tmp_path):
    path = tmp_path / "picture.gltf"
    path.write_bytes(png_bytes(np.zeros((1, 1, 4), np.uint8)))
    return path, ""


def _missing_file(tmp_path):
    return tmp_path / "nowhere.glb", ""


@pytest.mark.parametrize(
    "make",
    [
        _truncated,
        _malformed_json,
        _version_one,
        _index_out_of_range,
        _nan_position,
        _unsupported_required,
        _missing_bin,
        _short_bin,
        _bad_data_uri,
        _accessor_past_view,
        _view_past_buffer,
        _not_gltf,
        _missing_file,
    ],
)
def test_bad_input_raises_input_error_naming_file_and_place(tmp_path, make):
    path, where = make(tmp_path)
    with pytest.raises(InputError) as error:
        load(path)
    text = str(error.value)
    assert str(path) in text and where in text
    assert where in error.value.where if where else True  # may be "<referrer> → <where>"
    assert error.value.fix


# ------------------------------------------------------------------------------------------------
# The real sample scenes


def test_simple_instancing_gives_125_unbaked_instances():
    scene = load(SCENES / "SimpleInstancing" / "SimpleInstancing.glb")
    assert len(scene.primitives) == 1 and len(scene.instances) == 125
    assert [i.gpu_instance for i in scene.instances] == list(range(125))
    assert not any(i.baked for i in scene.instances)
    assert len({tuple(i.world[:3, 3]) for i in scene.instances}) == 125  # 125 distinct places
    assert scene.materials[scene.primitives[0].material].index is None  # no material: the default


def test_negative_scale_test_has_mirrored_instances_and_shared_meshes():
    scene = load(SCENES / "NegativeScaleTest" / "NegativeScaleTest.glb")
    determinants = np.array([np.linalg.det(i.world[:3, :3]) for i in scene.instances])
    assert (determinants < 0).sum() == 4 and (determinants > 0).sum() == 7
    primitives = range(len(scene.primitives))
    nodes_per_primitive = [{i.node for i in scene.instances if i.primitive == p} for p in primitives]
    assert max(len(nodes) for nodes in nodes_per_primitive) > 1  # reused meshes: one Primitive, several nodes
    assert any(len(p.texcoords) == 0 for p in scene.primitives)  # primitives without UVs
    assert {m.name for m in scene.materials if m.double_sided} == {"Not So Shiny", "So Shiny", "Dark"}


def test_multi_uv_test_has_two_uv_sets_and_emissive_on_the_second():
    scene = load(SCENES / "MultiUVTest" / "MultiUVTest.glb")
    (prim,) = scene.primitives
    assert len(prim.texcoords) == 2 and all(t.shape == (len(prim.positions), 2) for t in prim.texcoords)
    material = scene.materials[prim.material]
    assert material.emissive_texture.texcoord == 1 and material.base_color_texture.texcoord == 0
    assert scene.images[material.emissive_texture.image].pixels.shape == (1024, 1024, 4)


def test_glass_vase_flowers_materials():
    scene = load(SCENES / "GlassVaseFlowers" / "GlassVaseFlowers.glb")
    flowers, glass_alpha, glass = scene.materials[:3]
    assert (flowers.alpha_mode, flowers.double_sided) == ("MASK", True)
    assert scene.images[flowers.base_color_texture.image].pixels.shape == (1024, 1024, 4)
    assert glass_alpha.alpha_mode == "BLEND" and glass_alpha.base_color[3] == pytest.approx(0.3)
    assert glass.extensions == ("KHR_materials_transmission", "KHR_materials_volume")
    flower_nodes = {i.node for i in scene.instances if scene.primitives[i.primitive].material == 0}
    assert len(flower_nodes) == 2  # one mesh on two nodes
    glass_material = [scene.primitives[i.primitive].material == 2 for i in scene.instances]
    assert [i.baked for i in scene.instances] == [not g for g in glass_material]  # clear glass
    assert all("clear glass" in i.reason for i, g in zip(scene.instances, glass_material) if g)
    assert glass.transmission == 1.0 and glass.thickness == pytest.approx(0.075)


def test_lights_punctual_lamp_reads_external_images():
    scene = load(SCENES / "LightsPunctualLamp" / "LightsPunctualLamp.gltf")
    assert len(scene.instances) == 3
    body = scene.materials[0]
    assert body.emissive_texture is not None and body.base_color_texture.wrap_s == CLAMP_TO_EDGE
    assert scene.images[body.base_color_texture.image].pixels.shape == (2048, 2048, 4)
    assert "KHR_materials_transmission" in scene.materials[2].extensions
    assert len(scene.document.extensions["KHR_lights_punctual"]["lights"]) == 5


def _kept(raw, made, path="document"):
    """Assert every value of the glTF JSON ``raw`` is in ``made`` as it was: keys kept, lists
    item by item, numbers equal by value (1 and 1.0 alike), other values equal."""
    if isinstance(raw, dict):
        assert isinstance(made, dict), path
        for key, value in raw.items():
            if value == {} and key in ("extensions", "extras"):
                continue  # an empty extensions or extras object says nothing
            assert key in made, f"{path}.{key} lost"
            _kept(value, made[key], f"{path}.{key}")
    elif isinstance(raw, list):
        assert isinstance(made, list) and len(made) == len(raw), path
        for i, (x, y) in enumerate(zip(raw, made)):
            _kept(x, y, f"{path}[{i}]")
    elif isinstance(raw, (int, float)) and not isinstance(raw, bool):
        assert type(made) in (int, float) and made == raw, f"{path}: {raw!r} vs {made!r}"
    else:
        assert type(made) is type(raw) and made == raw, f"{path}: {raw!r} vs {made!r}"


def _document_text(path: Path) -> str:
    data = path.read_bytes()
    return (container._split_glb(data, str(path))[0] if data[:4] == b"glTF"
            else container._decode_text(data, str(path)))


def _document_paths(name: str, tmp_path: Path) -> list[Path]:
    """The shared scenes, a scene of ours, or a baked one (lightmap textures, images, the
    second UV set)."""
    import baker
    from assets.make_scenes import cornell_box

    if name == "shared":
        paths = sorted(SCENES.glob("*/*.gl*"))
        assert len(paths) >= 5
        return paths
    paths = [cornell_box().save(tmp_path / "cornell.glb")]
    if name == "baked":
        baker.bake(paths[0], tmp_path / "baked.glb", baker.Settings(page_size=64, rays=4))
        paths = [tmp_path / "baked.glb"]
    return paths


@pytest.mark.parametrize("name", ["shared", "cornell", "baked"])
def test_a_document_written_back_keeps_every_value_of_the_file(name, tmp_path):
    """A document read from a file's JSON and turned back into JSON data (what the writer
    starts from) keeps every value the file has, of every object; the data shares nothing with
    the document (a deep copy)."""
    from baker.gltf import document as gltf_document
    from baker.gltf.container import read_document

    for path in _document_paths(name, tmp_path):
        document = read_document(path)
        made = gltf_document.data(document)
        _kept(json.loads(_document_text(path)), made, path.name)
        if made.get("nodes"):
            made["nodes"][0]["name"] = "changed"
            made["nodes"][0].setdefault("extras", {})["k"] = 1
            assert document.nodes[0].name != "changed"
            assert "k" not in (document.nodes[0].extras or {})


def test_a_document_is_read_by_its_fields_json_types(tmp_path):
    """Ints for floats are floats, integral floats for indices are ints, keys glTF does not
    define are dropped, null stays None, defaults are the spec's; a value of another JSON type
    than its field's (a fractional index, a number for a name, a string in a vector) is an
    error naming where it is and saying what glTF expects there."""
    from baker.gltf import document as gltf_document

    nodes = [{"name": "a", "mesh": 0, "translation": [1, 2, 3], "rotation": [0, 0, 0, 1]},
             {"children": [0.0], "scale": [2, 2.5, 1], "extras": {"k": 1}, "weights": [0.5],
              "unknown": 1},
             {"matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1], "camera": None,
              "extensions": {"KHR_lights_punctual": {"light": 0}}}]
    raw = {"asset": {"version": "2.0"}, "nodes": nodes, "scene": 0,
           "accessors": [{"componentType": 5126.0, "count": 3, "type": "VEC3"}],
           "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [1, 0.5, 0, 1],
                                                   "metallicFactor": 0}, "alphaCutoff": 1}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "_CUSTOM": 1},
                                       "targets": [{"POSITION": 2}]}]}]}
    document = gltf_document.document(json.loads(json.dumps(raw)))
    assert document.nodes[0].translation == [1.0, 2.0, 3.0]
    assert all(type(v) is float for v in document.nodes[0].translation)
    assert document.nodes[1].children == [0] and type(document.nodes[1].children[0]) is int
    assert document.nodes[1].weights == [0.5] and not hasattr(document.nodes[1], "unknown")
    assert document.nodes[2].camera is None and document.scene == 0
    accessor = document.accessors[0]
    assert type(accessor.componentType) is int and accessor.byteOffset == 0
    assert accessor.normalized is False
    material = document.materials[0]
    assert material.alphaCutoff == 1.0 and type(material.alphaCutoff) is float
    assert material.pbrMetallicRoughness.roughnessFactor == 1.0 and material.alphaMode == "OPAQUE"
    primitive = document.meshes[0].primitives[0]
    assert primitive.attributes.POSITION == 0 and primitive.attributes._CUSTOM == 1
    assert primitive.attributes.NORMAL is None and primitive.mode == 4
    assert primitive.targets == [{"POSITION": 2}]
    accessor = {"componentType": 5126, "count": 2.5, "type": "VEC3"}
    for odd, where, expected in (({"accessors": [accessor]}, "accessors[0].count", "an integer"),
                                 ({"nodes": [{"name": 3}]}, "nodes[0].name", "a string"),
                                 ({"nodes": [{"translation": [1, "2", 3]}]},
                                  "nodes[0].translation[1]", "a number"),
                                 ({"nodes": [{"scale": "big"}]}, "nodes[0].scale", "an array")):
        path = tmp_path / "odd.gltf"
        path.write_text(json.dumps({"asset": {"version": "2.0"}, **odd}))
        with pytest.raises(InputError) as caught:
            load(path)
        assert caught.value.where == where and expected in caught.value.message
        assert caught.value.file == str(path) and caught.value.fix


def test_a_glb_json_chunk_padded_with_nul_bytes_loads(tmp_path):
    """The spec pads the JSON chunk with spaces; some exporters pad it with NUL bytes, which no
    JSON parser takes. Read with them stripped, the scene is the one padded with spaces."""
    from assets.make_scenes import cornell_box

    source = cornell_box().save(tmp_path / "spaces.glb")
    data = source.read_bytes()
    length = struct.unpack("<I", data[12:16])[0]
    text = data[20:20 + length].rstrip(b" ")
    padded = text + b"\0" * (4 + -len(text) % 4)
    body = struct.pack("<II", len(padded), 0x4E4F534A) + padded + data[20 + length:]
    nul = tmp_path / "nul.glb"
    nul.write_bytes(struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body)
    ours, theirs = load(nul), load(source)
    assert [m.name for m in ours.materials] == [m.name for m in theirs.materials]
    assert len(ours.instances) == len(theirs.instances) > 0
    for a, b in zip(ours.primitives, theirs.primitives):
        np.testing.assert_array_equal(a.positions, b.positions)


def test_extras_of_any_json_type_are_read_and_kept(tmp_path):
    """glTF lets ``extras`` hold any JSON value (an object is advised, not required): a list on
    the root and a material, a string on the asset, a number on a node, true on an accessor.
    pygltflib types extras as an object and failed on them ("not a glTF 2.0 document pygltflib
    can read"); the file now loads and bakes, the values kept in the output (asset.extras's
    under asset.extras.value, beside baker's record)."""
    import baker
    from assets.gltf_builder import GltfBuilder, box, quad

    b = GltfBuilder()
    grey = b.material("grey", (0.6, 0.6, 0.6))
    b.node("floor", b.shape_mesh("floor", quad(4.0, 4.0), material=grey))
    b.node("box", b.shape_mesh("box", box((0.5, 0.5, 0.5)), material=grey),
           translation=(0.0, 0.25, 0.0))
    document = json.loads(b.save(tmp_path / "scene.gltf").read_text())
    document["extras"], document["asset"]["extras"] = [1, 2, 3], "made by hand"
    document["nodes"][0]["extras"], document["materials"][0]["extras"] = 5, ["a"]
    document["accessors"][0]["extras"] = True
    (tmp_path / "scene.gltf").write_text(json.dumps(document))
    scene = load(tmp_path / "scene.gltf")
    assert scene.document.extras == [1, 2, 3] and scene.document.nodes[0].extras == 5
    baker.bake(tmp_path / "scene.gltf", tmp_path / "out.glb", baker.Settings(rays=2, page_size=64))
    written = load(tmp_path / "out.glb").document
    assert written.extras == [1, 2, 3] and written.nodes[0].extras == 5
    assert written.materials[0].extras == ["a"] and written.accessors[0].extras is True
    assert written.asset.extras["value"] == "made by hand" and "baker" in written.asset.extras
