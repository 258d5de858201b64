"""``baker preview``: the picture of a baked scene (albedo × lightmap, one Embree ray per pixel).

The files here are baked with the moz carrier, whose lightmap the preview shades itself: the
emissive carrier's pages hold the shaded light already (tests/test_carriers.py compares the
two; tests/test_browser.py compares both with the viewers')."""

import io

import numpy as np
import pygltflib
import pytest
from PIL import Image

import baker
from assets.gltf_builder import edited_glb, quat_axis_angle
from assets.make_scenes import cornell_box
from baker.geometry.world import build_world
from baker.gltf.load import load
from baker.preview import View, primary_rays, render
from baker.view import page_info
from baker.geometry.surface import LUMINANCE, viewer_diffuse_weight_at
from baker.cli.main import main
from tests.bakehelp import REAL_SCENES, saved

SIZE = (200, 150)


@pytest.fixture(scope="module")
def cornell(tmp_path_factory):
    """The Cornell box baked once (small and fast), its loaded output and its node indices."""
    folder = tmp_path_factory.mktemp("cornell")
    builder = cornell_box()
    source = saved(builder, folder, "in.glb")
    out = folder / "out.glb"
    baker.bake(source, out, baker.Settings(texel_density=10.0, rays=32, carrier="moz"))
    scene = load(out)
    world = build_world(scene)
    node_of_triangle = np.array([inst.node for inst in scene.instances])[world.tri_instance]
    return dict(source=source, out=out, scene=scene, nodes=builder.info["nodes"],
                node_of_triangle=node_of_triangle)


def _nodes_seen(cornell, picture):
    """(H, W) node index seen at each pixel, −1 for the background."""
    tri = picture.triangle
    return np.where(tri >= 0, cornell["node_of_triangle"][np.maximum(tri, 0)], -1)


def _near(picture, seen, node, centre, radius=0.12):
    """Pixels seeing ``node`` within ``radius`` of ``centre`` (world)."""
    distance = np.linalg.norm(picture.position - np.asarray(centre, float), axis=-1)
    return (seen == node) & (distance < radius)


def test_cornell_box_preview_is_albedo_times_lightmap(cornell):
    picture = render(cornell["scene"], "lit", SIZE)
    seen = _nodes_seen(cornell, picture)
    nodes = cornell["nodes"]
    assert picture.rgb.shape == (150, 200, 3) and picture.rgb.dtype == np.uint8
    assert picture.rgb.std() > 20  # not flat
    # Red wall pixels are red (in the stored picture, not only in the float values).
    red = picture.rgb[seen == nodes["left_wall"]].astype(float)
    assert len(red) > 1000
    assert red[:, 0].mean() > 2.0 * red[:, 1].mean() and red[:, 0].mean() > 100
    # The open floor in front of the blocks is lit more than the floor in the back-right corner.
    open_floor = _near(picture, seen, nodes["floor"], (-0.3, 0.0, 0.6))
    corner = _near(picture, seen, nodes["floor"], (0.95, 0.0, -0.95))
    assert open_floor.sum() > 20 and corner.sum() > 5
    open_level = picture.radiance[open_floor].mean()
    corner_level = picture.radiance[corner].mean()
    # About 1.7× since the ceiling emitter's direct light is baked in (tests/test_direct.py).
    assert open_level > 1.4 * corner_level, (open_level, corner_level)
    # Lightmapped surfaces differ from unlit ones: same white albedo, values vary across the floor.
    floor = picture.radiance[seen == nodes["floor"]].mean(axis=1)
    assert floor.std() / floor.mean() > 0.1
    assert picture.lightmapped[seen >= 0].all()


def test_lightmap_only_and_checker_pictures(cornell):
    lit = render(cornell["scene"], "lit", SIZE)
    alone = render(cornell["scene"], "lightmap", SIZE)
    checker = render(cornell["scene"], "checker", SIZE)
    seen = _nodes_seen(cornell, lit)
    np.testing.assert_array_equal(alone.triangle, lit.triangle)  # same view
    red_wall = seen == cornell["nodes"]["left_wall"]
    # The lightmap alone leaves out the wall's red albedo: only the bleeding stays.
    lit_red = lit.radiance[red_wall].mean(axis=0)
    alone_red = alone.radiance[red_wall].mean(axis=0)
    assert lit_red[0] / lit_red[1] > 5 and alone_red[0] / alone_red[1] < 2
    difference = np.abs(alone.rgb.astype(int) - checker.rgb.astype(int))[seen >= 0]
    assert difference.mean() > 20
    # The checker has two shades (per page tint); squares are at least a texel.
    shades = np.unique(checker.radiance[seen >= 0].round(6), axis=0)
    assert len(shades) == 2 and checker.checker_texels >= 1


def test_preview_looks_through_the_first_gltf_camera(cornell, tmp_path):
    doc = pygltflib.GLTF2().load(str(cornell["out"]))
    doc.cameras.append(pygltflib.Camera(type="perspective", perspective=pygltflib.Perspective(
        yfov=np.radians(40.0), aspectRatio=2.0, znear=0.01)))
    # Inside the box, 0.8 m from the red wall, above the tall block, turned +90° about +Y: glTF
    # cameras look along −Z, so this one faces −X and sees nothing but the red wall.
    doc.nodes.append(pygltflib.Node(name="eye", camera=len(doc.cameras) - 1,
                                    translation=[-0.2, 1.5, 0.3],
                                    rotation=list(quat_axis_angle((0, 1, 0), 90.0))))
    doc.scenes[0].nodes.append(len(doc.nodes) - 1)
    with_camera = tmp_path / "camera.glb"
    doc.save_binary(str(with_camera))
    picture = render(load(with_camera))
    assert picture.rgb.shape == (320, 640, 3)  # 640 wide at the camera's aspect ratio
    seen = _nodes_seen(cornell, picture)
    assert (seen == cornell["nodes"]["left_wall"]).mean() > 0.99


def test_orthographic_rays_are_parallel_and_span_the_view():
    view = View(origin=np.zeros(3), axes=np.eye(3), yfov=None, ymag=2.0)
    origins, directions = primary_rays(view, 8, 4)
    np.testing.assert_allclose(directions, np.tile([0.0, 0.0, -1.0], (32, 1)))
    assert origins[:, 1].max() == pytest.approx(2.0 * (1 - 1 / 4))  # top pixel centre
    assert origins[:, 0].max() == pytest.approx(4.0 * (1 - 1 / 8))  # aspect 2: xmag 4


def test_command_writes_the_png(cornell, tmp_path, capsys):
    png = tmp_path / "preview.png"
    assert main(["preview", str(cornell["out"]), "-o", str(png), "--size", "120x90",
                 "--checker"]) == 0
    pixels = np.asarray(Image.open(io.BytesIO(png.read_bytes())))
    assert pixels.shape == (90, 120, 3) and pixels.std() > 20
    assert "checker squares of" in capsys.readouterr().out


def test_scene_without_lightmaps_is_refused_cleanly(cornell, tmp_path, capsys):
    png = tmp_path / "preview.png"
    assert main(["preview", str(cornell["source"]), "-o", str(png)]) == 1
    err = capsys.readouterr().err
    assert "no lightmap" in err and "baker bake" in err and "Traceback" not in err
    assert not png.exists()
    assert main(["preview", str(cornell["out"]), "-o", str(tmp_path / "p.jpg")]) == 1
    assert "PNG" in capsys.readouterr().err


def _moz(document):
    """The first material's MOZ_lightmap extension (a dict) of a baked document."""
    return next(m.extensions["MOZ_lightmap"] for m in document.materials
                if "MOZ_lightmap" in (m.extensions or {}))


@pytest.mark.parametrize("field, value", [("intensity", "x"), ("intensity", [1]),
                                          ("index", 99), ("index", 0.5), ("texCoord", [1])])
def test_a_damaged_lightmap_reference_is_refused_cleanly(cornell, tmp_path, capsys, field,
                                                         value):
    """A baked file whose MOZ_lightmap holds a value of another type, or a texture it does not
    have (edited by hand, or damaged): a clear error naming the material, no picture. These
    were internal errors (float() of a list, a list indexed by a float; the fuzzer's finds)."""
    damaged = edited_glb(cornell["out"], lambda d: _moz(d).__setitem__(field, value),
                         tmp_path / "damaged.glb")
    png = tmp_path / "preview.png"
    assert main(["preview", str(damaged), "-o", str(png)]) == 1
    err = capsys.readouterr().err
    assert "MOZ_lightmap" in err and "materials[" in err and "baker bake" in err, err
    assert "Traceback" not in err and "internal error" not in err and not png.exists()


@pytest.mark.parametrize("record", [5, ["moz"], None])
def test_a_damaged_bake_record_previews_from_its_lightmaps(cornell, tmp_path, record):
    """asset.extras.baker (what the bake recorded: carrier, encoding) as a number, a list or
    null: the file's MOZ_lightmap pages still render, and ``baker view`` says the default
    carrier. A number there was an internal error (``.get`` of an int; the fuzzer's find)."""
    def damage(document):
        document.asset.extras["baker"] = record

    damaged = edited_glb(cornell["out"], damage, tmp_path / "damaged.glb")
    picture = render(load(damaged), "lit", (40, 30))
    assert (picture.triangle >= 0).any() and picture.rgb.std() > 0
    assert page_info(damaged)["carrier"] == "moz"


def test_a_baked_file_without_triangles_previews_as_background(cornell, tmp_path):
    """Every primitive made points (mode 0): nothing to meet, and the rays' first hits once
    indexed an empty array of normals (an internal error). The picture is the background."""
    def points(document):
        for mesh in document.meshes:
            for primitive in mesh.primitives:
                primitive.mode = 0

    picture = render(load(edited_glb(cornell["out"], points, tmp_path / "points.glb")), "lit",
                     (40, 30))
    assert picture.rgb.shape == (30, 40, 3) and (picture.triangle == -1).all()


@pytest.fixture(scope="module")
def small_bake(tmp_path_factory):
    """name → baked output of the shared scene ``name`` (texel density 4, 8 rays: about 1 s),
    each baked once for the whole module."""
    done = {}

    def get(name):
        if name not in done:
            out = tmp_path_factory.mktemp(name) / "out.glb"
            baker.bake(REAL_SCENES[name], out, baker.Settings(texel_density=4.0, rays=8,
                                                                       escape="scene",
                                                                       carrier="moz"))
            done[name] = out
        return done[name]

    return get


def test_preview_of_a_shared_scene_with_several_uv_sets(small_bake):
    """MultiUVTest keeps its own TEXCOORD_0/1; the lightmap goes to another set, which the
    preview must read (MOZ_lightmap.texCoord), not TEXCOORD_1."""
    out = small_bake("MultiUVTest")
    lit = render(load(out), "lit", (96, 64))
    alone = render(load(out), "lightmap", (96, 64))
    hit = lit.triangle >= 0
    assert hit.mean() > 0.1 and lit.lightmapped[hit].all()
    assert lit.rgb.std() > 10
    assert np.abs(lit.rgb.astype(int) - alone.rgb.astype(int))[hit].mean() > 10


# A lone convex box: every obscurance ray escapes, so its lightmap is one value (R_ave).
_UNIFORM = {"MultiUVTest"}
# Only EXT_mesh_gpu_instancing meshes, which get no lightmap (occluders only, docs/output.md).
_NOTHING_BAKED = {"SimpleInstancing"}
_MOSTLY_METAL = {"LightsPunctualLamp"}


@pytest.mark.parametrize("name", ["cornell", *REAL_SCENES])
def test_command_previews_every_scene(name, cornell, small_bake, tmp_path):
    """``baker preview`` writes the picture of the demo scene and of every shared scene; the
    picture is not flat, and lightmapped surfaces differ from the same surfaces unlit (albedo +
    emission alone): the lightmap is read, decoded and applied, and it varies across them."""
    out = cornell["out"] if name == "cornell" else small_bake(name)
    png = tmp_path / "preview.png"
    assert main(["preview", str(out), "-o", str(png), "--size", "96x72"]) == 0
    pixels = np.asarray(Image.open(io.BytesIO(png.read_bytes())))
    scene = load(out)
    lit = render(scene, "lit", (96, 72))
    np.testing.assert_array_equal(pixels, lit.rgb)  # the command wrote this picture
    hit = lit.triangle >= 0
    assert hit.mean() > 0.05
    # not flat; but a viewer lights only the diffuse part of a material with a lightmap, and the
    # lamp is almost all metal: the moz carrier shows it black (as three.js does, test_browser)
    assert pixels[hit].std() > (1 if name in _MOSTLY_METAL else 10)
    unlit = render(scene, "unlit", (96, 72))
    np.testing.assert_array_equal(unlit.triangle, lit.triangle)  # same view
    assert main(["preview", str(out), "-o", str(png), "--size", "96x72", "--unlit"]) == 0
    np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(png.read_bytes()))), unlit.rgb)
    shown = lit.lightmapped
    if name in _NOTHING_BAKED:
        assert not shown.any()
        np.testing.assert_array_equal(lit.radiance, unlit.radiance)
        return
    assert shown[hit].mean() > 0.4
    # Viewers light only a material's diffuse part with the lightmap: (1 − metallic) ×
    # (1 − transmission) of its base colour. Where that is 0 (MultiUVTest's metal cube; not
    # where a metallic texture may lower it, as on LightsPunctualLamp's stand), the preview
    # shows what they show: the map changes nothing.
    world = build_world(scene)
    material = world.tri_material[np.maximum(lit.triangle, 0)]
    weight = np.array([(1 - np.clip(m.metallic, 0, 1)) * (1 - np.clip(m.transmission, 0, 1))
                       for m in scene.materials])[material]  # factors only
    textured = np.array([m.metallic_roughness_texture is not None for m in scene.materials])
    diffuse = shown & (weight > 0)
    metal = shown & (weight == 0) & ~textured[material]
    np.testing.assert_array_equal(lit.radiance[metal], unlit.radiance[metal])
    if diffuse.any():
        with_map = lit.radiance[diffuse] @ LUMINANCE
        without = unlit.radiance[diffuse] @ LUMINANCE
        assert np.mean(np.abs(with_map - without)) > 0.1 * np.mean(without)
    alone = render(scene, "lightmap", (96, 72)).radiance[shown] @ LUMINANCE
    spread = alone.std() / alone.mean()
    assert spread < 0.01 if name in _UNIFORM else spread > 0.05, spread


def test_the_viewer_weight_reads_the_metallic_texture_at_texel_centres():
    """LightsPunctualLamp's stand takes its metallic from a texture (blue channel, linear): at
    points whose UV is a texel centre, the diffuse weight a viewer shades is
    1 − metallicFactor × texel / 255, whatever the texel (the shade, whose transmission comes
    from a texture of its own, is left out)."""
    scene = load(REAL_SCENES["LightsPunctualLamp"])
    world = build_world(scene)
    textured = [m for m, material in enumerate(scene.materials)
                if material.metallic_roughness_texture is not None
                and material.transmission_texture is None]
    assert textured
    tris = np.flatnonzero(np.isin(world.tri_material, textured))
    ref = scene.materials[textured[0]].metallic_roughness_texture
    assert all(scene.materials[m].metallic_roughness_texture == ref for m in textured)
    pixels = scene.images[ref.image].pixels
    size = np.array(pixels.shape[1::-1], np.float64)
    corners = world.texcoords[ref.texcoord][world.triangles[tris]]  # (k, 3, 2)
    texel = np.floor(corners.mean(axis=1) * size)
    centre = (texel + 0.5) / size
    edges = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]], axis=2)
    keep = (np.abs(np.linalg.det(edges)) > 1e-12) & np.all((texel >= 0) & (texel < size), axis=1)
    st = np.linalg.solve(edges[keep], (centre - corners[:, 0])[keep][..., None])[..., 0]
    bary = np.column_stack([1 - st.sum(axis=1), st])
    column, row = texel[keep].astype(int).T
    blue = pixels[row, column, 2] / 255.0
    material = [scene.materials[m] for m in world.tri_material[tris[keep]]]
    expected = np.array([(1 - m.metallic * b) * (1 - m.transmission)
                         for m, b in zip(material, blue)])
    assert len(expected) > 100 and len(np.unique(blue)) > 1
    np.testing.assert_allclose(viewer_diffuse_weight_at(scene, world, tris[keep], bary),
                               expected, atol=1e-9)
