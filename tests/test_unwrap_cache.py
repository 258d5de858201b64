"""Unwraps cached across bakes (``baker/atlas/unwrap_cache.py``): the bytes of a bake do not
depend on whether the cache was hit, missed, off, corrupted or unwritable, and an entry is used
exactly when xatlas's input is the same (a rigid move of a node keeps it)."""

from __future__ import annotations

import os

import numpy as np
import pytest

import baker
from assets.make_scenes import cornell_box
from assets.rebake_scenes import box_room, grid_boxes, moved
from baker.atlas import unwrap as unwrap_module
from baker.atlas import unwrap_cache

SETTINGS = baker.Settings(page_size=128, rays=4, shadow_rays=1, threads=1)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A cache folder of the test's own."""
    place = tmp_path / "cache"
    monkeypatch.setenv("BAKER_CACHE_DIR", str(place))
    return place


def _entries(place):
    return sorted((place / "unwrap").glob("*.npz")) if (place / "unwrap").is_dir() else []


def _no_xatlas(monkeypatch):
    """From here on, running xatlas fails the test: the unwrap must come from the cache."""
    def refuse(*args, **kwargs):
        raise AssertionError("xatlas ran although its input was cached")
    monkeypatch.setattr(unwrap_module, "call_forked_together", refuse)


def _bake(scene, out, settings=SETTINGS):
    baker.bake(scene, out, settings, state=False)
    return out.read_bytes()


def test_a_bake_from_the_cache_has_the_bytes_of_one_without(tmp_path, cache, monkeypatch):
    scene = cornell_box().save(tmp_path / "cornell.glb")
    cold = _bake(scene, tmp_path / "cold.glb")
    assert len(_entries(cache)) == 1
    with monkeypatch.context() as m:
        _no_xatlas(m)
        assert _bake(scene, tmp_path / "hit.glb") == cold
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    assert _bake(scene, tmp_path / "off.glb") == cold


def test_a_fit_to_one_page_is_read_back_without_the_layouts_on_its_way(tmp_path, cache,
                                                                        monkeypatch):
    """A derived density that spills onto two pages is lowered to fit one (``unwrap._fitted``),
    and what that came to is kept (``unwrap_cache.FITS``): the next bake of the same meshes
    reads the atlas and its density back without asking for any layout, with the same bytes,
    as a bake without the cache has."""
    room = (4.0, 3.0, 4.0)
    scene = box_room(grid_boxes(16, room=room, size=0.4), room=room).save(tmp_path / "r.glb")
    cold = _bake(scene, tmp_path / "cold.glb")
    assert len(list((cache / "unwrap" / unwrap_cache.FITS).glob("*.npz"))) == 1

    def refuse(*args, **kwargs):
        raise AssertionError("a layout was asked for although the fit was cached")

    with monkeypatch.context() as m:
        m.setattr(unwrap_module, "_packed", refuse)
        done = baker.bake(scene, tmp_path / "hit.glb", SETTINGS, state=False)
        assert done.report["atlas"]["pages"] == 1
        assert (tmp_path / "hit.glb").read_bytes() == cold
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    assert _bake(scene, tmp_path / "off.glb") == cold


@pytest.mark.parametrize("damage", ["truncated", "flipped", "wrong arrays", "empty"])
def test_a_damaged_entry_is_ignored_and_written_again(tmp_path, cache, damage):
    scene = cornell_box().save(tmp_path / "cornell.glb")
    cold = _bake(scene, tmp_path / "cold.glb")
    [entry] = _entries(cache)
    data = entry.read_bytes()
    if damage == "truncated":
        entry.write_bytes(data[: len(data) // 2])
    elif damage == "flipped":  # a bit of the arrays' data (the zip's CRC no longer matches)
        flipped = bytearray(data)
        flipped[len(data) // 2] ^= 0x10
        entry.write_bytes(bytes(flipped))
    elif damage == "wrong arrays":
        np.savez(entry.with_suffix(""), header=np.zeros(4, np.int64))
    else:
        entry.write_bytes(b"")
    assert unwrap_cache.read(entry.stem, 8) is None
    assert _bake(scene, tmp_path / "again.glb") == cold
    assert _entries(cache) == [entry]
    header, meshes = unwrap_cache.read(entry.stem, 8)  # the room's 8 baked instances
    assert header[0] > 0 and len(meshes) == 8


def test_a_rigid_move_hits_the_cache_and_a_changed_mesh_misses(tmp_path, cache, monkeypatch):
    boxes = grid_boxes(6)
    before = box_room(boxes).save(tmp_path / "before.glb")
    turned = box_room(moved(boxes, "box2", at=(1.9, -1.7), turn=33.0)).save(tmp_path / "after.glb")
    grown = box_room(moved(boxes, "box2", size=(0.5, 0.3, 0.3))).save(tmp_path / "grown.glb")
    _bake(before, tmp_path / "before_baked.glb")
    with monkeypatch.context() as m:
        _no_xatlas(m)
        _bake(turned, tmp_path / "after_baked.glb")
    assert len(_entries(cache)) == 1
    _bake(grown, tmp_path / "grown_baked.glb")  # a stretched box is new xatlas input
    assert len(_entries(cache)) == 2


def test_the_key_is_every_bit_of_the_input_and_every_option():
    positions = np.random.default_rng(1).random((5, 3)).astype(np.float32)
    triangles = np.array([[0, 1, 2], [2, 3, 4]], np.uint32)
    base = unwrap_cache.key([(positions, triangles)], ("v1", {"padding": 2}))
    nudged = positions.copy()
    nudged[3, 1] = np.nextafter(nudged[3, 1], np.float32(2))
    assert unwrap_cache.key([(nudged, triangles)], ("v1", {"padding": 2})) != base
    assert unwrap_cache.key([(positions, triangles[::-1].copy())], ("v1", {"padding": 2})) != base
    assert unwrap_cache.key([(positions, triangles)], ("v1", {"padding": 3})) != base
    assert unwrap_cache.key([(positions, triangles)], ("v2", {"padding": 2})) != base
    assert unwrap_cache.key([(positions, triangles)], ("v1", {"padding": 2})) == base


def test_an_unwritable_cache_costs_nothing_but_the_cache(tmp_path, monkeypatch):
    scene = cornell_box().save(tmp_path / "cornell.glb")
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    without = _bake(scene, tmp_path / "without.glb")
    blocker = tmp_path / "a file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("BAKER_CACHE_DIR", str(blocker))
    assert _bake(scene, tmp_path / "blocked.glb") == without
    assert blocker.read_text() == "not a folder"


def test_only_the_most_recently_used_entries_are_kept(tmp_path, cache, monkeypatch):
    monkeypatch.setattr(unwrap_cache, "KEEP", 2)
    arrays = ((np.zeros(1, np.uint32),) * 5,)
    for n, name in enumerate(("a", "b", "c")):
        unwrap_cache.write(name, (1, 1, 1, 1), arrays)
        path = cache / "unwrap" / f"{name}.npz"
        os.utime(path, (1000 + n, 1000 + n))
    unwrap_cache.write("d", (1, 1, 1, 1), arrays)
    assert [p.stem for p in _entries(cache)] == ["c", "d"]


def _unwrapped(path, **settings):
    """The scene at ``path``, its world and the atlas of ``unwrap`` at ``settings``."""
    from baker.geometry.world import build_world
    from baker.gltf.load import load
    from baker.pipeline.full import bounds_of_baked
    from baker.settings import resolve

    scene = load(path)
    world = build_world(scene)
    resolved = resolve(baker.Settings(**settings), *bounds_of_baked(world, scene))
    return scene, world, resolved, unwrap_module.unwrap(scene, world, resolved)


def test_the_two_packings_made_at_once_give_the_atlas_made_one_after_the_other(tmp_path,
                                                                               monkeypatch):
    """Where the page xatlas sizes itself may exceed a page, it and the run into whole pages
    are made at once (threads > 1): the atlas is the one the runs made in turn give."""
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    path = box_room(grid_boxes(40)).save(tmp_path / "boxes.glb")
    *_, in_turn = _unwrapped(path, page_size=128, threads=1)
    *_, at_once = _unwrapped(path, page_size=128, threads=2)
    assert in_turn.page_count > 1  # the first run came out larger than a page
    assert (in_turn.width, in_turn.height, in_turn.page_count) == (
        at_once.width, at_once.height, at_once.page_count)
    for a, b in zip(in_turn.instances, at_once.instances):
        assert np.array_equal(a.uv, b.uv) and np.array_equal(a.triangles, b.triangles)


def test_the_unwrappers_time_limit_grows_with_the_texels_it_packs(tmp_path, monkeypatch):
    """A few triangles at a high density are little charting but much packing: the watchdog
    gives the xatlas run 10 µs per expected texel beyond its 5 s."""
    from assets.make_scenes import open_plane

    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    given = []

    class Stop(Exception):
        pass

    def record(functions, what, seconds):
        given.append(seconds)
        raise Stop

    monkeypatch.setattr(unwrap_module, "call_forked_together", record)
    path = open_plane(10.0).save(tmp_path / "plane.glb")  # 100 m², 2 triangles
    with pytest.raises(Stop):
        _unwrapped(path, page_size=8192, texel_density=500.0, threads=1)
    texels = 100.0 * 500.0 ** 2
    assert given and given[0] >= 5.0 + 1e-5 * texels


def _charts(place):
    folder = place / "unwrap" / unwrap_cache.CHARTS
    return sorted(folder.glob("*.npz")) if folder.is_dir() else []


def _counting_charts(monkeypatch, tmp_path):
    """From here on every mesh charted (in whichever forked child) adds a line to the file
    returned."""
    log = tmp_path / "charted"
    log.write_text("")
    real = unwrap_module._chart

    def counted(mesh):
        with open(log, "a") as out:
            out.write(f"{len(mesh[1])}\n")
        return real(mesh)

    monkeypatch.setattr(unwrap_module, "_chart", counted)
    return log


def test_instances_stretched_alike_are_charted_once_and_each_gets_its_own_texels(
        tmp_path, cache, monkeypatch):
    """Six boxes of one unit mesh, scaled alike and turned and placed apart: one charting of
    the box (and one of the room); each box still has its own place, about the same texels."""
    from baker.atlas.rasterise import cover

    boxes = [dict(spec, size=(0.3, 0.4, 0.5)) for spec in grid_boxes(6)]
    path = box_room(boxes).save(tmp_path / "alike.glb")
    log = _counting_charts(monkeypatch, tmp_path)
    scene, world, _, atlas = _unwrapped(path, page_size=256, threads=2)
    assert len(log.read_text().split()) == 2 and len(_charts(cache)) == 2
    coverage = cover(atlas, world)
    instance_of = np.searchsorted(world.tri_start, coverage.triangle, side="right") - 1
    counts = np.bincount(instance_of, minlength=len(scene.instances))[1:]  # 0: the room
    assert len(counts) == 6 and counts.min() > 0.9 * counts.max() > 0


def test_a_bake_with_one_mesh_edited_charts_only_that_mesh_again(tmp_path, cache, monkeypatch):
    """Box 2 stretched: its unwrap input is new, the room's and the other boxes' are not (at a
    texel density given: one derived from the scene's area changes with it, and with it every
    mesh's input); the bake's bytes are those of a bake without any cache."""
    settings = baker.Settings(page_size=128, rays=4, shadow_rays=1, threads=1,
                              texel_density=12.0)
    boxes = grid_boxes(6)
    _bake(box_room(boxes).save(tmp_path / "before.glb"), tmp_path / "before_baked.glb", settings)
    grown = box_room(moved(boxes, "box2", size=(0.5, 0.3, 0.3))).save(tmp_path / "grown.glb")
    with monkeypatch.context() as m:
        log = _counting_charts(m, tmp_path)
        cached = _bake(grown, tmp_path / "grown_baked.glb", settings)
        assert log.read_text().split() == ["12"]  # the unit box's 12 triangles, once
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    assert _bake(grown, tmp_path / "uncached.glb", settings) == cached


def test_the_atlas_does_not_depend_on_the_cores_or_on_which_charts_were_cached(
        tmp_path, monkeypatch):
    """Charted by one child or by two (the meshes dealt differently), or packed from charts
    read back from the cache: the same atlas, bit for bit."""
    path = box_room(grid_boxes(12)).save(tmp_path / "boxes.glb")
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    *_, alone = _unwrapped(path, page_size=256, threads=1)
    monkeypatch.setattr(unwrap_module, "cores", lambda: 3)
    *_, beside = _unwrapped(path, page_size=256, threads=3)
    place = tmp_path / "cache"
    monkeypatch.setenv("BAKER_CACHE_DIR", str(place))
    _unwrapped(path, page_size=256, threads=2)
    for entry in _entries(place):  # the whole unwrap gone: packed again from cached charts
        entry.unlink()
    with monkeypatch.context() as m:
        log = _counting_charts(m, tmp_path)
        *_, from_charts = _unwrapped(path, page_size=256, threads=2)
        assert log.read_text() == ""
    for other in (beside, from_charts):
        assert (alone.width, alone.height, alone.page_count) == (
            other.width, other.height, other.page_count)
        for a, b in zip(alone.instances, other.instances, strict=True):
            assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.uv, b.uv)
            assert np.array_equal(a.triangles, b.triangles) and np.array_equal(a.pages, b.pages)


def test_a_scene_of_one_large_mesh_is_charted_and_packed_in_one_run(tmp_path, cache,
                                                                      monkeypatch):
    """A terrain of 3,200 triangles in a room of 12: no mesh is charted alone (one xatlas run
    charts and packs both), and the atlas is the same with one worker or two, and cached."""
    from benchmarks.bench_million import terrain

    path = terrain(40).save(tmp_path / "terrain.glb")
    log = _counting_charts(monkeypatch, tmp_path)
    scene, world, _, alone = _unwrapped(path, page_size=256, threads=1)
    assert log.read_text() == "" and not _charts(cache)
    assert sum(len(inst.triangles) for inst in alone.instances) == 3212
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    *_, beside = _unwrapped(path, page_size=256, threads=2)
    monkeypatch.setenv("BAKER_CACHE_DIR", str(cache))
    with monkeypatch.context() as m:
        _no_xatlas(m)
        *_, cached = _unwrapped(path, page_size=256, threads=1)
    for other in (beside, cached):
        assert (alone.width, alone.height, alone.page_count) == (
            other.width, other.height, other.page_count)
        for a, b in zip(alone.instances, other.instances, strict=True):
            assert np.array_equal(a.uv, b.uv) and np.array_equal(a.triangles, b.triangles)
