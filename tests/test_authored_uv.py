"""``--uv N``: baking into lightmap UVs the artist authored (``baker/atlas/authored.py``)."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import numpy as np
import pygltflib
import pytest

import baker
from assets.gltf_builder import GltfBuilder, box, quad
from baker.atlas.authored import authored_atlas, check_layout
from baker.atlas.rasterise import cover
from baker.atlas.unwrap import unwrap
from baker.cli.main import main
from baker.errors import InputError, SettingsError
from baker.geometry.world import build_world
from baker.gltf.load import load
from baker.pipeline.full import bounds_of_baked
from baker.rebake.state import default_path
from baker.settings import Settings, resolve
from tests.gltf_validator import validate
from tests.bakehelp import carried

PAGE = 64
SETTINGS = Settings(uv=1, page_size=PAGE, rays=8, shadow_rays=1, threads=1)


def _cells(count: int, margin: float) -> list[tuple[float, float, float]]:
    """(u0, v0, size) of ``count`` square cells on a grid over [0, 1]², each shrunk by
    ``margin`` (UV units) on every side."""
    across = int(np.ceil(np.sqrt(count)))
    size = 1.0 / across
    return [((k % across) * size + margin, (k // across) * size + margin, size - 2 * margin)
            for k in range(count)]


def authored_scene(margin: float = 4 / PAGE, cell_of=None, box_at=(0.3, 0.25, -0.2),
                   uv1_range=None) -> GltfBuilder:
    """A 2 m floor and a 0.5 m box on it, each its own mesh, with TEXCOORD_1 laid out by
    hand: each of the seven faces (floor, box's six) a square of a grid cell, ``margin`` UV
    units in from the cell's sides. ``cell_of``: face → cell (default: its own);
    ``uv1_range``: rescale the floor's set into (low, high) instead (to leave [0, 1])."""
    cells = _cells(7, margin)
    cell_of = cell_of or (lambda face: face)
    b = GltfBuilder()
    grey = b.material("grey", (0.7, 0.7, 0.7))
    floor_p, floor_t, floor_n, floor_uv = quad(2.0, 2.0)
    u0, v0, size = cells[cell_of(0)]
    floor_uv1 = np.array([u0, v0]) + floor_uv * size
    if uv1_range is not None:
        floor_uv1 = uv1_range[0] + floor_uv * (uv1_range[1] - uv1_range[0])
    b.node("floor", b.mesh("floor", floor_p, floor_t, normals=floor_n, uv0=floor_uv,
                           uv1=floor_uv1, material=grey))
    box_p, box_t, box_n, box_uv = box((0.5, 0.5, 0.5))
    uv1 = np.zeros_like(box_uv)
    for face in range(6):
        u0, v0, size = cells[cell_of(1 + face)]
        rows = slice(4 * face, 4 * face + 4)
        uv1[rows] = np.array([u0, v0]) + box_uv[rows] * size
    b.node("box", b.mesh("box", box_p, box_t, normals=box_n, uv0=box_uv, uv1=uv1,
                         material=grey), translation=box_at)
    return b


def test_a_good_authored_set_bakes_into_itself_and_stays_texcoord_1(tmp_path):
    """The bake uses the authored UVs as they are: every baked texel lies inside a face's
    square, the output's TEXCOORD_1 is the authored set (no set moved, no xatlas split), the
    MOZ_lightmap reads it, and the file validates."""
    path = authored_scene().save(tmp_path / "scene.gltf")
    result = baker.bake(path, tmp_path / "out.gltf", SETTINGS)
    assert result.pages == 1 and result.report["atlas"]["width"] == PAGE
    out = pygltflib.GLTF2().load(str(tmp_path / "out.gltf"))
    scene_in, scene_out = load(path), load(tmp_path / "out.gltf")
    for before, after in zip(scene_in.primitives, scene_out.primitives):
        assert len(after.texcoords) == 2  # TEXCOORD_0 and the lightmap set: nothing moved
        np.testing.assert_allclose(after.texcoords[1], before.texcoords[1], atol=1e-7)
        assert len(after.positions) == len(before.positions)
    lightmapped = [m for m in out.materials if carried(m) is not None]
    assert lightmapped and all(carried(m)["texCoord"] == 1 for m in lightmapped)
    assert validate(tmp_path / "out.gltf")["issues"]["numErrors"] == 0


def test_the_texels_follow_the_authored_set_not_an_unwrap(tmp_path):
    """Every covered texel lies in one of the seven cells' squares (with a texel of slack for
    conservative coverage), and the texels of the authored atlas differ from xatlas's."""
    scene = load(authored_scene().save(tmp_path / "scene.glb"))
    world = build_world(scene)
    resolved = resolve(SETTINGS, *bounds_of_baked(world, scene))
    atlas = authored_atlas(scene, world, resolved)
    key = cover(atlas, world).key.astype(np.int64)
    x, y = key % PAGE + 0.5, key // PAGE + 0.5
    inside = np.zeros(len(key), bool)
    for u0, v0, size in _cells(7, 4 / PAGE):
        inside |= ((x >= u0 * PAGE - 1) & (x <= (u0 + size) * PAGE + 1)
                   & (y >= v0 * PAGE - 1) & (y <= (v0 + size) * PAGE + 1))
    assert inside.all() and len(key) > 0.3 * PAGE * PAGE
    unwrapped = unwrap(scene, world, replace(resolved, uv=None))
    assert not np.array_equal(cover(unwrapped, world).key, cover(atlas, world).key)


@pytest.mark.parametrize("case,needle", [
    ("missing", "has no TEXCOORD_2"),
    ("outside", "leaves [0, 1]"),
    ("overlap", "overlaps itself"),
    ("padding", "closer than --padding 4 texels at page size 64"),
])
def test_bad_authored_sets_are_refused_naming_the_primitive(tmp_path, case, needle):
    """Each check of the set fails with an InputError naming the mesh and primitive, before
    any ray: no TEXCOORD_N, UVs outside [0, 1], two faces in one cell, islands 3 texels apart
    (2 free between the texels they touch) where --padding asks 4."""
    builder = {"missing": authored_scene, "outside": lambda: authored_scene(uv1_range=(-0.1, 0.5)),
               "overlap": lambda: authored_scene(cell_of=lambda f: 0 if f == 2 else f),
               "padding": lambda: authored_scene(margin=1.5 / PAGE)}[case]()
    scene = load(builder.save(tmp_path / "scene.glb"))
    world = build_world(scene)
    settings = replace(SETTINGS, uv=2 if case == "missing" else 1, padding=4)
    with pytest.raises(InputError) as error:
        authored_atlas(scene, world, resolve(settings, *bounds_of_baked(world, scene)))
    text = str(error.value)
    assert needle in text and "meshes[" in text and ".primitives[0]" in text
    if case == "overlap":  # the two faces that share a cell are both named
        assert "nodes[0]" in text and "nodes[1]" in text
    if case == "padding":  # --padding 2 takes the same set
        authored_atlas(scene, world, resolve(replace(SETTINGS, padding=2),
                                             *bounds_of_baked(world, scene)))


@pytest.mark.parametrize("padding", [1, 2, 4])
def test_xatlas_charts_pass_the_layout_checks_at_their_own_padding(tmp_path, padding):
    """The rule is the one xatlas packs by: its one-page atlas of the same scene, packed with
    ``padding``, passes the overlap and padding checks at that padding."""
    scene = load(authored_scene().save(tmp_path / "scene.glb"))
    world = build_world(scene)
    resolved = resolve(replace(SETTINGS, uv=None, padding=padding, page_size=2 * PAGE),
                       *bounds_of_baked(world, scene))
    atlas = unwrap(scene, world, resolved, fit_one_page=True)
    assert atlas.page_count == 1
    check_layout(scene, world, atlas, 1)
    with pytest.raises(InputError, match="closer than --padding"):
        check_layout(scene, world, replace(atlas, padding=4 * padding + 4), 1)


def test_the_cli_bakes_with_uv_and_refuses_it_with_a_texel_density(tmp_path, capsys):
    """``--uv 1`` from the command line bakes (the summary names the set); with
    ``--texel-density`` it is refused before any work; a bad set exits 1, writing nothing."""
    path = authored_scene().save(tmp_path / "scene.glb")
    assert main(["bake", str(path), "-o", str(tmp_path / "out.glb"), "--uv", "1",
                 "--page-size", str(PAGE), "--rays", "4", "--threads", "1"]) == 0
    assert "TEXCOORD_1 (about" in capsys.readouterr().out
    with pytest.raises(SettingsError, match="no effect with --uv"):
        Settings(uv=1, texel_density=10.0).check()
    assert main(["bake", str(path), "-o", str(tmp_path / "bad.glb"), "--uv", "3",
                 "--page-size", str(PAGE)]) == 1
    assert "has no TEXCOORD_3" in capsys.readouterr().err
    assert not (tmp_path / "bad.glb").exists()


def test_a_rebake_with_authored_uvs_after_a_move_equals_a_full_bake(tmp_path):
    """Move the box: the rebake is incremental and gives the full bake's bytes."""
    first = authored_scene().save(tmp_path / "scene.glb")
    baker.bake(first, tmp_path / "baked.glb", SETTINGS)
    edited = authored_scene(box_at=(-0.4, 0.25, 0.3)).save(tmp_path / "moved.glb")
    shutil.copy(default_path(tmp_path / "baked.glb"), default_path(tmp_path / "again.glb"))
    again = baker.bake(edited, tmp_path / "again.glb", SETTINGS, incremental="always")
    baker.bake(edited, tmp_path / "full.glb", SETTINGS)
    assert again.rebake["incremental"] is True, again.rebake.get("full_bake_reason")
    assert (tmp_path / "again.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()


def test_texcoord_0_as_the_lightmap_set_is_written_as_texcoord_1(tmp_path):
    """``--uv 0``: the lightmap UVs go to TEXCOORD_1, where MOZ_lightmap viewers read them,
    and the file's TEXCOORD_1 moves up to TEXCOORD_2 (the writer's usual move)."""
    b = GltfBuilder()
    grey = b.material("grey", (0.7, 0.7, 0.7))
    p, t, n, uv = quad(2.0, 2.0)
    b.node("floor", b.mesh("floor", p, t, normals=n, uv0=uv * 0.8 + 0.1, uv1=uv, material=grey))
    path = b.save(tmp_path / "floor.gltf")
    baker.bake(path, tmp_path / "out.gltf", replace(SETTINGS, uv=0))
    (prim,) = load(tmp_path / "out.gltf").primitives
    assert len(prim.texcoords) == 3
    np.testing.assert_allclose(prim.texcoords[1], prim.texcoords[0], atol=1e-7)
    np.testing.assert_allclose(prim.texcoords[2], load(path).primitives[0].texcoords[1], atol=1e-7)
    data = json.loads((tmp_path / "out.gltf").read_text())
    assert all(carried(m)["texCoord"] == 1 for m in data["materials"] if carried(m) is not None)
