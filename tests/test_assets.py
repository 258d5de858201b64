"""The scene builder and the scenes: valid files, correct orientation, deterministic bytes."""

from __future__ import annotations

import struct

import numpy as np
import pygltflib
import pytest

from assets import make_scenes
from assets.gltf_builder import GltfBuilder, box, cylinder, lathe, quad, uv_sphere

# scene function -> (node count, mesh count)
SCENES = {
    "cornell_box": (make_scenes.cornell_box, 8, 8),
    "vase_room": (make_scenes.vase_room, 10, 6),
    "open_plane": (make_scenes.open_plane, 1, 1),
    "parallel_planes": (make_scenes.parallel_planes, 2, 2),
    "red_wall_floor": (make_scenes.red_wall_floor, 2, 2),
    "three_instances": (make_scenes.three_instances, 7, 5),
    "slivers_and_tiny": (make_scenes.slivers_and_tiny, 2, 2),
    "textured_floor": (make_scenes.textured_floor, 2, 2),
}


def _accessor(doc: pygltflib.GLTF2, blob: bytes, index: int) -> np.ndarray:
    acc = doc.accessors[index]
    view = doc.bufferViews[acc.bufferView]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc.type]
    dtype = {pygltflib.FLOAT: "<f4", pygltflib.UNSIGNED_INT: "<u4"}[acc.componentType]
    start = view.byteOffset + (acc.byteOffset or 0)
    data = np.frombuffer(blob, dtype=dtype, count=acc.count * width, offset=start)
    return data.reshape(acc.count, width) if width > 1 else data


def _load(path) -> tuple[pygltflib.GLTF2, bytes]:
    doc = pygltflib.GLTF2().load(str(path))
    if str(path).endswith(".glb"):
        blob = doc.binary_blob()
    else:
        blob = (path.parent / doc.buffers[0].uri).read_bytes()
    return doc, blob


@pytest.mark.parametrize("name", sorted(SCENES))
@pytest.mark.parametrize("ext", [".glb", ".gltf"])
def test_scene_round_trips(tmp_path, name, ext):
    make, n_nodes, n_meshes = SCENES[name]
    path = make().save(tmp_path / f"{name}{ext}")
    doc, blob = _load(path)
    assert doc.asset.version == "2.0" and doc.asset.generator == "baker assets"
    assert len(doc.nodes) == n_nodes and len(doc.meshes) == n_meshes
    assert doc.buffers[0].byteLength == len(blob)
    # Every node reachable from scene 0 exactly once.
    seen, stack = [], list(doc.scenes[doc.scene].nodes)
    while stack:
        i = stack.pop()
        seen.append(i)
        stack.extend(doc.nodes[i].children)
    assert sorted(seen) == list(range(n_nodes))
    for mesh in doc.meshes:
        (prim,) = mesh.primitives
        pos = _accessor(doc, blob, prim.attributes.POSITION)
        acc = doc.accessors[prim.attributes.POSITION]
        assert np.array_equal(acc.min, pos.min(axis=0)) and np.array_equal(acc.max, pos.max(axis=0))
        idx = _accessor(doc, blob, prim.indices)
        assert doc.accessors[prim.indices].componentType == pygltflib.UNSIGNED_INT
        assert len(idx) % 3 == 0 and idx.max() < len(pos)
        if prim.attributes.NORMAL is not None:
            nrm = _accessor(doc, blob, prim.attributes.NORMAL)
            assert np.allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-5)
    for view in doc.bufferViews:
        assert view.byteOffset % 4 == 0 and view.byteOffset + view.byteLength <= len(blob)


def test_glb_layout(tmp_path):
    data = make_scenes.textured_floor().save(tmp_path / "t.glb").read_bytes()
    magic, version, length = struct.unpack_from("<4sII", data)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    json_len, json_type = struct.unpack_from("<II", data, 12)
    bin_len, bin_type = struct.unpack_from("<II", data, 20 + json_len)
    assert json_type == 0x4E4F534A and bin_type == 0x004E4942
    assert json_len % 4 == 0 and bin_len % 4 == 0 and 28 + json_len + bin_len == len(data)


def test_same_scene_same_bytes(tmp_path):
    b = make_scenes.vase_room()
    for ext in (".glb", ".gltf"):
        first = b.save(tmp_path / f"a{ext}").read_bytes()
        second = b.save(tmp_path / f"a{ext}").read_bytes()
        rebuilt = make_scenes.vase_room().save(tmp_path / f"b{ext}").read_bytes()
        assert first == second
        # The .gltf names its own .bin, so compare the JSON with the name swapped.
        assert rebuilt == first if ext == ".glb" else rebuilt.replace(b"b.bin", b"a.bin") == first
    assert (tmp_path / "a.bin").read_bytes() == (tmp_path / "b.bin").read_bytes()


def _winding_dots(positions, triangles, normals):
    p = positions[triangles]
    face = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return np.einsum("ij,ikj->ik", face, normals[triangles])  # (m, 3): against each corner's normal


SHAPES = {
    "box": lambda: box((1.0, 2.0, 3.0)),
    "quad": lambda: quad(2.0, 0.5),
    "cylinder": lambda: cylinder(0.5, 2.0, 12),
    "uv_sphere": lambda: uv_sphere(0.7, 6, 10),
    "vase": lambda: lathe(make_scenes._vase_profile(), 20),
}


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_outward_shapes(name):
    positions, triangles, normals, uv = SHAPES[name]()
    assert triangles.dtype.kind == "i" and triangles.min() >= 0 and triangles.max() < len(positions)
    assert uv.shape == (len(positions), 2)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)
    assert (_winding_dots(positions, triangles, normals) > 0).all()  # also: no zero-area triangles
    if name != "quad" and name != "vase":
        # Closed convex solids centred at the origin: normals point away from the centre.
        centroid = positions[triangles].mean(axis=1)
        face_n = normals[triangles].mean(axis=1)
        assert (np.einsum("ij,ij->i", centroid, face_n) > 0).all()


def test_quad_faces_up():
    positions, triangles, normals, _ = quad(2.0, 0.5)
    assert len(positions) == 4 and len(triangles) == 2
    assert np.allclose(normals, [0, 1, 0]) and np.allclose(positions[:, 1], 0)
    assert np.allclose(np.ptp(positions, axis=0), [2.0, 0.0, 0.5]) and np.allclose(positions.mean(axis=0), 0)


def test_sphere_normals_radial_and_closed():
    positions, triangles, normals, _ = uv_sphere(0.7, 6, 10)
    assert np.allclose(normals * 0.7, positions)
    # Closed surface: the signed volume equals the sphere's, minus the facetting.
    p = positions[triangles]
    volume = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0
    assert 0.7 * 4 / 3 * np.pi * 0.7**3 < volume < 4 / 3 * np.pi * 0.7**3


def test_inward_box_is_a_room():
    size = np.array([4.0, 3.0, 2.0])
    positions, triangles, normals, _ = box(size, inward=True)
    assert len(positions) == 24 and len(triangles) == 12
    assert (_winding_dots(positions, triangles, normals) > 0).all()
    centroid = positions[triangles].mean(axis=1)
    face_n = normals[triangles].mean(axis=1)
    assert (np.einsum("ij,ij->i", -centroid, face_n) > 0).all()  # towards the centre
    assert np.allclose(np.abs(positions), size / 2)
    outward = box(size)
    assert np.allclose(outward[2], -normals) and np.array_equal(outward[1], triangles[:, ::-1])


def test_three_instances_share_one_mesh(tmp_path):
    b = make_scenes.three_instances()
    doc, _ = _load(b.save(tmp_path / "t.glb"))
    users = [n for n in doc.nodes if n.mesh == b.info["box_mesh"]]
    assert sorted(n.name for n in users) == ["box_corner", "box_open", "box_shelf"]
    assert len({tuple(n.translation) for n in users}) == 3
    assert sum(n.mesh == b.info["box_mesh"] for n in doc.nodes) == 3


def test_cornell_box_layout(tmp_path):
    b = make_scenes.cornell_box()
    doc, _ = _load(b.save(tmp_path / "c.gltf"))
    nodes = {n.name: n for n in doc.nodes}
    light = nodes["light"]
    assert light.translation[1] == pytest.approx(2.0 - 0.001)
    mat = doc.materials[doc.meshes[light.mesh].primitives[0].material]
    assert mat.emissiveFactor == [1.0, 1.0, 1.0]
    assert mat.extensions["KHR_materials_emissive_strength"]["emissiveStrength"] == 10.0
    assert "KHR_materials_emissive_strength" in doc.extensionsUsed
    red = doc.materials[doc.meshes[nodes["left_wall"].mesh].primitives[0].material]
    assert red.pbrMetallicRoughness.baseColorFactor[:3] == pytest.approx([0.63, 0.065, 0.05])
    # Blocks stand on the floor, inside the room, clear of the walls.
    for name in ("tall_block", "short_block"):
        node = nodes[name]
        acc = doc.accessors[doc.meshes[node.mesh].primitives[0].attributes.POSITION]
        assert node.translation[1] + acc.min[1] == pytest.approx(0.0, abs=1e-6)
        reach = np.hypot(acc.max[0], acc.max[2])
        assert abs(node.translation[0]) + reach < 0.9 and abs(node.translation[2]) + reach < 0.9


def test_vase_triangle_count(tmp_path):
    doc, _ = _load(make_scenes.vase_room().save(tmp_path / "v.glb"))
    vase = next(m for m in doc.meshes if m.name == "vase")
    assert 300 <= doc.accessors[vase.primitives[0].indices].count // 3 <= 600


def test_slivers_and_tiny_are_what_they_say():
    b = make_scenes.slivers_and_tiny(texel_density=32.0, include_degenerate=True)
    doc = b.document()
    blob = b.binary()
    prim = doc.meshes[doc.nodes[b.info["nodes"]["debris"]].mesh].primitives[0]
    pos = _accessor(doc, blob, prim.attributes.POSITION).astype(np.float64)
    tri = _accessor(doc, blob, prim.indices).reshape(-1, 3)
    p = pos[tri]
    edges = np.linalg.norm(p[:, [1, 2, 0]] - p, axis=2)
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    ranges = b.info["triangles"]
    longest = edges.max(axis=1)
    aspect = longest**2 / (2 * np.maximum(area, 1e-300))
    sl = ranges["sliver"]
    assert np.allclose(aspect[sl], b.info["sliver_aspect"], rtol=0.3)
    assert aspect[sl].max() > 5e5
    assert (longest[ranges["tiny"]] < (1 / 32.0) / 5).all()
    assert (aspect[ranges["normal"]] < 3).all()
    assert (area[ranges["degenerate"]] == 0).all()
    assert (area[ranges["normal"]] > 0).all() and (area[ranges["tiny"]] > 0).all()


def test_textured_floor_has_texture_and_vertex_colours(tmp_path):
    b = make_scenes.textured_floor()
    doc, blob = _load(b.save(tmp_path / "t.gltf"))
    floor = doc.meshes[doc.nodes[b.info["nodes"]["floor"]].mesh].primitives[0]
    colours = _accessor(doc, blob, floor.attributes.COLOR_0)
    assert np.allclose(colours, b.info["vertex_colors"])
    tex = doc.materials[floor.material].pbrMetallicRoughness.baseColorTexture
    image = doc.images[doc.textures[tex.index].source]
    view = doc.bufferViews[image.bufferView]
    from io import BytesIO

    from PIL import Image

    pixels = np.asarray(Image.open(BytesIO(blob[view.byteOffset : view.byteOffset + view.byteLength])))
    assert np.array_equal(pixels, b.info["image"])
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) == 2


def test_builder_rejects_bad_input():
    b = GltfBuilder()
    with pytest.raises(ValueError):
        b.mesh("bad", np.zeros((3, 3)), np.array([[0, 1, 3]]))
    with pytest.raises(ValueError):
        b.mesh("bad", np.zeros((3, 2)), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError):
        b.node("bad", translation=(0, 0, 0), matrix=np.eye(4))
    with pytest.raises(ValueError):
        b.save("x.obj")


def test_matrix_stored_column_major():
    b = GltfBuilder()
    m = np.eye(4)
    m[:3, 3] = (1.0, 2.0, 3.0)
    b.node("n", matrix=m)
    assert b.document().nodes[0].matrix[12:15] == [1.0, 2.0, 3.0]


def _quat_matrix(q) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _world_faces(doc, blob, node):
    """World-space triangle centroids and corner-averaged normals of a root node with TRS."""
    prim = doc.meshes[node.mesh].primitives[0]
    r = _quat_matrix(node.rotation) if node.rotation else np.eye(3)
    t = np.asarray(node.translation or (0, 0, 0))
    pos = _accessor(doc, blob, prim.attributes.POSITION) @ r.T + t
    nrm = _accessor(doc, blob, prim.attributes.NORMAL) @ r.T
    tri = _accessor(doc, blob, prim.indices).reshape(-1, 3)
    return pos[tri].mean(axis=1), nrm[tri].mean(axis=1), pos


@pytest.mark.parametrize(
    "name, inside",
    [("cornell_box", (0.0, 1.0, 0.0)), ("vase_room", (0.0, 1.5, 0.0))],
)
def test_room_surfaces_face_the_inside(tmp_path, name, inside):
    doc, blob = _load(getattr(make_scenes, name)().save(tmp_path / "r.glb"))
    rooms = {"cornell_box": ("floor", "ceiling", "back_wall", "left_wall", "right_wall", "light"),
             "vase_room": ("floor", "walls", "window")}[name]
    for node in doc.nodes:
        if node.name in rooms:
            centroid, normal, _ = _world_faces(doc, blob, node)
            assert (np.einsum("ij,ij->i", np.asarray(inside) - centroid, normal) > 0).all(), node.name


def test_cornell_walls_where_they_belong(tmp_path):
    doc, blob = _load(make_scenes.cornell_box().save(tmp_path / "c.glb"))
    expect = {"floor": (1, 0.0), "ceiling": (1, 2.0), "back_wall": (2, -1.0), "left_wall": (0, -1.0),
              "right_wall": (0, 1.0), "light": (1, 1.999)}
    for node in doc.nodes:
        if node.name in expect:
            axis, value = expect[node.name]
            _, _, pos = _world_faces(doc, blob, node)
            assert np.allclose(pos[:, axis], value, atol=1e-6), node.name
            assert np.all(np.abs(pos[:, [0, 2]]) <= 1.0 + 1e-6), node.name
            assert pos[:, 1].min() >= -1e-6 and pos[:, 1].max() <= 2.0 + 1e-6, node.name


def test_test_scene_planes(tmp_path):
    doc, blob = _load(make_scenes.parallel_planes(height=0.5, half_extent=50.0).save(tmp_path / "p.glb"))
    nodes = {n.name: n for n in doc.nodes}
    _, n_probe, p_probe = _world_faces(doc, blob, nodes["probe"])
    _, n_ceil, p_ceil = _world_faces(doc, blob, nodes["ceiling"])
    assert np.allclose(n_probe, [0, 1, 0]) and np.allclose(p_probe[:, 1], 0)
    assert np.allclose(n_ceil, [0, -1, 0]) and np.allclose(p_ceil[:, 1], 0.5)
    assert np.allclose(np.ptp(p_ceil, 0), [100, 0, 100])
    tri = _accessor(doc, blob, doc.meshes[nodes["ceiling"].mesh].primitives[0].indices).reshape(-1, 3)
    assert (_winding_dots(p_ceil, tri, np.tile(n_ceil[0], (4, 1))) > 0).all()
    doc, blob = _load(make_scenes.red_wall_floor().save(tmp_path / "r.glb"))
    wall = next(n for n in doc.nodes if n.name == "red_wall")
    _, n_wall, p_wall = _world_faces(doc, blob, wall)
    assert np.allclose(n_wall, [0, 0, 1]) and np.allclose(p_wall[:, 2], -2.0)
    assert np.allclose(p_wall.min(0), [-2, 0, -2]) and np.allclose(p_wall.max(0), [2, 2, -2])
