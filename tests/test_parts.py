"""A bake made a part of the texels at a time (parts.py), with the parts' rows on disk
(spill.py), gives the same bytes as one made all at once, and leaves no file behind."""

import os
from dataclasses import fields

import numpy as np
import pytest

import baker
from baker.pipeline import parts as parts
from baker.run.spill import Column, Spill
from tests.bakehelp import REAL_SCENES

SCENES = {"lamp": (REAL_SCENES["LightsPunctualLamp"], 192),  # punctual lights
          "vase": (REAL_SCENES["GlassVaseFlowers"], 128)}  # glass, leaves: chain counts, §4 terms


def _bake(path, out, **settings):
    return baker.bake(path, out, baker.Settings(rays=8, **settings))


@pytest.mark.parametrize("name", sorted(SCENES))
def test_parts_on_disk_give_the_bytes_of_one_part(name, tmp_path, monkeypatch):
    path, page = SCENES[name]
    # The same file name in two folders: the output names its images after itself.
    (tmp_path / "whole").mkdir()
    whole = _bake(path, tmp_path / "whole" / "baked.glb", page_size=page)
    monkeypatch.setattr(parts, "PART_TEXELS", 997)  # several parts, cut anywhere
    (tmp_path / "parts").mkdir()
    split = _bake(path, tmp_path / "parts" / "baked.glb", page_size=page)
    assert split.texels == whole.texels > 3 * 997
    for name in ("baked.glb", "baked.glb.bake"):
        assert (tmp_path / "parts" / name).read_bytes() == (tmp_path / "whole" / name).read_bytes()
    for key in ("rays", "shadow_rays", "validity", "rmse_estimate"):
        assert split.report[key] == pytest.approx(whole.report[key], rel=1e-12), key
    assert not [p for p in (tmp_path / "parts").iterdir()
                if p.name.startswith(".")]  # the spilled rows are gone


def test_a_computation_in_parts_gives_back_its_texels_and_terms(tmp_path, monkeypatch):
    """What tests, the error maps and the denoiser read (``Computed.texels``, ``terms``, …) is
    the same whether it was held or spilled."""
    from baker.pipeline.full import compute
    from baker.gltf.load import load

    scene = load(REAL_SCENES["LightsPunctualLamp"])
    settings = baker.Settings(rays=8, page_size=128)
    held = compute(scene, settings)
    monkeypatch.setattr(parts, "PART_TEXELS", 1000)
    spilled = compute(scene, settings, spill_folder=tmp_path)
    assert spilled.per_texel.spill is not None and held.per_texel.spill is None
    for group in ("texels", "validity", "terms", "direct"):
        a, b = getattr(held, group), getattr(spilled, group)
        for f in fields(a):
            x, y = getattr(a, f.name), getattr(b, f.name)
            assert np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y, (group, f.name)
    spilled.per_texel.close()
    assert not list(tmp_path.iterdir())


def test_a_spilled_column_is_written_as_numpy_writes_the_array(tmp_path):
    rng = np.random.default_rng(1)
    spill = Spill(tmp_path)
    from dataclasses import dataclass

    @dataclass
    class Rows:
        value: np.ndarray
        zero: np.ndarray
        light_colours: np.ndarray  # per scene: kept once

    colours = rng.random((2, 3))
    chunks = [Rows(rng.random((n, 3)), np.zeros(n, np.int64), colours) for n in (5, 1, 7)]
    for chunk in chunks:
        spill.append("rows", chunk)
    group = spill.groups["rows"]
    import io
    for name in ("value", "zero"):
        whole = np.concatenate([getattr(c, name) for c in chunks])
        ours, numpy = io.BytesIO(), io.BytesIO()
        group.columns[name].write_npy(ours)
        np.save(numpy, whole)
        assert ours.getvalue() == numpy.getvalue()
        assert (group.columns[name].encoding == "zeros") == (name == "zero")
    assert group.columns["light_colours"].array is colours
    assert np.array_equal(group.load().value, np.concatenate([c.value for c in chunks]))
    assert Column.of(np.zeros((0, 3))).encoding == "dense"  # an empty term is stored as such
    spill.close()
    assert not list(tmp_path.iterdir())


def test_an_interrupted_bake_in_parts_leaves_no_rows_on_disk(tmp_path, monkeypatch):
    import importlib

    bake_module = importlib.import_module("baker.pipeline.full")
    monkeypatch.setattr(parts, "PART_TEXELS", 1000)
    lit, original = [], bake_module.direct_light

    def interrupted(*args, **kwargs):  # Ctrl-C in the second part
        lit.append(1)
        if len(lit) == 2:
            raise KeyboardInterrupt
        return original(*args, **kwargs)

    monkeypatch.setattr(bake_module, "direct_light", interrupted)
    with pytest.raises(KeyboardInterrupt):
        _bake(REAL_SCENES["LightsPunctualLamp"], tmp_path / "out.glb", page_size=128)
    assert len(lit) == 2 and not list(tmp_path.iterdir())


def test_rows_a_killed_bake_left_behind_are_removed_by_the_next(tmp_path):
    """A SIGKILL leaves the spilled rows (nothing can run then), or a replaced state not yet
    deleted (``spill.set_aside``); the next spill in the folder removes the folders and files
    of processes that are gone, and keeps those of running ones."""
    import subprocess
    import sys

    from baker.run.spill import remove_stale

    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()
    (tmp_path / f".baker-spill-{gone}-x1").mkdir()
    (tmp_path / f".baker-spill-{gone}-x1" / "terms.w_hit").write_bytes(b"\0" * 64)
    (tmp_path / f".baker-spill-{gone}-x3.old").write_bytes(b"\0" * 64)  # a state set aside
    (tmp_path / f".baker-spill-{os.getpid()}-x2").mkdir()  # a bake running now: this one
    (tmp_path / ".baker-spill-notapid").mkdir()
    Spill(tmp_path).close()
    assert sorted(p.name for p in tmp_path.iterdir()) == \
        [f".baker-spill-{os.getpid()}-x2", ".baker-spill-notapid"]
    assert remove_stale(tmp_path) == []


@pytest.mark.parametrize("where", ["spilled", "in memory"])
def test_column_encodings_follow_the_rows(tmp_path, where):
    """A column's ``encoding`` (how the state stores it) follows its rows, whether appended
    part by part to disk or held in memory: one row repeated -> "repeated"; few rows with a bit
    set (−0.0 counts, as the state keeps bits) -> "sparse", whose rows and indices give the
    array back; otherwise "dense"."""
    rng = np.random.default_rng(3)
    n = 1000
    mostly_zero = np.zeros((n, 3))
    mostly_zero[[4, 500, 999]] = rng.random((3, 3))
    mostly_zero[7, 1] = -0.0
    arrays = {"repeated": np.full(n, 64, np.int64), "sparse": mostly_zero,
              "dense": rng.random((n, 2)), "zeros": np.zeros(n, np.int8),
              "almost repeated": np.r_[np.full(n - 1, 64, np.int64), 65]}
    expected_encoding = {"almost repeated": "dense"}
    for expected, array in arrays.items():
        if where == "in memory":
            column = Column.of(array)
        else:
            column = Column(str(tmp_path / expected), array.dtype, array.shape[1:])
            for part in np.array_split(array, 4):
                column._append(part)
        assert column.encoding == expected_encoding.get(expected, expected)
        if expected == "sparse":
            indices, rows = column.sparse_rows()
            assert indices.tolist() == [4, 7, 500, 999]
            rebuilt = np.zeros_like(array)
            rebuilt[indices] = rows
            assert rebuilt.tobytes() == array.tobytes()


def test_texel_points_keep_only_the_moved_sample_points():
    """``TexelPoints`` keeps the sample points the probes moved (any bit differing from the one
    ``texels_of`` made, so 0.0 → −0.0 counts) and gives every point back bit for bit from the
    made ones; the others are stored as zero rows, which the state leaves out."""
    from types import SimpleNamespace

    from baker.pipeline.parts import TexelPoints

    rng = np.random.default_rng(5)
    made = rng.random((6, 3))
    made[5] = 0.0
    position = made.copy()
    position[1] += [0.0, 1e-12, 0.0]
    position[5, 2] = -0.0
    texels = SimpleNamespace(key=np.arange(6, dtype=np.uint64), triangle=np.zeros(6, np.int64),
                             triangle_texels=np.array([6]), position=position)
    points = TexelPoints.of(texels, made)
    assert points.moved.tolist() == [False, True, False, False, False, True]
    assert not points.moved_position[~points.moved].any()
    assert points.positions(made).tobytes() == position.tobytes()
    assert Column.of(points.moved_position).encoding == "sparse"


def test_a_bake_killed_at_once_leaves_no_rows_and_says_why(tmp_path):
    """SIGKILL (as Ray's hard exit when a cluster's head is lost) runs nothing more in the
    bake's process: its spill's watcher removes the spilled rows at once and says why."""
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    from assets.make_scenes import cornell_box

    scene = cornell_box().save(tmp_path / "cornell.glb")
    script = ("import sys, baker, baker.pipeline.parts as parts\n"
              "parts.PART_TEXELS = 500\n"
              "baker.bake(sys.argv[1], sys.argv[2], baker.Settings(page_size=128, rays=256))\n")
    out = tmp_path / "out" / "baked.glb"
    out.parent.mkdir()
    bake = subprocess.Popen([sys.executable, "-c", script, str(scene), str(out)],
                            stderr=subprocess.PIPE, cwd=Path(__file__).resolve().parents[1])
    deadline = time.monotonic() + 120
    while not list(out.parent.glob(".baker-spill-*")) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert list(out.parent.glob(".baker-spill-*")), "the bake made no spill"
    bake.send_signal(signal.SIGKILL)
    # The watcher holds the bake's standard error too: it ends once the watcher has spoken.
    said = bake.communicate(timeout=60)[1].decode()
    assert bake.returncode == -signal.SIGKILL
    assert list(out.parent.iterdir()) == []
    assert "the bake ended abruptly" in said, said
