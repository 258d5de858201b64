"""Incremental rebake (issue 5): rigid-move-invariant atlas, bake state, diff, dirty texels, and
the invariant everything leans on — an incremental rebake gives the same bytes as a full bake of
the edited scene (docs/design.md §4–5)."""

from __future__ import annotations

import shutil
import zipfile
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pytest

import baker
from assets.gltf_builder import edited_glb, quat_axis_angle, rotation_matrix
from assets.make_scenes import cornell_box
from assets.rebake_scenes import box_room, grid_boxes, moved
from baker.pipeline.full import compute
from baker.geometry.world import build_world
from baker.rebake.fallback import FullBake
from baker.rebake.incremental import rebake
from baker.gltf.load import load
from baker.settings import resolve
from baker.rebake.state import default_path
from baker.atlas.unwrap import frame_area, stretch, unwrap
from baker.cli.common import OUTPUTS_CHANGED
from baker.cli.main import main
from tests.bakehelp import rasterised

ROOM = (4.0, 3.0, 4.0)
BOXES = grid_boxes(4, room=ROOM, size=0.4)
LAMP = {"at": (0.3, 2.6, 0.2), "intensity": 5.0, "radius": 0.1}
SETTINGS = baker.Settings(rays=16, page_size=128, shadow_rays=4, threads=1)


def _room(boxes=BOXES, **kwargs):
    return box_room(boxes, room=ROOM, lamp=kwargs.pop("lamp", LAMP), **kwargs)


EDITS = {
    "box moved across the room": lambda: _room(moved(BOXES, "box1", at=(1.2, -1.1))),
    "box rotated": lambda: _room(moved(BOXES, "box2", turn=77.0)),
    "base colour changed": lambda: _room(colours={"accent": (0.1, 0.5, 0.9)}),
    "light moved": lambda: _room(lamp=dict(LAMP, at=(-1.0, 2.5, 0.5))),
    "light intensity changed": lambda: _room(lamp=dict(LAMP, intensity=9.0)),
    "object removed": lambda: _room(BOXES[:3]),
    "object added": lambda: _room(BOXES + [dict(BOXES[1], name="box9", at=(0.0, 1.5))]),
}
NEEDS_NEW_ATLAS = {"object removed", "object added"}


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    """The unedited room, fully baked, with its bake state."""
    folder = tmp_path_factory.mktemp("base")
    scene = _room().save(folder / "room.glb")
    result = baker.bake(scene, folder / "room_baked.glb", SETTINGS)
    assert result.rebake["incremental"] is False and default_path(folder / "room_baked.glb").exists()
    return folder / "room_baked.glb"


def _rebake_and_full(base: Path, builder, folder: Path, settings=SETTINGS):
    """Rebake the edited scene from the base state, and bake it fully; return both results."""
    scene = builder.save(folder / "edited.glb")
    shutil.copy(default_path(base), default_path(folder / "incremental.glb"))
    incremental = baker.bake(scene, folder / "incremental.glb", settings, incremental="always")
    full = baker.bake(scene, folder / "full.glb", settings)
    return incremental, full


@pytest.mark.parametrize("edit", list(EDITS))
def test_rebake_is_byte_identical_to_a_full_bake(base, tmp_path, edit):
    incremental, full = _rebake_and_full(base, EDITS[edit](), tmp_path)
    assert (tmp_path / "incremental.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()
    assert (default_path(tmp_path / "incremental.glb").read_bytes()
            == default_path(tmp_path / "full.glb").read_bytes())
    info = incremental.rebake
    if edit in NEEDS_NEW_ATLAS:  # packing changes: a full bake is the right answer, and says why
        assert info["incremental"] is False and info["full_bake_reason"]
        return
    assert info["incremental"] is True, info.get("full_bake_reason")
    fraction = info["dirty_fraction"]
    if edit.startswith("light"):  # no obscurance ray: recomposition or one light's shadows
        assert info["dirty_texels"] == 0
        assert info["relit_lights"] == ([0] if edit == "light moved" else [])
    else:
        assert 0 < fraction < 0.5, fraction
        assert len(incremental.rebake["dirty_keys"]) == info["dirty_texels"]


GLASS = {"KHR_materials_transmission": {"transmissionFactor": 1.0},
         "KHR_materials_ior": {"ior": 1.5},
         "KHR_materials_volume": {"thicknessFactor": 0.1, "attenuationDistance": 2.0}}


@pytest.mark.parametrize("extension, key, value", [
    ("KHR_materials_ior", "ior", 1.2), ("KHR_materials_transmission", "transmissionFactor", 0.5),
    ("KHR_materials_volume", "thicknessFactor", 0.3),
    ("KHR_materials_volume", "attenuationDistance", 0.5)])
def test_a_glass_s_values_changed_rebake_like_a_full_bake(tmp_path, extension, key, value):
    """The Cornell room's tall box made of glass (transmission, ior, volume), one value of an
    extension it already has changed: the rebake is a full bake (the material changed, or the
    clear glass left the atlas), and says why. The material's
    fingerprint held its extensions' names, not these values: an ior edit rebaked as "nothing
    changed" and kept the old refraction (the output differed from a full bake's)."""
    def glass(document):
        material = document.materials[1]
        material.extensions = {name: dict(values) for name, values in GLASS.items()}
        material.pbrMetallicRoughness.metallicFactor = 0.0
        material.pbrMetallicRoughness.roughnessFactor = 0.0

    settings = baker.Settings(rays=8, page_size=64, threads=1)
    scene = edited_glb(cornell_box().save(tmp_path / "room.glb"), glass, tmp_path / "glass.glb")
    baker.bake(scene, tmp_path / "incremental.glb", settings)
    edited = edited_glb(scene, lambda d: d.materials[1].extensions[extension].__setitem__(
        key, value), tmp_path / "edited.glb")
    rebaked = baker.bake(edited, tmp_path / "incremental.glb", settings, incremental="always")
    baker.bake(edited, tmp_path / "full.glb", settings)
    assert (tmp_path / "incremental.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()
    assert rebaked.rebake["incremental"] is False and rebaked.rebake["full_bake_reason"]


def test_added_or_removed_node_names_the_reason(base, tmp_path):
    density = baker.Settings(**{**{f.name: getattr(SETTINGS, f.name) for f in fields(SETTINGS)},
                                "texel_density": 10.0})
    scene = _room().save(tmp_path / "room.glb")
    baker.bake(scene, tmp_path / "out.glb", density)
    edited = _room(BOXES[:3]).save(tmp_path / "edited.glb")
    result = baker.bake(edited, tmp_path / "out.glb", density, incremental="always")
    assert result.rebake["incremental"] is False
    reason = result.rebake["full_bake_reason"]
    assert f"removed node {BOXES[3]['name']!r}" in reason and "None" not in reason, reason
    added = _room(BOXES + [dict(BOXES[1], name="box9", at=(0.0, 1.5))])
    result = baker.bake(added.save(tmp_path / "added.glb"), tmp_path / "out.glb", density,
                        incremental="always")
    assert "instances added " in (reason := result.rebake["full_bake_reason"])
    assert "node 'box9' (nodes[5]), mesh 2, primitive 0" in reason, reason


def test_no_false_negatives_next_to_a_wall(tmp_path):
    """Every texel whose full-bake terms change when a box moves against a wall is dirty."""
    settings = baker.Settings(rays=16, page_size=128, shadow_rays=4, threads=1, d_max=0.3)
    low = dict(LAMP, at=(0.9, 0.9, -0.5))  # low, beside the box: shadows reach past d_max
    before = _room(lamp=low).save(tmp_path / "before.glb")
    after = _room(moved(BOXES, "box1", at=(1.75, -0.5)), lamp=low).save(tmp_path / "after.glb")
    baker.bake(before, tmp_path / "out.glb", settings)
    result = baker.bake(after, tmp_path / "out.glb", settings, incremental="always")
    assert result.rebake["incremental"]
    a, b = compute(load(before), settings), compute(load(after), settings)
    assert np.array_equal(a.texels.key, b.texels.key)
    changed = ~(a.texels.position == b.texels.position).all(axis=1)
    for x, y in ((a.terms, b.terms), (a.direct, b.direct), (a.validity, b.validity)):
        for f in fields(x):
            u, v = getattr(x, f.name), getattr(y, f.name)
            if isinstance(u, np.ndarray) and len(u) == len(changed):
                changed |= ~(u.reshape(len(u), -1) == v.reshape(len(v), -1)).all(axis=1)
    dirty = np.isin(a.texels.key, result.rebake["dirty_keys"])
    assert changed.sum() > 100  # the move changes plenty, near the wall and around
    assert not (changed & ~dirty).any(), int((changed & ~dirty).sum())
    assert result.rebake["dirty_by_reason"]["shadow"] > 0  # shadows reach past d_max here


def test_atlas_and_texels_do_not_change_under_a_rigid_move(tmp_path):
    """Moving and turning a (scaled) node leaves the atlas, and every texel's key (its page, x, y)
    and owning triangle (so its barycentric placement), bit-identical; only its world positions
    move."""
    scenes = [_room(), _room(moved(BOXES, "box0", at=(-1.0, 1.3), turn=131.0))]
    out = []
    for k, builder in enumerate(scenes):
        scene = load(builder.save(tmp_path / f"s{k}.glb"))
        world = build_world(scene)
        settings = resolve(SETTINGS, frame_area(scene, world), 1.0)
        atlas = unwrap(scene, world, settings)
        out.append((settings, atlas, rasterised(atlas, world)))
    (s0, a0, t0), (s1, a1, t1) = out
    assert s0.texel_density == s1.texel_density
    assert (a0.width, a0.height, a0.page_count) == (a1.width, a1.height, a1.page_count)
    for u0, u1 in zip(a0.instances, a1.instances):
        for name in ("vertices", "triangles", "uv", "pages"):
            assert np.array_equal(getattr(u0, name), getattr(u1, name))
    for name in ("key", "triangle", "triangle_texels", "page_width", "page_height"):
        assert np.array_equal(getattr(t0, name), getattr(t1, name)), name
    assert not np.array_equal(t0.position, t1.position)


def test_stretch_ignores_rotation_and_keeps_mirroring():
    rng = np.random.default_rng(3)
    scale = np.diag([0.3, 1.7, 0.9])
    for _ in range(20):
        r = rotation_matrix(rng.normal(size=3), float(rng.uniform(0, 360)))
        assert np.array_equal(stretch(r @ scale), stretch(scale))
        assert np.array_equal(stretch(r @ scale @ np.diag([1, 1, -1])),
                              stretch(scale @ np.diag([1, 1, -1])))
    assert np.linalg.det(stretch(np.diag([1.0, 1.0, -1.0]))) < 0


@pytest.mark.parametrize("damage", ["missing", "truncated", "flipped bit", "version", "foreign",
                                    "other scene"])
def test_unusable_state_means_a_full_bake_with_a_reason(base, tmp_path, damage):
    scene = EDITS["box moved across the room"]().save(tmp_path / "edited.glb")
    state = default_path(tmp_path / "out.glb")
    if damage == "truncated":
        data = default_path(base).read_bytes()
        state.write_bytes(data[: len(data) // 2])
    elif damage == "flipped bit":  # in the middle of some array: its member's CRC-32 tells
        data = bytearray(default_path(base).read_bytes())
        data[len(data) // 2] ^= 0x10
        state.write_bytes(bytes(data))
    elif damage == "version":
        with zipfile.ZipFile(default_path(base)) as src, zipfile.ZipFile(state, "w") as dst:
            for item in src.infolist():
                data = src.read(item)
                if item.filename == "header.json":
                    data = data.replace(f'"version": {baker.rebake.state.VERSION}'.encode(),
                                        b'"version": 99')
                dst.writestr(item, data)
    elif damage == "foreign":
        state.write_bytes(b"PK\x03\x04 not really a zip")
    elif damage == "other scene":
        other = box_room(grid_boxes(3, room=ROOM, seed=5), room=ROOM).save(tmp_path / "other.glb")
        baker.bake(other, tmp_path / "out.glb", SETTINGS)
    result = baker.bake(scene, tmp_path / "out.glb", SETTINGS, incremental="always")
    assert result.rebake["incremental"] is False
    reason = result.rebake["full_bake_reason"]
    assert reason and "\n" not in reason
    if damage == "version":
        assert "version 99" in reason
    if damage == "flipped bit":
        assert "damaged" in reason
    baker.bake(scene, tmp_path / "full.glb", SETTINGS, state=False)
    assert (tmp_path / "out.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()


def test_a_state_of_another_build_of_baker_means_a_full_bake(base, tmp_path, monkeypatch):
    """A state keeps the terms the code that wrote it computed: written by another build (other
    sources, or another Embree, numba or numpy), it is not mixed with this build's terms."""
    from baker.rebake import diff as diff_module

    scene = EDITS["box moved across the room"]().save(tmp_path / "edited.glb")
    shutil.copy(default_path(base), default_path(tmp_path / "out.glb"))
    assert diff_module.code_fingerprint() in default_path(base).read_bytes().decode("latin-1")
    monkeypatch.setattr(diff_module, "code_fingerprint", lambda: "another build")
    result = baker.bake(scene, tmp_path / "out.glb", SETTINGS, incremental="always")
    assert result.rebake["incremental"] is False
    assert "another build of baker" in result.rebake["full_bake_reason"]


def test_the_code_fingerprint_covers_every_source_file_of_the_package(tmp_path):
    """Every ``.py`` under baker/, in any subpackage, is in the build's fingerprint: an edit, a
    new file or a file moved to another package changes it (states of two builds never mix)."""
    from baker.jit import sources_digest

    package = Path(baker.__file__).resolve().parent
    copy = tmp_path / "baker"
    shutil.copytree(package, copy, ignore=shutil.ignore_patterns("__pycache__"))
    digest = sources_digest(copy)
    assert sources_digest(package) == digest  # only the files and their paths count
    deep = copy / "light" / "obscurance.py"
    assert deep.exists()
    changed = [lambda: deep.write_text(deep.read_text() + "\n"),
               lambda: (copy / "rays" / "new_module.py").write_text(""),
               lambda: (copy / "rays" / "new_module.py").rename(copy / "image" / "new_module.py")]
    seen = {digest}
    for change in changed:
        change()
        seen.add(sources_digest(copy))
    assert len(seen) == 1 + len(changed)


def test_unchanged_scene_recomputes_nothing(base, tmp_path):
    scene = _room().save(tmp_path / "same.glb")
    shutil.copy(default_path(base), default_path(tmp_path / "out.glb"))
    with pytest.raises(FullBake):  # the library-level call refuses a missing state
        rebake(load(scene), SETTINGS, tmp_path / "nothing.bake")
    result = baker.bake(scene, tmp_path / "out.glb", SETTINGS, incremental="always")
    assert result.rebake["incremental"] and result.rebake["dirty_texels"] == 0
    assert (tmp_path / "out.glb").read_bytes() == base.read_bytes()


def test_cli_bakes_incrementally_rebakes_and_watches(base, tmp_path, capsys, monkeypatch):
    """The commands' flow; whether the cost model prices a rebake out is its own tests' (it
    weighs times measured on the machine: a small room's rebake can lose to a full bake)."""
    import baker.rebake.dirty as dirty_module
    import baker.rebake.incremental as incremental_module

    monkeypatch.setattr(incremental_module, "worth_reading", lambda path: None)
    monkeypatch.setattr(dirty_module, "afford", lambda *args, **kwargs: None)
    out = tmp_path / "out.glb"
    scene = _room().save(tmp_path / "room.glb")
    args = ["--rays", "16", "--page-size", "128", "--shadow-rays", "4", "--threads", "1"]
    assert main(["bake", str(scene), "-o", str(out), *args]) == 0
    assert "full bake: no bake state" in capsys.readouterr().out
    EDITS["box moved across the room"]().save(scene)
    assert main(["rebake", str(scene), "-o", str(out), "--moved", "box1"]) == 0
    captured = capsys.readouterr()
    assert "rebake: node box1 moved" in captured.out and "note:" not in captured.err
    assert main(["bake", str(scene), "-o", str(out), *args, "--full"]) == 0
    assert "rebake:" not in capsys.readouterr().out
    assert main(["bake", str(scene), "-o", str(out), *args]) == 0  # the state is used by default
    assert "0 of" in capsys.readouterr().out
    assert main(["rebake", str(scene), "-o", str(out), "--moved", "crate_99"]) == 0
    assert "has no node named crate_99" in capsys.readouterr().err
    assert main(["watch", str(scene), "-o", str(out), "--rays", "16", "--max-bakes", "1",
                 "--interval", "0.01"]) == 0
    assert "baked" in capsys.readouterr().out


def test_rebake_says_a_moved_name_the_scene_lacks_after_a_full_bake_too(
        tmp_path, capsys, monkeypatch):
    """``baker rebake --moved`` naming a node the scene has not: the note says so also when
    the rebake is priced out and a full bake is done (it was said after incremental ones only,
    so a machine where the last rebake's fixed work outweighed a full bake lost it)."""
    import baker.rebake.incremental as incremental_module

    out = tmp_path / "out.glb"
    scene = _room().save(tmp_path / "room.glb")
    args = ["--rays", "4", "--page-size", "64", "--shadow-rays", "1", "--threads", "1"]
    assert main(["bake", str(scene), "-o", str(out), *args]) == 0
    EDITS["box moved across the room"]().save(scene)

    def priced_out(path):
        raise FullBake("a rebake would cost more than a full bake (the test's price)")

    monkeypatch.setattr(incremental_module, "worth_reading", priced_out)
    capsys.readouterr()
    assert main(["rebake", str(scene), "-o", str(out), "--moved", "box1", "crate_99"]) == 0
    captured = capsys.readouterr()
    assert "full bake: a rebake would cost more" in captured.out
    assert "has no node named crate_99 (--moved)" in captured.err
    assert "the diff found" not in captured.err  # no diff was made to compare with


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_pre_commit_hook_bakes_each_scene_beside_it(tmp_path, capsys, suffix):
    """The hook bakes each scene into <stem>_baked beside it and stops the commit (exit 5,
    naming the files) whenever it wrote an output anew or with other bytes (a .gltf's .bin
    included): new outputs are files git does not track, which pre-commit would let through.
    Run again on the same scene, its rebake writes the same bytes: exit 0, the commit goes on;
    after an edit, exit 5 again."""
    hooks = (Path(__file__).resolve().parents[1] / ".pre-commit-hooks.yaml").read_text()
    assert "entry: baker hook" in hooks and "id: baker-bake" in hooks
    scene = box_room(BOXES[:1], room=ROOM).save(tmp_path / f"crate{suffix}")
    out = tmp_path / f"crate_baked{suffix}"
    written = [out, *([out.with_suffix(".bin")] if suffix == ".gltf" else [])]
    argv = ["hook", str(scene), str(out), "--rays", "4", "--page-size", "64"]
    assert main(argv) == OUTPUTS_CHANGED
    said = capsys.readouterr().err
    assert all(str(path) in said for path in written) and "commit again" in said, said
    assert out.exists() and default_path(out).exists()
    assert not (tmp_path / f"crate_baked_baked{suffix}").exists()  # outputs are not baked again
    assert main(argv) == 0
    assert "commit again" not in capsys.readouterr().err
    box_room(moved(BOXES[:1], BOXES[0]["name"], at=(0.5, -0.5)), room=ROOM).save(scene)
    assert main(argv) == OUTPUTS_CHANGED
    said = capsys.readouterr().err
    assert all(str(path) in said for path in written), said
    assert main(["hook", str(tmp_path / "missing.glb")]) == 1


def test_the_hook_has_git_ignore_the_bake_states(tmp_path, capsys):
    """In a git repository, after ``baker hook``: the baked output is not ignored, its bake
    state and timing record are, by one line added once to the folder's .gitignore (the lines
    there before kept)."""
    import subprocess

    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    (tmp_path / ".gitignore").write_text("*.tmp")  # no final newline
    scene = box_room(BOXES[:1], room=ROOM).save(tmp_path / "crate.glb")
    for code in (OUTPUTS_CHANGED, 0):  # its output and .gitignore new, then as they were
        assert main(["hook", str(scene), "--rays", "4", "--page-size", "64"]) == code
    assert capsys.readouterr().out.count("to " + str(tmp_path / ".gitignore")) == 1
    lines = (tmp_path / ".gitignore").read_text().splitlines()
    assert lines[0] == "*.tmp" and lines.count("*_baked.gl*.bake*") == 1

    def ignored(name: str) -> bool:
        return subprocess.run(["git", "-C", str(tmp_path), "check-ignore", "-q", name]).returncode == 0

    assert ignored("crate_baked.glb.bake") and ignored("crate_baked.glb.bake.json")
    assert not ignored("crate_baked.glb") and not ignored("crate.glb")


def test_relight_after_a_shrunk_default_density_casts_no_ray(tmp_path):
    """A default density too large for one page is lowered by the full bake; changing only the
    light's intensity and colour still recomposes (no ray) to the full bake's bytes."""
    from assets.light_scenes import lit_floor

    lit_floor("point", intensity=10.0).save(tmp_path / "scene.glb")
    settings = baker.Settings(rays=4, page_size=256, threads=1)
    first = baker.bake(tmp_path / "scene.glb", tmp_path / "lit.glb", settings)
    assert first.settings.texel_density < 0.99 * baker.settings.default_texel_density(
        16.0, 256)  # the 4 m floor's derived density did not fit and was lowered
    edited = lit_floor("point", intensity=40.0, color=(1.0, 0.5, 0.5)).save(tmp_path / "b.glb")
    again = baker.bake(edited, tmp_path / "lit.glb", settings, incremental="always")
    baker.bake(edited, tmp_path / "full.glb", settings)
    assert again.rebake["incremental"] is True, again.rebake.get("full_bake_reason")
    assert again.rebake["rays"] == 0
    assert (tmp_path / "lit.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()


def test_baker_relight_recomposes_without_rays_and_refuses_other_edits(tmp_path, capsys):
    from assets.light_scenes import lit_floor

    lit_floor("point", intensity=10.0).save(tmp_path / "scene.glb")
    out = tmp_path / "lit.glb"
    assert main(["bake", str(tmp_path / "scene.glb"), "-o", str(out), "--rays", "4",
                 "--page-size", "128", "--quiet"]) == 0
    moved_light = lit_floor("point", position=(0.5, 2.0, 0.0), intensity=10.0).save(
        tmp_path / "moved.glb")
    before = out.read_bytes()
    assert main(["relight", str(moved_light), "-o", str(out)]) == 1
    assert "cannot relight without tracing" in capsys.readouterr().err
    assert out.read_bytes() == before  # refused: nothing written
    brighter = lit_floor("point", intensity=25.0, color=(0.2, 0.4, 1.0)).save(tmp_path / "b.glb")
    assert main(["relight", str(brighter), "-o", str(out), "--report",
                 str(tmp_path / "r.json"), "--quiet"]) == 0
    import json
    assert json.loads((tmp_path / "r.json").read_text())["rebake"]["rays"] == 0
    assert main(["relight", str(brighter), "-o", str(out)]) == 0
    assert "\n  0 rays cast (the lightmaps rest on " in capsys.readouterr().out
    assert main(["bake", str(brighter), "-o", str(tmp_path / "full.glb"), "--rays", "4",
                 "--page-size", "128", "--quiet", "--no-state"]) == 0
    assert out.read_bytes() == (tmp_path / "full.glb").read_bytes()


def test_relight_is_never_priced_out_by_the_last_rebakes_time(tmp_path):
    """A relight casts no ray: however slow the state's last rebake was recorded (its overhead
    above the whole full bake, which prices an ordinary rebake out: ``cost.worth_reading``), a
    relight of it goes on, and gives the full bake's bytes."""
    import json

    from assets.light_scenes import lit_floor
    from baker.rebake.state import timing_path

    lit_floor("point", intensity=10.0).save(tmp_path / "scene.glb")
    out = tmp_path / "lit.glb"
    settings = baker.Settings(rays=4, page_size=64)
    baker.bake(tmp_path / "scene.glb", out, settings)
    record = timing_path(default_path(out))
    recorded = json.loads(record.read_text())
    record.write_text(json.dumps({**recorded, "rebake_overhead": 1e3 * recorded[
        "full_bake_seconds"], "rebake_correction": 1.0}))
    brighter = lit_floor("point", intensity=25.0, color=(0.2, 0.4, 1.0)).save(tmp_path / "b.glb")
    result = baker.bake(brighter, out, settings, relight=True)
    assert result.rebake["incremental"] and result.rebake["rays"] == 0
    baker.bake(brighter, tmp_path / "full.glb", settings, state=False)
    assert out.read_bytes() == (tmp_path / "full.glb").read_bytes()


def test_moving_an_alpha_cut_quad_rebakes_like_a_full_bake(tmp_path):
    """The dirty search casts against the moved geometry without its alpha (a ray through a hole
    counts as meeting it: more texels recomputed, never fewer); the recomputed texels use the
    full tracer with alpha tests, so the result is the full bake's, to the byte."""
    from assets.material_scenes import alpha_cut_quad

    settings = baker.Settings(rays=16, page_size=128, threads=1, texel_density=12.0, d_max=0.8)
    base = alpha_cut_quad()
    base.save(tmp_path / "before.glb")
    baker.bake(tmp_path / "before.glb", tmp_path / "incremental.glb", settings)
    edited = alpha_cut_quad()
    edited._nodes[edited.info["leaf"]].translation = [0.4, 0.0, -0.3]
    edited.save(tmp_path / "after.glb")
    result = baker.bake(tmp_path / "after.glb", tmp_path / "incremental.glb", settings,
                        incremental="always")
    baker.bake(tmp_path / "after.glb", tmp_path / "full.glb", settings)
    assert result.rebake["incremental"], result.rebake.get("full_bake_reason")
    assert 0 < result.rebake["dirty_fraction"] < 1
    assert (tmp_path / "incremental.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()
    assert (default_path(tmp_path / "incremental.glb").read_bytes()
            == default_path(tmp_path / "full.glb").read_bytes())


def test_rebake_reports_its_time_against_the_last_full_bake(base, tmp_path, capsys):
    scene = EDITS["box moved across the room"]().save(tmp_path / "edited.glb")
    shutil.copy(default_path(base), default_path(tmp_path / "out.glb"))
    assert baker.rebake.state.last_full_bake_seconds(default_path(tmp_path / "out.glb")) is None
    shutil.copy(baker.rebake.state.timing_path(default_path(base)),
                baker.rebake.state.timing_path(default_path(tmp_path / "out.glb")))
    full = baker.rebake.state.last_full_bake_seconds(default_path(base))
    assert full is not None and full > 0
    result = baker.bake(scene, tmp_path / "out.glb", SETTINGS, incremental="always")
    assert result.rebake["last_full_bake_seconds"] == full
    assert 0 < result.rebake["seconds"] == result.seconds
    assert main(["rebake", str(scene), "-o", str(tmp_path / "out.glb")]) == 0
    assert f"of the last full bake ({full:.2f} s)" in capsys.readouterr().out


def _baked_copy(base: Path, folder: Path) -> Path:
    """A copy of the base room's baked output, with its state, in a new ``folder``."""
    folder.mkdir()
    output = folder / base.name
    shutil.copy(base, output)
    shutil.copy(default_path(base), default_path(output))
    return output


def test_a_failed_write_leaves_the_old_state_and_no_temporary(base, tmp_path, monkeypatch):
    """The state is written while the pages are encoded, but put in place only once the output
    is: when writing the output fails, the previous state stays as it was, byte for byte, and
    no temporary file is left beside it."""
    import importlib

    bake_module = importlib.import_module("baker.api")
    output = _baked_copy(base, tmp_path / "out")
    folder = output.parent
    before = default_path(output).read_bytes()

    def failing_write(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(bake_module, "write", failing_write)
    edited = _room(moved(BOXES, "box0", at=(-1.0, 1.3))).save(tmp_path / "edited.glb")
    with pytest.raises(OSError, match="disk full"):
        baker.bake(edited, output, SETTINGS, incremental="always")
    assert default_path(output).read_bytes() == before
    assert sorted(p.name for p in folder.iterdir()) == sorted(
        [output.name, default_path(output).name])


def test_the_state_a_rebake_replaces_is_freed_beside_it_and_leaves_nothing(base, tmp_path,
                                                                           monkeypatch):
    """The old state (as every file a bake replaces) is given a second name before the new one
    replaces it, and deleted on a thread of its own (``spill.set_aside``, ``remove_later``);
    once those threads are done, the folder holds the output and the state only."""
    import importlib
    import threading

    staging = importlib.import_module("baker.run.atomic")
    monkeypatch.setattr(importlib.import_module("baker.run.spill"), "LATER_BYTES", 0)
    output = _baked_copy(base, tmp_path / "out")
    folder = output.parent
    old = default_path(output).read_bytes()
    later, threads = [], []

    def remove_later(path):
        later.append((path, Path(path).read_bytes() == old))
        before = set(threading.enumerate())
        real_remove_later(path)
        threads.extend(t for t in threading.enumerate() if t not in before)

    real_remove_later = staging.remove_later
    monkeypatch.setattr(staging, "remove_later", remove_later)
    edited = _room(moved(BOXES, "box0", at=(-1.0, 1.3))).save(tmp_path / "edited.glb")
    assert baker.bake(edited, output, SETTINGS, incremental="always").rebake["incremental"]
    assert [was_the_old_state for _, was_the_old_state in later].count(True) == 1
    assert all(Path(path).parent == folder for path, _ in later)
    for thread in threads:
        thread.join()
    assert sorted(p.name for p in folder.iterdir()) == sorted(
        [output.name, default_path(output).name])
    assert default_path(output).read_bytes() != old


def test_state_leaves_out_arrays_of_zeros_and_reads_them_back(base):
    """Arrays of zeros (the atlas's page numbers on a single page) are listed in the header
    instead of stored, and read back equal (same dtype, shape and bytes). Terms a room without
    sky or mirrors does not have are not held at all (0 rows)."""
    import json

    from baker.rebake.state import state_classes

    path = default_path(base)
    with zipfile.ZipFile(path) as archive:
        names = set(archive.namelist())
        zeros = json.loads(archive.read("header.json"))["zeros"]
    assert "atlas/pages" in zeros and "atlas/pages.npy" not in names
    assert "terms/w_hit" not in zeros and "terms/w_hit.npy" in names
    stored = baker.rebake.state.load(path, state_classes())
    pages = stored.atlas.instances[0].pages
    assert len(pages) == stored.atlas.instances[0].triangles.shape[0] and pages.dtype == np.int64
    assert sum(len(u.pages) for u in stored.atlas.instances) == zeros["atlas/pages"]["shape"][0]
    assert not pages.any() and len(pages) > 0
    assert stored.groups["direct"].sky.shape == (0, 3)
    assert stored.groups["terms"].chain_rays.shape == (0,)


def test_state_stores_repeated_and_sparse_arrays_compactly_and_reads_them_back(base, tmp_path):
    """The ray counts (64 for every texel) are stored as one row, how far the validity probes
    moved each point (0 for almost all) as its rows that are not 0: and every array reads back
    with the bits, shape and dtype it was written with."""
    import json

    from baker.rebake.state import state_classes

    path = default_path(base)
    with zipfile.ZipFile(path) as archive:
        header = json.loads(archive.read("header.json"))
        sizes = {info.filename: info.file_size for info in archive.infolist()}
    assert "terms/counts" in header["repeated"] and sizes["terms/counts.npy"] < 200
    assert "validity/moved_by" in header["sparse"] and "validity/moved_by.rows.npy" in sizes
    assert "terms/w_hit" not in header["sparse"] and "terms/w_hit" not in header["repeated"]
    stored = baker.rebake.state.load(path, state_classes())
    again = tmp_path / "again.bake"
    with open(again, "wb") as file:
        baker.rebake.state.write_state(file, stored)
    assert again.read_bytes() == path.read_bytes()
    counts = stored.groups["terms"].counts
    assert counts.dtype == np.int64 and counts.shape == (header["repeated"]["terms/counts"][
        "shape"][0],) and (counts == SETTINGS.rays).all()
    moved_by = stored.groups["validity"].moved_by
    assert moved_by.shape == tuple(header["sparse"]["validity/moved_by"]["shape"])
    assert 0 < np.count_nonzero(moved_by) < len(moved_by) / 4


def _with_crate(builder, at):
    """``builder`` with a 0.3 m grey crate standing at ``at`` (x, z) on its floor."""
    from assets.gltf_builder import box

    grey = builder.material("crate", (0.5, 0.4, 0.3))
    builder.node("crate", builder.shape_mesh("crate", box((0.3, 0.3, 0.3)), material=grey),
                 translation=(at[0], 0.15, at[1]))
    return builder


@pytest.mark.parametrize("scene", ["mirror", "leaf"])
def test_moves_seen_through_mirrors_and_leaves_rebake_like_a_full_bake(tmp_path, scene):
    """A crate moved where a floor texel sees it only in a mirror (its rays reflected), or under a
    leaf (the leaf's back-face rays): the rebake still gives the full bake's bytes."""
    from assets.material_scenes import leaf, mirror_wall

    make = {"mirror": lambda: mirror_wall(size=4.0, height=2.0),
            "leaf": lambda: leaf(height=1.2, translucency=0.5)}[scene]
    start, end = {"mirror": ((-1.5, -1.5), (1.6, 1.2)), "leaf": ((-1.6, 1.6), (0.2, 0.1))}[scene]
    settings = baker.Settings(rays=16, page_size=128, threads=1, texel_density=10.0, d_max=1.5)
    result = _crate_moved(tmp_path, make, start, end, settings)
    assert result.rebake["dirty_fraction"] < 1


def _crate_moved(tmp_path, make, start, end, settings):
    """Bake ``make()`` with a crate at ``start``, then rebake it with the crate at ``end`` and
    bake that fully: check the rebake was incremental and gave the same bytes; return it."""
    _with_crate(make(), start).save(tmp_path / "before.glb")
    _with_crate(make(), end).save(tmp_path / "after.glb")
    baker.bake(tmp_path / "before.glb", tmp_path / "incremental.glb", settings)
    result = baker.bake(tmp_path / "after.glb", tmp_path / "incremental.glb", settings,
                        incremental="always")
    baker.bake(tmp_path / "after.glb", tmp_path / "full.glb", settings)
    assert result.rebake["incremental"], result.rebake.get("full_bake_reason")
    assert (tmp_path / "incremental.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()
    return result


def test_a_small_move_at_the_edge_of_the_scene_still_rebakes(tmp_path):
    """Moving a crate that sticks out past the floor a centimetre further grows the scene's
    bounds: the tracer's frame (snapped to 1/16 of the scene's size) and the derived d_max (a
    quarter octave) stay, so the rebake is incremental and gives the full bake's bytes."""
    from assets.material_scenes import leaf

    settings = baker.Settings(rays=16, page_size=128, threads=1, texel_density=10.0)
    _crate_moved(tmp_path, lambda: leaf(height=0.5, facing="up-opaque"), (2.1, 0.0), (2.11, 0.0),
                 settings)


def test_a_box_moved_out_of_the_room_keeps_the_derived_d_max(tmp_path, capsys):
    """A box pushed out through a wall grows the baked bounds, whose diagonal the automatic
    d_max follows (a quarter octave of it): the bake keeps the last one's instead
    (``asked.kept_d_max``), says so and records it as asked. The tracer's frame moved
    with the bounds, so it bakes fully — with the kept d_max: the bytes of a full bake given
    it."""
    before = _room().save(tmp_path / "before.glb")
    after = _room(moved(BOXES, "box1", at=(4.0, 0.0))).save(tmp_path / "after.glb")
    first = baker.bake(before, tmp_path / "incremental.glb", SETTINGS)
    derived = baker.bake(after, tmp_path / "fresh.glb", SETTINGS).settings.d_max
    assert derived != first.settings.d_max
    assert main(["bake", str(after), "-o", str(tmp_path / "incremental.glb"), "--rays", "16",
                 "--page-size", "128", "--shadow-rays", "4", "--threads", "1"]) == 0
    said = capsys.readouterr().out
    assert "full bake: the scene's bounds changed" in said, said
    assert (f"d_max {first.settings.d_max:.4g} kept from the last bake (the scene's bounds now "
            f"derive {derived:.4g}: --d-max {derived:.4g} to take it)") in said, said
    baker.bake(after, tmp_path / "full.glb", replace(SETTINGS, d_max=first.settings.d_max))
    assert (tmp_path / "incremental.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()
    assert (default_path(tmp_path / "incremental.glb").read_bytes()
            == default_path(tmp_path / "full.glb").read_bytes())


def test_texels_touching_a_corner_follow_the_full_bake_after_any_move(tmp_path):
    """Sample points clamped into a room's corners would lie in the walls and floor, where which
    of the triangles there a probe meets first depends on Embree's BVH of the whole scene, which
    a crate moved far away changes. They are drawn off the edges (``rasterise.INSET``): almost no
    texel touches other geometry (the few that do are redone), and the bytes match a full
    bake. Without the inset, 2,080 of the room's 34,964 texels touch."""
    room = (12.0, 3.0, 12.0)
    crates = grid_boxes(10, room=room, size=0.4)
    crate = min(crates, key=lambda c: c["size"][0] * c["size"][1] * c["size"][2])
    settings = baker.Settings(page_size=256, rays=16, threads=1)
    box_room(crates, room=room).save(tmp_path / "before.glb")
    box_room(moved(crates, crate["name"], at=(-0.9 * crate["at"][0], -0.9 * crate["at"][1])),
             room=room).save(tmp_path / "after.glb")
    baker.bake(tmp_path / "before.glb", tmp_path / "incremental.glb", settings)
    result = baker.bake(tmp_path / "after.glb", tmp_path / "incremental.glb", settings,
                        incremental="always")
    baker.bake(tmp_path / "after.glb", tmp_path / "full.glb", settings)
    assert result.rebake["incremental"], result.rebake.get("full_bake_reason")
    # 795 texels near the crate's two places (2.3 %); with the corners' 2,080 it was 8.3 %
    assert result.rebake["dirty_by_reason"]["validity"] < 0.04 * result.rebake["texels"]
    assert (default_path(tmp_path / "incremental.glb").read_bytes()
            == default_path(tmp_path / "full.glb").read_bytes())
    assert (tmp_path / "incremental.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()


def test_the_shadow_ray_prefilter_keeps_every_texel_whose_rays_meet_the_move(tmp_path,
                                                                              monkeypatch):
    """``shadows.may_shadow`` skips the texels whose shadow rays cannot pass the moved box (by
    the rays' geometry); with a soft point light, a spot and a soft sun, the rebake finds the
    same shadow-dirty texels as when every texel's shadow rays are cast, and the same bytes."""
    from baker.rebake import shadows

    def lit(boxes):
        builder = _room(boxes, lamp=dict(LAMP, radius=0.3))
        sun = builder.light("directional", name="sun", intensity=3.0,
                            extras={"angular_diameter": 8.0})
        spot = builder.light("spot", name="spot", intensity=8.0, outer_cone=0.6)
        builder.node("sun", extensions={"KHR_lights_punctual": {"light": sun}},
                     rotation=quat_axis_angle((1, 0, 0.3), -50.0))
        builder.node("spot", translation=(1.5, 2.0, -1.0), rotation=quat_axis_angle((1, 0, 0), -80.0),
                     extensions={"KHR_lights_punctual": {"light": spot}})
        return builder

    settings = baker.Settings(rays=8, page_size=128, shadow_rays=4, d_max=0.3)
    before = lit(BOXES).save(tmp_path / "before.glb")
    after = lit(moved(BOXES, "box1", at=(0.4, 0.6))).save(tmp_path / "after.glb")
    found = {}
    for name, prefilter in (("all", False), ("filtered", True)):
        if not prefilter:
            monkeypatch.setattr(shadows, "may_shadow",
                                lambda texels, rows, *_: np.ones(len(rows), bool))
        baker.bake(before, tmp_path / f"{name}.glb", settings)
        result = baker.bake(after, tmp_path / f"{name}.glb", settings, incremental="always")
        found[name] = (result.rebake["dirty_by_reason"], result.report["rebake"]["test_rays"],
                       (tmp_path / f"{name}.glb").read_bytes())
        monkeypatch.undo()
    assert found["filtered"][0] == found["all"][0] and found["all"][0]["shadow"] > 10
    assert found["filtered"][2] == found["all"][2]
    assert found["filtered"][1] < 0.7 * found["all"][1]  # most texels' shadow rays not cast


def test_moving_a_node_of_a_scene_with_nothing_baked(tmp_path):
    """SimpleInstancing's only node is GPU-instanced, so nothing is baked (0 texels): moving it
    rebakes incrementally (no texel to redo) and gives the full bake's bytes. The validity
    check of 0 texels once raised a numpy reshape error."""
    import pygltflib
    from bakehelp import REAL_SCENES

    document = pygltflib.GLTF2().load(str(REAL_SCENES["SimpleInstancing"]))
    shutil.copy(REAL_SCENES["SimpleInstancing"], tmp_path / "before.glb")
    document.nodes[0].translation = [0.05, 0.0, 0.0]
    document.save(str(tmp_path / "after.glb"))
    settings = baker.Settings(page_size=64, rays=4)
    baker.bake(tmp_path / "before.glb", tmp_path / "inc.glb", settings)
    result = baker.bake(tmp_path / "after.glb", tmp_path / "inc.glb", settings, incremental="always")
    assert result.rebake["incremental"] and result.rebake["changes"] == ["node nodes[0] moved"]
    assert result.texels == 0 and result.rebake["dirty_texels"] == 0
    baker.bake(tmp_path / "after.glb", tmp_path / "full.glb", settings)
    assert (tmp_path / "inc.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()
    assert default_path(tmp_path / "inc.glb").read_bytes() == default_path(
        tmp_path / "full.glb").read_bytes()


def test_state_atlas_joins_the_instances_and_splits_them_back(tmp_path):
    """The atlas is stored as one array per ``InstanceUV`` field over all instances (not four
    members per instance) and read back instance by instance with the same bits — including
    an instance with no triangles."""
    from baker.atlas.layout import Atlas, InstanceUV

    rng = np.random.default_rng(2)
    units = tuple(InstanceUV(instance=i, vertices=rng.integers(0, 99, k),
                             triangles=rng.integers(0, max(k, 1), (m, 3)), uv=rng.random((k, 2)),
                             pages=rng.integers(-1, 3, m))
                  for i, (k, m) in zip((4, 0, 7), ((5, 3), (0, 0), (9, 11))))
    atlas = Atlas(width=64, height=32, page_count=3, texel_density=12.5, padding=2,
                  instances=units)
    path = tmp_path / "atlas.bake"
    with open(path, "wb") as file:
        baker.rebake.state.write_state(file, baker.rebake.state.BakeState(
            fingerprints={}, atlas=atlas, groups={}, instance_world=np.zeros((0, 4, 4))))
    with zipfile.ZipFile(path) as archive:
        assert sum(name.startswith("atlas/") for name in archive.namelist()) == 6
    back = baker.rebake.state.load(path, {}).atlas
    assert (back.width, back.height, back.page_count, back.texel_density, back.padding) == (
        64, 32, 3, 12.5, 2)
    assert [u.instance for u in back.instances] == [4, 0, 7]
    for mine, theirs in zip(units, back.instances):
        for name in ("vertices", "triangles", "uv", "pages"):
            a, b = getattr(mine, name), getattr(theirs, name)
            assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def test_rays_stopped_before_the_moved_box_leave_their_texels_clean(tmp_path, monkeypatch):
    """A ray that meets the moved box only behind a surface that did not move has that surface
    as its first hit before and after the move (``judges.HitsCompared``): the texels behind a
    screen are not recomputed, and the rebake still gives the full bake's bytes."""
    from baker.rebake.judges import HitsCompared

    screen = {"name": "screen", "size": (0.1, 1.2, 2.5), "at": (0.1, 0.5), "colour": "crate"}
    settings = baker.Settings(rays=16, page_size=128, shadow_rays=4, threads=1, d_max=1.5)
    before = _room(BOXES + [screen]).save(tmp_path / "before.glb")
    after = _room(moved(BOXES, "box3", at=(0.67, 0.55)) + [screen]).save(tmp_path / "after.glb")
    baker.bake(after, tmp_path / "full.glb", settings)
    found = {}
    for name in ("every ray that meets it", "first hits only"):
        if name == "every ray that meets it":
            judged = HitsCompared.__call__  # every ray that meets it: changed
            monkeypatch.setattr(HitsCompared, "__call__",
                                lambda self, *rays: judged(self, *rays) | True)
        out = tmp_path / f"{name}.glb"
        baker.bake(before, out, settings)
        result = baker.bake(after, out, settings, incremental="always")
        assert result.rebake["incremental"]
        found[name] = result.rebake["dirty_by_reason"]["obscurance"]
        assert out.read_bytes() == (tmp_path / "full.glb").read_bytes()
        assert default_path(out).read_bytes() == default_path(tmp_path / "full.glb").read_bytes()
        monkeypatch.undo()
    # Measured 0.88 (434 of 493) with xatlas's atlas, 0.91 (416 of 457) with charts packed
    # as rectangles (atlas/packing.py): the texels behind the screen are about a tenth.
    assert found["first hits only"] < 0.93 * found["every ray that meets it"], found


def test_the_cell_search_finds_the_rays_drawing_them_all_finds():
    """``near_rays.drawn_near_rays`` finds the rays of texels far from the spheres cell by cell
    (``_cell_candidates``) and draws all the rays of the others: the same rays, bit for bit,
    as drawing every texel's rays, for texels near and far, facing the spheres or not, and ray
    counts that are powers of two or not. Half the texels' hemispheres tilt from their front
    faces (shading normals), so some of their rays are folded above the face
    (``sampling.fold``): every ray whose folded direction passes near a sphere is found."""
    from baker.rebake.near_rays import drawn_near_rays
    from baker.light.hemisphere import cosine_directions
    from baker.rays.sampling import folded, tangent_frames

    rng = np.random.default_rng(6)
    for rays in (16, 64, 100):
        count = 3000
        normals = rng.normal(size=(count, 3))
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        geometric = normals + np.where(np.arange(count)[:, None] % 2, 0.6, 0.0) * rng.normal(
            size=(count, 3))
        geometric /= np.linalg.norm(geometric, axis=1)[:, None]
        starts = rng.uniform(-3, 3, (count, 3))
        centres = np.array([[0.3, 0.2, -0.1], [1.2, -0.4, 0.5]])
        radii = np.array([0.25, 0.1])
        keys = rng.integers(0, 2**40, count).astype(np.uint64)
        t1, t2 = tangent_frames(normals)
        args = (0, np.uint64(11), keys, rays, starts, t1, t2, normals, geometric,
                centres, radii, 2.5)
        found = [sorted(zip(*(a.tolist() for a in drawn_near_rays(*args, cells))))
                 for cells in (True, False)]
        assert found[0] == found[1] and len(found[0]) > 100, rays
        x, y, z = cosine_directions(keys, rays, 11, "sobol")
        drawn = np.repeat(normals, rays, axis=0)
        world = (x[:, None] * np.repeat(t1, rays, axis=0) + y[:, None] * np.repeat(t2, rays, axis=0)
                 + z[:, None] * drawn)
        world = folded(world, drawn, np.repeat(geometric, rays, axis=0))
        assert (np.einsum("ij,ij->i", world, np.repeat(geometric, rays, axis=0)) >= -1e-12).all()
        offset = centres[None] - np.repeat(starts, rays, axis=0)[:, None]  # (k·rays, 2, 3)
        along = np.clip(np.einsum("rbc,rc->rb", offset, world), 0.0, 2.5)  # closest on the ray
        near = (np.linalg.norm(offset - along[..., None] * world[:, None], axis=2)
                < radii).any(axis=1)
        folded_near = set(zip(*(a.tolist() for a in np.divmod(np.flatnonzero(near), rays))))
        assert folded_near <= {(t, s) for t, s, *_ in found[0]}, rays
        tilted = np.arange(count) % 2 == 1
        assert sum(tilted[t] for t, _ in folded_near) > 30


def test_a_state_with_zip64_members_reads_back_and_rebakes(tmp_path, monkeypatch):
    """Past 2 GiB (a 4096² bake's state) members and offsets get ZIP64 fields; forced here
    for every member, the state reads back and the rebake still gives the full bake's bytes."""
    from baker.rebake import zipwriter as zipwriter

    monkeypatch.setattr(zipwriter, "ZIP64_LIMIT", 16)
    scene = _room().save(tmp_path / "room.glb")
    baker.bake(scene, tmp_path / "out.glb", SETTINGS)
    assert b"PK\x06\x06" in default_path(tmp_path / "out.glb").read_bytes()
    incremental, full = _rebake_and_full(tmp_path / "out.glb", EDITS["box moved across the room"](),
                                         tmp_path)
    assert incremental.rebake["incremental"], incremental.rebake.get("full_bake_reason")
    assert (tmp_path / "incremental.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()
    assert (default_path(tmp_path / "incremental.glb").read_bytes()
            == default_path(tmp_path / "full.glb").read_bytes())


@pytest.mark.parametrize("case", ["recovered", "not recovered", "albedo above 1"])
def test_texels_whose_rays_the_move_changed_recast_only_those_rays(tmp_path, monkeypatch, case):
    """In a diffuse scene a texel whose rays meet the moved box takes the change of those rays
    alone (``exact_sums.ray_changes``): far fewer rays than its own are cast. Where its stored
    sums are not recovered exactly (forced here), or an albedo above 1 could make sums inexact
    (``Surfaces.exact_sums``), it is traced anew. The bytes are the full bake's either way."""
    from baker.rebake import exact_sums
    from baker.rebake import incremental as incremental

    if case == "not recovered":
        exactness = exact_sums.changed_terms
        monkeypatch.setattr(incremental, "changed_terms", lambda terms, changes: (
            exactness(terms, changes)[0], np.zeros(len(changes), bool)))
    colours = {"accent": (3.0, 0.5, 0.9)} if case == "albedo above 1" else {}
    settings = baker.Settings(rays=16, page_size=128, shadow_rays=4, threads=1, d_max=1.5)
    before = _room(lamp=None, colours=colours).save(tmp_path / "before.glb")
    after = _room(moved(BOXES, "box1", at=(1.2, -1.1)), lamp=None, colours=colours).save(
        tmp_path / "after.glb")
    baker.bake(after, tmp_path / "full.glb", settings)
    baker.bake(before, tmp_path / "out.glb", settings)
    result = baker.bake(after, tmp_path / "out.glb", settings, incremental="always")
    assert (tmp_path / "out.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()
    assert default_path(tmp_path / "out.glb").read_bytes() == default_path(
        tmp_path / "full.glb").read_bytes()
    info = result.rebake
    by_reason = info["dirty_by_reason"]
    assert by_reason["obscurance"] > 100
    traced = (by_reason["own"] + by_reason["validity"]) * settings.rays
    if case == "recovered":
        assert info["rays"] < traced + 0.3 * by_reason["obscurance"] * settings.rays, info
    else:
        assert info["rays"] >= traced + by_reason["obscurance"] * settings.rays, info


def test_far_texels_whose_probes_see_the_same_faces_keep_their_validity(tmp_path, monkeypatch):
    """A far texel's validity changes only if one of its hemisphere probes meets a back face
    first before the move and not after, or the other way round (``judges.ProbesCompared``):
    the texels whose probes merely see the moved box are not probed again, and the rebake still
    gives the full bake's bytes."""
    from baker.rebake import dirty
    from baker.rebake.judges import ProbesCompared

    settings = baker.Settings(rays=16, page_size=128, shadow_rays=4, threads=1, d_max=1.5)
    before = _room(lamp=None).save(tmp_path / "before.glb")
    after = _room(moved(BOXES, "box1", at=(1.2, -1.1)), lamp=None).save(tmp_path / "after.glb")
    baker.bake(after, tmp_path / "full.glb", settings)
    probed = {}
    check = dirty.check_texels
    for name in ("every probe that meets it", "back faces compared"):
        if name == "every probe that meets it":
            judged = ProbesCompared.__call__
            monkeypatch.setattr(ProbesCompared, "__call__",
                                lambda self, *probes: judged(self, *probes) | True)
        monkeypatch.setattr(dirty, "check_texels", lambda *args, **kwargs: (
            probed.__setitem__(name, len(args[3])) or check(*args, **kwargs)))
        out = tmp_path / f"{name}.glb"
        baker.bake(before, out, settings)
        assert baker.bake(after, out, settings, incremental="always").rebake["incremental"]
        assert out.read_bytes() == (tmp_path / "full.glb").read_bytes()
        assert default_path(out).read_bytes() == default_path(tmp_path / "full.glb").read_bytes()
        monkeypatch.undo()
    assert probed["back faces compared"] < 0.8 * probed["every probe that meets it"], probed


@pytest.mark.parametrize("dear", [True, False], ids=["probes dear", "tracing dear"])
def test_a_rebake_dearer_than_a_full_bake_falls_back_to_one(tmp_path, dear):
    """With d_max across the room, a moved box reaches every texel. Priced by a last full bake
    that spent its time on validity probes (which the dirty search pays for each texel within
    reach), the rebake would cost more than a full bake: it bakes fully, says why, and gives a
    full bake's bytes. Priced by one that spent it tracing (which a rebake does only for the
    box's own texels), it rebakes."""
    settings = replace(SETTINGS, d_max=3.0)
    before = _room().save(tmp_path / "before.glb")
    after = EDITS["box moved across the room"]().save(tmp_path / "after.glb")
    baker.bake(before, tmp_path / "incremental.glb", settings)
    state = default_path(tmp_path / "incremental.glb")
    stages = {"load": 0.01, "validity": 0.7 if dear else 0.1, "trace": 0.1 if dear else 0.7,
              "direct": 0.1, "compose": 0.1}
    baker.rebake.state.save_full_bake_seconds(state, 1.0, stages=stages)
    result = baker.bake(after, tmp_path / "incremental.glb", settings, incremental=True)
    baker.bake(after, tmp_path / "full.glb", settings)
    assert (tmp_path / "incremental.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()
    assert state.read_bytes() == default_path(tmp_path / "full.glb").read_bytes()
    info = result.rebake
    assert info["incremental"] is (not dear), info.get("full_bake_reason")
    if dear:
        assert "a rebake would cost more than a full bake" in info["full_bake_reason"]
        assert "(the last took 1.00 s)" in info["full_bake_reason"]


def test_rebake_cost_prices_the_texels_by_the_stages_of_a_full_bake():
    """Half the texels redone whole at ``REDO_COST`` times their validity, trace and direct
    light (0.8 of the full bake), the rest searched at ``SEARCH_COST`` times their probes
    (validity 0.4); compose and write 0.1; a full bake from there redoes all but its 0.1 of
    loading, lights and plan (the rebake has done them and hands them over)."""
    from baker.rebake import cost

    stages = {"load": 0.5, "lights": 0.3, "plan": 0.2, "validity": 4.0, "trace": 3.0, "direct": 1.0, "compose": 0.5,
              "write": 0.5}
    scaling, tail, full = cost.rebake_cost(stages, 0.5, 0.5)
    redo, search = cost.REDO_COST, cost.SEARCH_COST
    assert scaling == pytest.approx(0.5 * redo * 0.8 + 0.5 * search * 0.4)
    assert tail == pytest.approx(0.1) and full == pytest.approx(0.9)
    assert cost.rebake_cost(stages, 0.0, 0.0)[0] == 0.0


@pytest.mark.parametrize("material, priced_out", [("wall", True), ("accent", False)])
def test_a_recolour_is_priced_before_its_search(tmp_path, material, priced_out):
    """A recolour was never priced: recolouring what every texel sees (the room's walls)
    redid nearly all of them after a search about as long as a trace (2.3× a full bake in a
    room of 60 crates). Its search is now tried on a sample of the texels first: the walls
    bake fully and say why, the accent box (a few texels see it) still rebakes; both give the
    full bake's bytes."""
    before = _room().save(tmp_path / "before.glb")
    after = _room(colours={material: (0.1, 0.5, 0.9)}).save(tmp_path / "after.glb")
    baker.bake(before, tmp_path / "out.glb", SETTINGS)
    result = baker.bake(after, tmp_path / "out.glb", SETTINGS, incremental=True)
    reason = result.rebake.get("full_bake_reason", "")
    assert result.rebake["incremental"] is not priced_out, reason
    if priced_out:
        assert reason.startswith("a rebake would cost more than a full bake: the edit reaches")
    else:
        assert 0 < result.rebake["dirty_fraction"] < 0.5
    baker.bake(after, tmp_path / "full.glb", SETTINGS)
    assert (tmp_path / "out.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()


def test_a_rebake_asked_for_whatever_it_costs_still_prices_and_measures_itself(tmp_path):
    """``incremental="always"`` rebakes however dear the model finds it (told the last rebake
    took 8× the model, a priced rebake of this move bakes fully), yet it still reports the
    model's figure for its search and rays and records what they took over it: how
    bench_rebake_cost.py measures the model, and what the next priced rebake goes by."""
    before = _room().save(tmp_path / "before.glb")
    after = EDITS["box moved across the room"]().save(tmp_path / "after.glb")
    baker.bake(before, tmp_path / "out.glb", SETTINGS)
    state = default_path(tmp_path / "out.glb")
    first = baker.rebake.state.last_full_bake(state)
    baker.rebake.state.save_full_bake_seconds(state, first["full_bake_seconds"],
                                              stages=first["stage_seconds"],
                                              rebake_correction=1e6)
    result = baker.bake(after, tmp_path / "out.glb", SETTINGS, incremental="always")
    assert result.rebake["incremental"], result.rebake.get("full_bake_reason")
    modelled = result.rebake["modelled_seconds"]
    assert modelled is not None and modelled > 0
    stages = result.report["stage_seconds"]
    spent = stages["dirty"] + stages["trace"] + stages["direct"]
    record = baker.rebake.state.last_full_bake(state)
    assert record["rebake_correction"] == pytest.approx(spent / modelled, rel=1e-3)


def test_a_rebake_measures_itself_and_the_next_one_of_the_state_goes_by_it(tmp_path):
    """A rebake records beside the state what its search and rays took over the cost model's
    figure (``rebake_measured``); the next rebake of that state scales the model by it: told
    that the last rebake took 8× the model (the most it believes), a move the model alone
    would rebake bakes fully, and says why, with a full bake's bytes."""
    before = _room().save(tmp_path / "before.glb")
    after = EDITS["box moved across the room"]().save(tmp_path / "after.glb")
    baker.bake(before, tmp_path / "out.glb", SETTINGS)
    state = default_path(tmp_path / "out.glb")
    shutil.copy(state, tmp_path / "first.bake")
    shutil.copy(baker.rebake.state.timing_path(state),
                baker.rebake.state.timing_path(tmp_path / "first.bake"))
    result = baker.bake(after, tmp_path / "out.glb", SETTINGS, incremental=True)
    assert result.rebake["incremental"], result.rebake.get("full_bake_reason")
    record = baker.rebake.state.last_full_bake(state)
    stages = result.report["stage_seconds"]
    spent = stages["dirty"] + stages["trace"] + stages["direct"]
    modelled = result.rebake["modelled_seconds"]
    assert record["rebake_correction"] == pytest.approx(spent / modelled, rel=1e-3)
    first = baker.rebake.state.last_full_bake(tmp_path / "first.bake")
    assert record["full_bake_seconds"] == first["full_bake_seconds"]
    shutil.copy(tmp_path / "first.bake", state)
    baker.rebake.state.save_full_bake_seconds(state, first["full_bake_seconds"],
                                              stages=first["stage_seconds"],
                                              rebake_correction=1e6)
    again = baker.bake(after, tmp_path / "out.glb", SETTINGS, incremental=True)
    reason = again.rebake.get("full_bake_reason", "")
    assert "× 8.00 as the last rebake of this state measured" in reason, reason
    baker.bake(after, tmp_path / "full.glb", SETTINGS)
    assert (tmp_path / "out.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()
    # The time a rebake took besides its search and rays is measured too; when it is more
    # than the whole full bake, the next rebake of that state does not even read it.
    assert record["rebake_overhead"] == pytest.approx(
        result.rebake["seconds"] - result.rebake["compile_seconds"] - spent, abs=0.02)
    shutil.copy(tmp_path / "first.bake", state)
    baker.rebake.state.save_full_bake_seconds(state, 0.5, stages=first["stage_seconds"],
                                              rebake_overhead=0.6)
    third = baker.bake(after, tmp_path / "out.glb", SETTINGS, incremental=True)
    assert third.rebake["full_bake_reason"] == (
        "a rebake would cost more than a full bake: the last rebake of this state took 0.60 s "
        "besides its search and rays, the last full bake 0.50 s in all")
    assert (tmp_path / "out.glb").read_bytes() == (tmp_path / "full.glb").read_bytes()

def test_the_state_docs_name_the_format_version_a_state_carries(base):
    """docs/bake_state.md's title and header table name the version a written state's header
    holds (``state.VERSION``): a format change that forgets its docs fails here."""
    import json
    import re

    with zipfile.ZipFile(default_path(base)) as archive:
        version = json.loads(archive.read("header.json"))["version"]
    text = (Path(__file__).resolve().parent.parent / "docs" / "bake_state.md").read_text()
    assert re.search(r"format version (\d+)", text).group(1) == str(version)
    assert re.search(r"`version` = `(\d+)`", text).group(1) == str(version)
