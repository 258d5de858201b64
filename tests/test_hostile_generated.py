"""Generated hostile inputs and faults (issue 40; ``tests/hostile_cases.py``), run as processes.

Each case is a real ``baker`` process (forked from a server that imported baker once:
``tests/hostile_runner.py``), and each is checked for what its plan says — exit code, message
— and for what every case owes: nothing outside the output's place changed (the scene, the
decoys beside it), a refused or interrupted run left the output's place as it was (no
temporary, no spill folder), a run that ended well wrote no file holding the decoy's secret,
a signal was honoured within ``SIGNAL_SECONDS``, and the process ended within
``LIMIT_SECONDS`` and under ``CEILING_KIB`` resident (its peak, ``os.wait4``). The default run
takes the fast set; ``BAKER_LONG=1`` all of them (several hundred).
"""

from __future__ import annotations

import hashlib
import multiprocessing
import os
import stat
import threading
import time
from pathlib import Path

import pytest

from baker.cli.common import NOTHING_BAKED, OUTPUTS_CHANGED
from tests.hostile_cases import FAMILIES, Layout, cases, prepare
from tests.hostile_runner import Runner

CEILING_KIB = 1_000_000  # peak resident memory of a run: under 1 GB
LIMIT_SECONDS = 60.0
SIGNAL_SECONDS = 2.0  # from SIGINT or SIGTERM to the process's end
_HASHED = 64 << 20  # files up to this size are compared by their bytes, larger by size and time

FAST = cases(long=False)
LONG = [case for case in cases(long=True) if not case.fast]


@pytest.fixture(scope="module")
def runner():
    server = Runner()
    yield server
    server.close()


def snapshot(folder: Path, leave_out: Path | None = None) -> dict[str, tuple]:
    """What is under ``folder`` (but ``leave_out``): each path's kind and content — a file's
    hash (its size and time past ``_HASHED``), a link's target, a FIFO's or socket's kind alone
    (never opened)."""
    out: dict[str, tuple] = {}
    for path in sorted(folder.rglob("*")):
        if leave_out is not None and (path == leave_out or leave_out in path.parents):
            continue
        info = path.lstat()
        name = str(path.relative_to(folder))
        if stat.S_ISLNK(info.st_mode):
            out[name] = ("link", os.readlink(path))
        elif stat.S_ISREG(info.st_mode):
            out[name] = ("file", info.st_size, info.st_nlink,
                         hashlib.sha256(path.read_bytes()).hexdigest()
                         if info.st_size <= _HASHED else info.st_mtime_ns)
        else:
            out[name] = (stat.S_IFMT(info.st_mode),)
    return out


def _read_fifo(path: Path, into: list[bytes]) -> None:
    with open(path, "rb") as stream:
        into.append(stream.read())


def run_case(case, runner: Runner, root: Path) -> None:
    """Build ``case`` under ``root``, run it and check it (see the module's docstring)."""
    layout, plan = prepare(case, root, lambda argv: runner.run(argv, root, LIMIT_SECONDS))
    place = plan.place or layout.out
    outside, inside = snapshot(root, place), snapshot(place)
    streamed: list[bytes] = []
    if plan.reader is not None:
        threading.Thread(target=_read_fifo, args=(plan.reader, streamed), daemon=True).start()
    result = runner.run(plan.argv, root, LIMIT_SECONDS, plan.signal, plan.after)
    said = result["err"] + result["out"]
    code = result["code"]
    assert code in plan.code, (code, said)
    assert "Traceback" not in said and "internal error" not in said, said
    for part in plan.says:
        assert part in said, (part, said)
    if code == 1 and plan.argv[0] != "hook":
        lines = result["err"].strip().splitlines()
        assert lines[0].startswith("baker: error: ") and len(lines) <= 2, said
        assert lines[-1].strip().startswith("fix: "), said
    assert result["seconds"] < LIMIT_SECONDS and result["kib"] < CEILING_KIB, result
    if plan.signal is not None and code != 0:
        assert result["after_signal"] < SIGNAL_SECONDS, result
    assert snapshot(root, place) == outside, "a file outside the output's place changed"
    after = snapshot(place)
    if code not in (0, NOTHING_BAKED, OUTPUTS_CHANGED):  # 4: written, with no surface baked;
        # 5: the hook's outputs written, to be added to the commit
        assert after == inside, "a refused or interrupted run changed the output's place"
    for name, content in after.items():
        path = place / name
        if content[0] == "file" and inside.get(name) != content and content[1] <= _HASHED:
            assert layout.secret not in path.read_bytes(), f"the secret reached {name}"
    if plan.reader is not None:
        assert streamed and streamed[0].startswith(plan.streams), streamed


@pytest.mark.parametrize("case", FAST, ids=[case.id for case in FAST])
def test_a_hostile_case(case, runner, tmp_path):
    run_case(case, runner, tmp_path)


@pytest.mark.long
@pytest.mark.parametrize("case", LONG, ids=[case.id for case in LONG])
def test_a_hostile_case_of_the_long_set(case, runner, tmp_path):
    run_case(case, runner, tmp_path)


def test_the_cases_cover_every_family_fast_and_long():
    """Each family has cases in the fast set, and the long set has several hundred."""
    assert {case.family for case in FAST} == set(FAMILIES)
    assert {case.family for case in LONG} == set(FAMILIES)
    assert len(FAST) + len(LONG) >= 300
    assert len({case.id for case in FAST + LONG}) == len(FAST) + len(LONG)


# ------------------------------------------------------------------------------------------------
# a folder swapped for a link while files are read


def _swap(folder: Path, outside: Path) -> None:
    """Forever: ``folder/sub`` a real folder, then a link to ``outside``, and back."""
    real, parked, link = folder / "sub", folder / "parked", folder / "sublink"
    os.symlink(outside, link)
    while True:
        os.rename(real, parked)
        os.rename(link, real)
        os.rename(real, link)
        os.rename(parked, real)


@pytest.mark.parametrize("reads", [pytest.param(3000, id="3000"),
                                   pytest.param(20000, id="20000", marks=pytest.mark.long)])
def test_a_folder_swapped_for_a_link_while_files_are_read_leaks_nothing(tmp_path, reads):
    """While another process swaps ``sub`` for a link to a folder outside and back as fast as
    it can, ``sub/data.bin`` is read ``reads`` times: never a byte from outside (the check
    then open of a path was followed 23 times in 13,700 reads), every read either the inside
    file or a clean refusal (InputError), never another error."""
    from baker.errors import InputError
    from baker.gltf.files import SceneFolder

    folder, outside = tmp_path / "scene", tmp_path / "outside"
    folder.mkdir()
    outside.mkdir()
    (outside / "data.bin").write_bytes(b"SECRET!!" * 4)
    (folder / "sub").mkdir()
    (folder / "sub" / "data.bin").write_bytes(b"inside.." * 4)
    swapper = multiprocessing.get_context("fork").Process(target=_swap, args=(folder, outside),
                                                          daemon=True)
    swapper.start()
    seen = {"inside": 0, "refused": 0}
    deadline = time.monotonic() + LIMIT_SECONDS
    try:
        with SceneFolder(folder, "scene.gltf") as opened:
            # at least ``reads``, and until the swap has raced them both ways
            while sum(seen.values()) < reads or not all(seen.values()):
                assert time.monotonic() < deadline, seen
                try:
                    data = opened.read("sub/data.bin", "buffers[0].uri", 32)
                except InputError:
                    seen["refused"] += 1
                    continue
                assert data == b"inside.." * 4, data
                seen["inside"] += 1
    finally:
        swapper.kill()
        swapper.join()


# ------------------------------------------------------------------------------------------------
# the settings a bake state may give


def test_a_bake_state_gives_no_setting_a_caller_alone_gives(tmp_path):
    """``asked_settings`` (``baker rebake``, ``relight``, ``hook``) takes the last bake's
    settings from its state, but never one of ``CALLER_ONLY`` (hard links, cluster, ray budget,
    work-unit size, threads): a state edited to say them gives the defaults (or the caller's
    overrides), while the rest of what it says is kept."""
    from baker.cli.main import main
    from baker.rebake.asked import asked_settings
    from baker.settings import CALLER_ONLY, Settings
    from tests.hostile_cases import edit_state

    layout = Layout(tmp_path)
    assert main(["bake", str(layout.save()), "-o", str(layout.output), "--rays", "6",
                 "--page-size", "32", "--quiet"]) == 0
    hostile = {"allow_hard_links": True, "cluster": "203.0.113.1:6379",
               "max_total_rays": 10 ** 18, "chunk_texels": 10 ** 9, "threads": 4096}
    assert set(hostile) == set(CALLER_ONLY)
    state = layout.out / "baked.glb.bake"
    edit_state(state, lambda header, members: header["fingerprints"]["asked"].update(hostile))
    settings = asked_settings(state)
    defaults = Settings()
    assert {name: getattr(settings, name) for name in CALLER_ONLY} == {
        name: getattr(defaults, name) for name in CALLER_ONLY}
    assert (settings.rays, settings.page_size) == (6, 32)
    assert asked_settings(state, threads=2, cluster=None).threads == 2
