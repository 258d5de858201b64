"""Charts cached across bakes (``baker/atlas/unwrap_cache.py``, ``charts.py``): the bytes of a
bake do not depend on whether the cache was hit, missed, off, corrupted or unwritable; an entry
is used exactly when the charting's input is the same (a rigid move of a node keeps it, and so
does another texel density, which only packs the charts again)."""

from __future__ import annotations

import hashlib
import os
import stat

import numpy as np
import pytest

import baker
from assets.make_scenes import cornell_box
from assets.rebake_scenes import box_room, grid_boxes, moved
from baker.atlas import charts as charts_module
from baker.atlas import unwrap as unwrap_module
from baker.atlas import unwrap_cache
from baker.run import atomic

SETTINGS = baker.Settings(page_size=128, rays=4, shadow_rays=1, threads=1)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A cache folder of the test's own."""
    place = tmp_path / "cache"
    monkeypatch.setenv("BAKER_CACHE_DIR", str(place))
    return place


def _entries(place):
    """Every entry: one per distinct mesh charted, and one of all a scene's meshes together."""
    folder = place / "unwrap" / "charts"
    return sorted(folder.glob(f"*{unwrap_cache.SUFFIX}")) if folder.is_dir() else []


def _meshes_in(entry) -> int:
    """How many meshes' charts an entry holds."""
    return len(unwrap_cache._unpacked(bytearray(entry.read_bytes()))[1])  # its lengths


def _no_charting(monkeypatch):
    """From here on, charting any mesh fails the test: the charts must come from the cache."""
    def refuse(*args, **kwargs):
        raise AssertionError("a mesh was charted although its charts were cached")
    monkeypatch.setattr(charts_module, "call_forked_together", refuse)


def _bake(scene, out, settings=SETTINGS):
    baker.bake(scene, out, settings, state=False)
    return out.read_bytes()


def test_a_bake_from_the_cache_has_the_bytes_of_one_without(tmp_path, cache, monkeypatch):
    scene = cornell_box().save(tmp_path / "cornell.glb")
    cold = _bake(scene, tmp_path / "cold.glb")
    counts = sorted(_meshes_in(entry) for entry in _entries(cache))
    assert counts[:-1] == [1] * (len(counts) - 1) and counts[-1] == len(counts) - 1 < 8
    with monkeypatch.context() as m:
        _no_charting(m)
        assert _bake(scene, tmp_path / "hit.glb") == cold
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    assert _bake(scene, tmp_path / "off.glb") == cold


def test_another_texel_density_packs_the_cached_charts_again(tmp_path, cache, monkeypatch):
    """A bake at one density, then at another: no mesh is charted again, the atlas is the
    other density's (more texels, a larger page), and the bytes are those of a bake at that
    density without any cache."""
    scene = box_room(grid_boxes(8)).save(tmp_path / "room.glb")
    low = baker.Settings(page_size=256, rays=4, shadow_rays=1, threads=1, texel_density=8.0)
    high = baker.Settings(page_size=256, rays=4, shadow_rays=1, threads=1, texel_density=12.0)
    first = baker.bake(scene, tmp_path / "low.glb", low, state=False)
    with monkeypatch.context() as m:
        _no_charting(m)
        second = baker.bake(scene, tmp_path / "high.glb", high, state=False)
    assert second.texels > 2 * first.texels
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    assert _bake(scene, tmp_path / "uncached.glb", high) == (tmp_path / "high.glb").read_bytes()


@pytest.mark.parametrize("damage", ["truncated", "flipped", "wrong arrays", "empty"])
def test_a_damaged_entry_is_ignored_and_written_again(tmp_path, cache, damage):
    scene = cornell_box().save(tmp_path / "cornell.glb")
    cold = _bake(scene, tmp_path / "cold.glb")
    entries = {entry: _meshes_in(entry) for entry in _entries(cache)}
    for entry, meshes in entries.items():  # every one damaged
        data = entry.read_bytes()
        if damage == "truncated":
            entry.write_bytes(data[: len(data) // 2])
        elif damage == "flipped":  # a bit of the arrays' data (the entry's CRC no longer matches)
            flipped = bytearray(data)
            flipped[len(data) // 2] ^= 0x10
            entry.write_bytes(bytes(flipped))
        elif damage == "wrong arrays":
            entry.write_bytes(unwrap_cache._packed([np.zeros(4, np.int64)]))
        else:
            entry.write_bytes(b"")
        assert unwrap_cache.read(entry.stem, meshes) is None
    assert _bake(scene, tmp_path / "again.glb") == cold
    assert _entries(cache) == sorted(entries)
    for entry, meshes in entries.items():
        header, arrays = unwrap_cache.read(entry.stem, meshes)
        assert min(header) > 0 and len(arrays) == meshes


def test_a_rigid_move_hits_the_cache_and_a_changed_mesh_misses(tmp_path, cache, monkeypatch):
    boxes = grid_boxes(6)
    before = box_room(boxes).save(tmp_path / "before.glb")
    turned = box_room(moved(boxes, "box2", at=(1.9, -1.7), turn=33.0)).save(tmp_path / "after.glb")
    grown = box_room(moved(boxes, "box2", size=(0.5, 0.3, 0.3))).save(tmp_path / "grown.glb")
    _bake(before, tmp_path / "before_baked.glb")
    count = len(_entries(cache))
    with monkeypatch.context() as m:
        _no_charting(m)
        _bake(turned, tmp_path / "after_baked.glb")
    assert len(_entries(cache)) == count
    _bake(grown, tmp_path / "grown_baked.glb")  # a stretched box is a new mesh to chart
    assert len(_entries(cache)) == count + 2  # its charts, and the scene's together


def test_the_key_is_every_bit_of_the_input_and_every_option():
    positions = np.random.default_rng(1).random((5, 3))
    triangles = np.array([[0, 1, 2], [2, 3, 4]], np.int64)
    base = unwrap_cache.key([(positions, triangles)], ("v1", {"padding": 2}))
    nudged = positions.copy()
    nudged[3, 1] = np.nextafter(nudged[3, 1], 2.0)
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


def test_an_entry_is_written_whole_or_not_at_all(tmp_path, monkeypatch):
    """``atomic.write_private`` (the cache's writes): the bytes land whole, with the permissions
    a new file gets (0666 less the umask); a write that fails midway (a full disk) or a Ctrl-C
    leaves the entry that was there and no temporary beside it."""
    path = tmp_path / "entry.charts"
    old_mask = os.umask(0o027)
    try:
        atomic.write_private(path, b"first" * 1000)
    finally:
        os.umask(old_mask)
    assert path.read_bytes() == b"first" * 1000
    assert stat.S_IMODE(path.stat().st_mode) == 0o640
    for failure in (OSError(28, "No space left on device"), KeyboardInterrupt()):
        written = []

        def fails(handle, data, failure=failure):
            if written:
                raise failure
            written.append(len(data))
            return len(data) // 2  # a short write: the rest is written again

        monkeypatch.setattr(atomic.os, "write", fails)
        with pytest.raises(type(failure)):
            atomic.write_private(path, b"second" * 1000)
        monkeypatch.undo()
        assert written == [6000]
        assert path.read_bytes() == b"first" * 1000
        assert [p.name for p in tmp_path.iterdir()] == ["entry.charts"]


def test_only_the_most_recently_used_entries_are_kept(tmp_path, cache, monkeypatch):
    """Entries of an earlier format (``.npz``), never read again, count and go first."""
    monkeypatch.setattr(unwrap_cache, "KEEP_CHARTS", 2)
    arrays = ((np.zeros(1, np.int64),) * unwrap_cache.PER_MESH,)
    for n, name in enumerate(("a", "b", "c")):
        unwrap_cache.write(name, (1,), arrays)
        os.utime(unwrap_cache.entry_path(name), (1000 + n, 1000 + n))
    old = unwrap_cache.entries() / "old.npz"
    old.write_bytes(b"PK")
    os.utime(old, (500, 500))
    unwrap_cache.write("d", (1,), arrays)
    assert [p.stem for p in _entries(cache)] == ["c", "d"] and not old.exists()


def test_the_charting_time_limit_grows_with_the_triangles(tmp_path, monkeypatch):
    """The watchdog gives a child charting meshes 5 s and 2 ms a triangle of CPU time."""
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    given = []

    class Stop(Exception):
        pass

    def record(functions, what, seconds, tick=None):
        given.append(seconds)
        raise Stop

    monkeypatch.setattr(charts_module, "call_forked_together", record)
    boxes = grid_boxes(6)
    with pytest.raises(Stop):
        _unwrapped(box_room(boxes).save(tmp_path / "boxes.glb"), page_size=128, threads=1)
    assert given == [pytest.approx(5.0 + 2e-3 * (12 + 6 * 12))]  # the room and six boxes


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


def _counting_charts(monkeypatch, tmp_path):
    """From here on every mesh charted (in whichever forked child) adds a line to the file
    returned: its triangle count."""
    log = tmp_path / "charted"
    log.write_text("")
    real = charts_module.chart_many

    def counted(meshes):
        with open(log, "a") as out:
            out.writelines(f"{len(triangles)}\n" for _, triangles in meshes)
        return real(meshes)

    monkeypatch.setattr(charts_module, "chart_many", counted)
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
    assert len(log.read_text().split()) == 2 and len(_entries(cache)) == 3  # and together
    coverage = cover(atlas, world)
    instance_of = np.searchsorted(world.tri_start, coverage.triangle, side="right") - 1
    counts = np.bincount(instance_of, minlength=len(scene.instances))[1:]  # 0: the room
    assert len(counts) == 6 and counts.min() > 0.9 * counts.max() > 0


def test_a_bake_with_one_mesh_edited_charts_only_that_mesh_again(tmp_path, cache, monkeypatch):
    """Box 2 stretched: its charting input is new, the room's and the other boxes' are not
    (whatever the density: the charts hold none); the bake's bytes are those of a bake
    without any cache."""
    boxes = grid_boxes(6)
    _bake(box_room(boxes).save(tmp_path / "before.glb"), tmp_path / "before_baked.glb")
    grown = box_room(moved(boxes, "box2", size=(0.5, 0.3, 0.3))).save(tmp_path / "grown.glb")
    with monkeypatch.context() as m:
        log = _counting_charts(m, tmp_path)
        cached = _bake(grown, tmp_path / "grown_baked.glb")
        assert log.read_text().split() == ["12"]  # the unit box's 12 triangles, once
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    assert _bake(grown, tmp_path / "uncached.glb") == cached


@pytest.mark.parametrize("hint", ["kept", "garbage", "joint gone"])
def test_an_edit_reads_the_scene_s_last_joint_entry(tmp_path, cache, monkeypatch, hint):
    """After a bake, every entry of one mesh removed: the scene's last joint entry (named for
    its file, ``unwrap_cache.last_joint``) gives the charts of the meshes an edit (box 2
    stretched) left as they were, so only box 2 is charted again. A hint that cannot be read
    (garbage, or naming an entry no longer there) costs the charting, never the bytes."""
    boxes = grid_boxes(6)
    scene = tmp_path / "room.glb"
    box_room(boxes).save(scene)
    _bake(scene, tmp_path / "before_baked.glb")
    for entry in _entries(cache):
        if _meshes_in(entry) == 1:
            entry.unlink()
    (last,) = (cache / "unwrap" / "scenes").iterdir()
    if hint == "garbage":
        last.write_bytes(b"not a name\n" + bytes(range(256)))
    elif hint == "joint gone":
        for entry in _entries(cache):
            entry.unlink()
    box_room(moved(boxes, "box2", size=(0.5, 0.3, 0.3))).save(scene)
    with monkeypatch.context() as m:
        log = _counting_charts(m, tmp_path)
        cached = _bake(scene, tmp_path / "grown_baked.glb")
        charted = sorted(map(int, log.read_text().split()))
    assert charted == [12] if hint == "kept" else len(charted) > 1
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    assert _bake(scene, tmp_path / "uncached.glb") == cached


def test_the_last_joint_entries_of_the_scenes_baked_last_are_named(cache, monkeypatch):
    """``remember_joint`` / ``last_joint`` round-trip a scene's joint entry and its meshes'
    names, by the scene's path; past ``KEEP_SCENES`` scenes the least recently baked's go."""
    monkeypatch.setattr(unwrap_cache, "KEEP_SCENES", 2)
    names = {f"/scenes/{k}.glb": [f"{k:x}{m:x}" * 32 for m in range(k + 1)] for k in range(1, 4)}
    for k, (scene, meshes) in enumerate(names.items()):
        unwrap_cache.remember_joint(scene, f"{k + 10:x}" * 64, meshes)
        os.utime(next((cache / "unwrap" / "scenes").glob(
            f"{hashlib.sha256(scene.encode()).hexdigest()}.last")), (k, k))  # in order
    kept = {scene: unwrap_cache.last_joint(scene) for scene in names}
    assert kept["/scenes/1.glb"] is None
    for k, scene in ((1, "/scenes/2.glb"), (2, "/scenes/3.glb")):
        assert kept[scene] == (f"{k + 10:x}" * 64, names[scene])
    assert unwrap_cache.last_joint("/scenes/other.glb") is None


def test_the_atlas_does_not_depend_on_the_cores_or_on_which_charts_were_cached(
        tmp_path, monkeypatch):
    """Charted by one child or by three (the meshes dealt differently), or packed from charts
    read back from the cache, some of them only: the same atlas, bit for bit."""
    path = box_room(grid_boxes(12)).save(tmp_path / "boxes.glb")
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    *_, alone = _unwrapped(path, page_size=256, threads=1)
    monkeypatch.setattr(charts_module, "cores", lambda: 3)
    *_, beside = _unwrapped(path, page_size=256, threads=3)
    place = tmp_path / "cache"
    monkeypatch.setenv("BAKER_CACHE_DIR", str(place))
    _unwrapped(path, page_size=256, threads=2)
    singles = [entry for entry in _entries(place) if _meshes_in(entry) == 1]
    for entry in set(_entries(place)) - set(singles) | set(singles[::2]):
        entry.unlink()  # the scene's joint entry gone, and half the meshes charted again
    *_, from_charts = _unwrapped(path, page_size=256, threads=2)
    for other in (beside, from_charts):
        assert (alone.width, alone.height, alone.page_count) == (
            other.width, other.height, other.page_count)
        for a, b in zip(alone.instances, other.instances, strict=True):
            assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.uv, b.uv)
            assert np.array_equal(a.triangles, b.triangles) and np.array_equal(a.pages, b.pages)


def test_an_entry_round_trips_and_any_cut_or_changed_byte_is_refused(cache):
    """An entry holds its arrays' values, types and shapes whole, aligned; cut anywhere, or with any
    byte changed (the format's, the layout's or the data's), it is read as none, never as
    other arrays or an exception."""
    rng = np.random.default_rng(5)
    mesh = (rng.integers(0, 9, 7), rng.integers(0, 7, (4, 3)), rng.random((7, 2)),
            rng.integers(0, 2, 7), rng.random((2, 2)))
    unwrap_cache.write("entry", (2,), (mesh, mesh[:4] + (rng.random((2, 2)),)))
    header, meshes = unwrap_cache.read("entry", 2)
    assert header == (2,)
    for got, want in zip(meshes[0], mesh):
        assert got.dtype == np.asarray(want).dtype and np.array_equal(got, want)
        assert got.flags.aligned  # else every kernel given them is numba's JIT
    path = unwrap_cache.entry_path("entry")
    data = path.read_bytes()
    for cut in sorted({0, 1, len(data) - 1, *rng.integers(1, len(data), 40)}):
        path.write_bytes(data[:cut])
        assert unwrap_cache.read("entry", 2) is None, cut
    for at in sorted({*range(40), *rng.integers(0, len(data), 60)}):
        changed = bytearray(data)
        changed[at] ^= 1 << int(rng.integers(0, 8))
        path.write_bytes(bytes(changed))
        assert unwrap_cache.read("entry", 2) is None, at
