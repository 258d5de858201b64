"""Hostile input cannot read, run, replace or exhaust anything (issue 26; docs/robustness.md).

Every case is a generated input — a small scene saved as ``.gltf`` + ``.bin`` in ``scene/``, then
edited as an attacker would — with its expected outcome: a clean one- or two-line error (exit 1)
or a correct bake (exit 0). Beside the scene's folder lies a decoy secret, and a copy of the
scene's own ``.bin`` and texture with the secret appended, so that a scene which managed to read
them would bake: the secret must never appear in any file baker writes. Every case also checks
that nothing was written outside the output's folder, and that a refused bake left the previous
output as it was.
"""

from __future__ import annotations

import importlib
import json
import os
import socket
import threading
from pathlib import Path

import pytest

from baker.cli.main import main
from tests.hostile_cases import FAST, PREVIOUS, Layout, spellings


class Case(Layout):
    """A scene folder beside a decoy (``hostile_cases.Layout``), baked in-process."""

    def bake(self, capsys, *args: str, output: Path | None = None) -> tuple[int, str]:
        """Save the edited JSON, bake it; return (exit code, stderr)."""
        code = main(super().bake(*args, output=output))
        return code, capsys.readouterr().err

    def written(self) -> dict[str, bytes]:
        """Every file under the root but the scene's, the decoys and the previous output."""
        fixed = {"secret.txt", "secret.bin", "secret.png"}
        return {str(p.relative_to(self.root)): p.read_bytes() for p in sorted(self.root.rglob("*"))
                if p.is_file() and not p.is_symlink() and p.name not in fixed
                and self.folder not in p.parents}

    def assert_refused(self, err: str, *parts: str) -> None:
        """One clean message naming ``parts``; the previous output kept; nothing else written."""
        assert err.startswith("baker: error: "), err
        assert "Traceback" not in err and "internal error" not in err, err
        lines = err.strip().splitlines()
        assert 1 <= len(lines) <= 2 and lines[-1].strip().startswith("fix: "), err
        for part in parts:
            assert part in err, f"{part!r} not in {err!r}"
        assert self.written() == {"out/baked.glb": PREVIOUS}

    def assert_no_secret(self) -> None:
        for name, data in self.written().items():
            assert self.secret not in data, name


@pytest.fixture
def case(tmp_path) -> Case:
    return Case(tmp_path)


# ------------------------------------------------------------------------------------------------
# reading: only files inside the scene's folder


ESCAPES = list(spellings(Path("/r"), "x"))  # every way an attacker might spell a way out


@pytest.mark.parametrize("spelling", ESCAPES)
def test_a_buffer_outside_the_scenes_folder_is_refused(case, capsys, spelling):
    uri = spellings(case.root, "secret.bin")[spelling]
    (case.folder / "sub").mkdir()
    case.json["buffers"][0]["uri"] = uri
    code, err = case.bake(capsys)
    assert code == 1, err
    case.assert_refused(err, "buffers[0].uri", uri[:60])
    case.assert_no_secret()


@pytest.mark.parametrize("kind", ["buffer", "image"])
def test_a_hard_link_to_a_file_outside_the_folder_is_refused_unless_allowed(case, capsys, kind):
    """A file inside the folder that is a hard link to the decoy beside it (the same inode: the
    resolved-path rule cannot see it) is refused, naming it and the setting; nothing of the
    decoy reaches an output. With ``--allow-hard-links`` the same scene bakes, as a copy does."""
    link = case.folder / ("linked.bin" if kind == "buffer" else "linked.png")
    os.link(case.root / ("secret.bin" if kind == "buffer" else "secret.png"), link)
    if kind == "buffer":
        case.json["buffers"][0]["uri"] = link.name
    else:
        case.with_texture(link.name)
    code, err = case.bake(capsys)
    assert code == 1, err
    where = "buffers[0].uri" if kind == "buffer" else "images[0].uri"
    case.assert_refused(err, where, link.name, "2 names", "--allow-hard-links")
    case.assert_no_secret()
    code, err = case.bake(capsys, "--allow-hard-links")
    assert code == 0, err


@pytest.mark.parametrize("slot", ["baseColorTexture", "normalTexture"])
@pytest.mark.parametrize("spelling", ESCAPES)
def test_an_image_outside_the_scenes_folder_is_refused(case, capsys, spelling, slot):
    """A colour texture (decoded by the bake) or a normal map (only carried over: copied beside
    an output in another folder) alike."""
    (case.folder / "sub").mkdir()
    uri = spellings(case.root, "secret.png")[spelling]
    case.with_texture(uri, slot)
    code, err = case.bake(capsys)
    assert code == 1, err
    case.assert_refused(err, "images[0].uri", uri[:60])
    case.assert_no_secret()


def test_a_symbolic_link_leading_out_of_the_folder_is_refused(case, capsys):
    (case.folder / "linked.bin").symlink_to(case.root / "secret.bin")
    (case.folder / "up").symlink_to(case.root, target_is_directory=True)
    for uri in ("linked.bin", "up/secret.bin", "up%2Fsecret.bin"):
        case.json["buffers"][0]["uri"] = uri
        code, err = case.bake(capsys)
        assert code == 1, err
        case.assert_refused(err, "buffers[0].uri", uri, "leads out of the scene's folder")
    case.assert_no_secret()


@pytest.mark.parametrize("uri", ["/proc/self/environ", "/dev/zero", "/etc/passwd"])
def test_system_files_are_refused(case, capsys, uri):
    if not os.path.exists(uri):
        pytest.skip(f"{uri} does not exist on this system")
    os.environ["BAKER_TEST_SECRET"] = case.secret.decode()
    try:
        case.json["buffers"][0]["uri"] = uri
        code, err = case.bake(capsys)
    finally:
        del os.environ["BAKER_TEST_SECRET"]
    assert code == 1, err
    case.assert_refused(err, "buffers[0].uri", uri, "absolute path")
    case.assert_no_secret()


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this system")
def test_special_files_inside_the_folder_are_refused_without_blocking(case, capsys):
    """A FIFO (opening it for reading would wait for a writer for ever), a socket, a folder, and
    a link inside the folder to /dev/zero (endless bytes)."""
    os.mkfifo(case.folder / "pipe.bin")
    server = socket.socket(socket.AF_UNIX)
    server.bind(str(case.folder / "socket.bin"))
    (case.folder / "folder.bin").mkdir()
    (case.folder / "zero.bin").symlink_to("/dev/zero")
    expected = {"pipe.bin": "a FIFO", "socket.bin": "unreadable", "folder.bin": "a folder",
                "zero.bin": "leads out of the scene's folder"}
    try:
        for uri, what in expected.items():
            case.json["buffers"][0]["uri"] = uri
            code, err = case.bake(capsys)
            assert code == 1, err
            case.assert_refused(err, "buffers[0].uri", uri, what)
    finally:
        server.close()


def test_a_buffer_is_read_only_up_to_its_byte_length(case, capsys, monkeypatch):
    """A 64 MiB file named by a buffer of a few hundred bytes: the bake reads what is declared
    (the bytes past it are never read: the bake succeeds and the secret there is not copied)."""
    data = case.bin.read_bytes()
    with open(case.bin, "ab") as stream:
        stream.write(case.secret)
        stream.truncate(64 << 20)
    code, err = case.bake(capsys)
    assert code == 0, err
    assert case.json["buffers"][0]["byteLength"] == len(data)
    case.assert_no_secret()


@pytest.mark.parametrize("uri, name", [("my%20scene.bin", "my scene.bin"),
                                       ("sub/../scene.bin", "scene.bin"),
                                       ("%2573cene.bin", "%73cene.bin")])
def test_relative_uris_inside_the_folder_still_bake(case, capsys, uri, name):
    """Percent-decoding happens once: ``%2573`` is the file ``%73cene.bin``, not ``scene.bin``."""
    (case.folder / "sub").mkdir()
    if name != "scene.bin":
        case.bin.rename(case.folder / name)
    case.json["buffers"][0]["uri"] = uri
    code, err = case.bake(capsys)
    assert code == 0, err
    case.assert_no_secret()


def test_image_files_are_copied_under_names_baker_makes(case, capsys):
    """An image the input names ``mygame/.git/hooks/pre-commit`` (inside its folder) is copied
    beside an output in another folder as ``<stem>_image0``: no path of the input's making is
    created under the output's folder."""
    hooks = case.folder / "mygame" / ".git" / "hooks"
    hooks.mkdir(parents=True)
    (hooks / "pre-commit").write_bytes(case.png.read_bytes())
    case.with_texture("mygame/.git/hooks/pre-commit")
    output = case.out / "baked.gltf"
    code, err = case.bake(capsys, output=output)
    assert code == 0, err
    assert sorted(p.name for p in case.out.rglob("*") if not p.name.endswith(".bake")
                  and not p.name.endswith(".bake.json")) == [
        "baked.bin", "baked.glb", "baked.gltf", "baked_image0"]
    assert (case.out / "baked_image0").read_bytes() == case.png.read_bytes()
    assert json.loads(output.read_text())["images"][0]["uri"] == "baked_image0"


# ------------------------------------------------------------------------------------------------
# writing: every output staged, put in place together or not at all


ALL_OUTPUTS = ("--report", "out/report.json", "--lightmaps", "out/pages", "--error-map",
               "out/errors", "--full")


def _previous_bake(case: Case, capsys) -> dict[str, bytes]:
    """Bake the case with every output (report, page files, error maps, state and its .json),
    then make the floor red, so that the next bake changes every file; return the root's files."""
    args = [str(case.root / a) if a.startswith("out/") else a for a in ALL_OUTPUTS]
    code, err = case.bake(capsys, *args)
    assert code == 0, err
    case.json["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = [0.9, 0.1, 0.1, 1.0]
    return snapshot(case.root)


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` but the scene's own (hidden temporaries and set-aside files
    included), once the previous bake's replaced files are deleted (``spill.remove_later``)."""
    for thread in threading.enumerate():
        if thread.name == "baker-remove-later":
            thread.join()
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and not p.is_symlink() and p.parent.name != "scene"}


def _counting_stage(monkeypatch, fail_at: int | None, count: list[int]) -> None:
    """Wrap ``stage_atomically`` (the bake's files and its state) so that the ``fail_at``-th
    file staged runs out of disk space while it is written."""
    staging = importlib.import_module("baker.run.atomic")
    real = staging.stage_atomically

    def stage(path, data, durable=False, made=None):
        count.append(path)
        if len(count) - 1 != fail_at:
            return real(path, data, durable, made)

        def full(stream):
            stream.write(b"half a file")
            raise OSError(28, "No space left on device")
        return real(path, full, durable, made)

    monkeypatch.setattr(staging, "stage_atomically", stage)
    monkeypatch.setattr(importlib.import_module("baker.rebake.staging"), "stage_atomically", stage)


def test_a_full_disk_at_any_file_leaves_every_previous_file(case, capsys, monkeypatch):
    """The disk fills up while the k-th file of the bake is written (the output, a page file,
    an error map, the state, its .json, the report): exit 1 naming that file, and every file
    of the previous bake as it was, no temporary left."""
    _previous_bake(case, capsys)
    args = [str(case.root / a) if a.startswith("out/") else a for a in ALL_OUTPUTS]
    staged: list[Path] = []
    with monkeypatch.context() as patch:
        _counting_stage(patch, None, staged)
        code, err = case.bake(capsys, *args)
    assert code == 0, err
    names = {p.name for p in staged}
    assert {"baked.glb", "baked.glb.bake", "baked.glb.bake.json", "report.json"} <= names
    assert any("lightmap" in n for n in names) and any("error" in n for n in names)
    before = snapshot(case.root)
    case.json["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = [0.1, 0.9, 0.1, 1.0]
    for fail_at in range(len(staged)):
        with monkeypatch.context() as patch:
            _counting_stage(patch, fail_at, [])
            code, err = case.bake(capsys, *args)
        assert code == 1, (fail_at, err)
        assert "No space left on device" in err and staged[fail_at].name in err, err
        assert snapshot(case.root) == before, staged[fail_at]


@pytest.mark.parametrize("error", [OSError(28, "No space left on device"), KeyboardInterrupt()])
def test_a_failure_while_the_files_are_put_in_place_puts_the_previous_ones_back(
        case, capsys, monkeypatch, error):
    """The k-th rename fails (or Ctrl-C comes then): the files already renamed get their
    previous contents back; exit 1 (130)."""
    staging = importlib.import_module("baker.run.atomic")
    before = _previous_bake(case, capsys)
    args = [str(case.root / a) if a.startswith("out/") else a for a in ALL_OUTPUTS]
    replace, calls = os.replace, []
    for fail_at in range(7):
        def failing(source, destination):
            calls.append(destination)
            if len(calls) - 1 == fail_at:
                raise error
            replace(source, destination)

        calls.clear()
        with monkeypatch.context() as patch:
            patch.setattr(staging.os, "replace", failing)
            code, err = case.bake(capsys, *args)
        assert code == (130 if isinstance(error, KeyboardInterrupt) else 1), err
        assert snapshot(case.root) == before, fail_at


@pytest.mark.parametrize("option, value, message", [
    ("--state", "secret.txt/x.bake", "is a file"),  # a missing folder is made (test_bad_input)
    ("--report", "out", "is a folder"),
    ("--lightmaps", "out/baked.glb", "is a file"),
    ("--error-map", "secret.txt", "is a file"),
    ("--state", "out/folder.bake", "is a folder"),
])
def test_an_output_path_that_cannot_be_written_is_refused_before_baking(case, capsys, option,
                                                                       value, message):
    before = _previous_bake(case, capsys)
    (case.out / "folder.bake").mkdir()
    code, err = case.bake(capsys, option, str(case.root / value))
    assert code == 1, err
    assert message in err and err.startswith("baker: error: ") and "fix:" in err, err
    assert snapshot(case.root) == before


def test_the_default_state_path_being_a_folder_is_refused_before_baking(case, capsys):
    before = _previous_bake(case, capsys)
    (case.out / "baked.glb.bake").unlink()
    (case.out / "baked.glb.bake").mkdir()
    del before["out/baked.glb.bake"]
    code, err = case.bake(capsys)
    assert code == 1 and "baked.glb.bake" in err and "is a folder" in err, err
    assert snapshot(case.root) == before


# ------------------------------------------------------------------------------------------------
# the bake state: checked member by member, anything off a full bake


def _edit_state(path: Path, edit) -> None:
    """Rewrite the bake state at ``path`` with ``edit(header, arrays)`` applied (the header's
    JSON and every ``.npy`` member as arrays, changed in place), CRCs recomputed as an attacker
    would: the state passes every check of its bytes."""
    import io
    import zipfile

    import numpy as np

    with zipfile.ZipFile(path) as archive:
        header = json.loads(archive.read("header.json"))
        arrays = {name[:-4]: np.load(io.BytesIO(archive.read(name)))
                  for name in archive.namelist() if name.endswith(".npy")}
    for name, listed in header.pop("zeros").items():  # every array stored whole, to be edited
        arrays[name] = np.zeros(listed["shape"], listed["dtype"])
    for name, listed in header.pop("repeated").items():
        arrays[name] = np.broadcast_to(arrays[name], listed["shape"]).astype(listed["dtype"])
    for name, listed in header.pop("sparse").items():
        full = np.zeros(listed["shape"], listed["dtype"])
        full[arrays.pop(f"{name}.rows")] = arrays[name]
        arrays[name] = full
    header.update(zeros={}, repeated={}, sparse={})
    compress = edit(header, arrays) or zipfile.ZIP_STORED
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as archive:
        archive.writestr("header.json", json.dumps(header), compress_type=compress)
        for name, array in arrays.items():
            buffer = io.BytesIO()
            np.save(buffer, array)
            archive.writestr(f"{name}.npy", buffer.getvalue())


def _set(name, index, value):
    def edit(header, arrays):
        arrays[name][index] = value
    return edit


def _header(change):
    def edit(header, arrays):
        change(header)
    return edit


STATE_EDITS = {
    "fingerprints {}": _header(lambda h: h.update(fingerprints={})),
    "fingerprints a list": _header(lambda h: h.update(fingerprints=[1, 2])),
    "an instance's fingerprint a string": _header(
        lambda h: h["fingerprints"]["instances"].__setitem__(0, "x")),
    "stored density a string": _header(
        lambda h: h["fingerprints"]["settings"]["values"].update(texel_density="dense")),
    "atlas width 0": _header(lambda h: h["groups"]["atlas"]["scalars"].update(width=0)),
    "page_count -1": _header(lambda h: h["groups"]["atlas"]["scalars"].update(page_count=-1)),
    "a huge listed shape": _header(lambda h: h["zeros"].update(
        {"terms/escaped": {"shape": [1 << 40], "dtype": "<f8"}})),
    "an object dtype": _header(lambda h: h["zeros"].update(
        {"terms/escaped": {"shape": [4], "dtype": "|O"}})),
    "a texel's triangle out of range": _set("texels/triangle", 0, 10 ** 6),
    "an unwrap's vertex out of range": _set("atlas/triangles", (0, 0), 10 ** 6),
    "vertex counts that do not add up": _set("atlas/vertex_counts", 0, 10 ** 6),
    "unsorted keys": _set("texels/key", 0, 1 << 40),
    "NaN terms": _set("terms/w_hit", (0, 0), float("nan")),
    "escaped 5": _set("terms/escaped", slice(None), 5.0),
    "validity state 7": _set("validity/state", 0, 7),
    "infinite world matrix": _set("instance_world", (0, 0, 0), float("inf")),
    "counts as floats": lambda h, a: a.update({"terms/counts": a["terms/counts"] * 1.0}),
    "a deflated header": lambda h, a: __import__("zipfile").ZIP_DEFLATED,
}


@pytest.mark.parametrize("edit", list(STATE_EDITS))
def test_an_edited_bake_state_gives_a_full_bake_of_the_right_lightmap(case, capsys, edit):
    """Every edit of a state whose CRCs pass: exit 0 (never 3) with "full bake: the bake state
    is unusable …" or another reason for a full bake, and an output byte for byte the one a
    bake without a state gives."""
    code, err = case.bake(capsys, "--no-state", output=case.out / "reference.glb")
    assert code == 0, err
    code, err = case.bake(capsys)
    assert code == 0, err
    state = case.out / "baked.glb.bake"
    _edit_state(state, STATE_EDITS[edit])
    case.json["nodes"][0]["translation"] = [0.0, 0.0, 0.0]  # an edit a rebake can follow
    code = main(["bake", str(case.gltf), "-o", str(case.output), *FAST[:-1]])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "full bake: " in out and "internal error" not in err, out
    if edit not in ("fingerprints a list", "a deflated header"):
        assert "unusable" in out or "damaged" in out, out
    assert case.output.read_bytes() == (case.out / "reference.glb").read_bytes()


def test_an_unedited_state_rewritten_so_still_rebakes(case, capsys):
    """The control of the edits above: the state rewritten by ``_edit_state`` with no edit (every
    array stored whole) is used: the rebake follows."""
    code, err = case.bake(capsys)
    assert code == 0, err
    _edit_state(case.out / "baked.glb.bake", lambda header, arrays: None)
    case.json["nodes"][0]["translation"] = [0.0, 0.0, 0.0]
    case.gltf.write_text(json.dumps(case.json))
    code = main(["bake", str(case.gltf), "-o", str(case.output), *FAST[:-1]])
    out, err = capsys.readouterr()
    assert code == 0 and out.startswith("rebake: "), (out, err)


# ------------------------------------------------------------------------------------------------
# exhaustion: special files, bombs, huge declared counts — in a child process, time and memory
# measured

CEILING_KIB = 1_000_000  # resident memory of the whole `baker bake` process (Python, numba, …)
LIMIT_SECONDS = 60.0


# Runs the command given, kills it after LIMIT seconds, prints its exit code and peak resident KiB.
_LAUNCHER = """
import os, subprocess, sys, time
limit, start = float(sys.argv[1]), time.monotonic()
child = subprocess.Popen(sys.argv[2:], stdout=subprocess.DEVNULL)
while True:
    pid, status, usage = os.wait4(child.pid, os.WNOHANG)
    if pid:
        break
    if time.monotonic() - start > limit:
        child.kill()
        pid, status, usage = os.wait4(child.pid, 0)
        break
    time.sleep(0.02)
print(os.waitstatus_to_exitcode(status), usage.ru_maxrss)
"""


def run_measured(*args: str) -> tuple[int, str, float, int]:
    """Run ``python -m baker.cli.main ARGS`` as a child; return (exit code, stderr, seconds,
    peak resident KiB of that child alone). Killed after ``LIMIT_SECONDS``.

    The child is started by a small launcher process, which reads its peak from ``os.wait4``:
    Linux counts in a child's peak the resident size of the process it was forked from (kept
    across exec), and the test process itself grows past the ceiling in a full suite (2.5 GB
    seen), while the launcher is a bare Python of a few MB."""
    import subprocess
    import sys
    import tempfile
    import time

    root = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryFile() as err:
        start = time.monotonic()
        launcher = subprocess.run(
            [sys.executable, "-c", _LAUNCHER, str(LIMIT_SECONDS), sys.executable, "-m",
             "baker.cli.main", *args], cwd=root, stdout=subprocess.PIPE, stderr=err, text=True,
            timeout=LIMIT_SECONDS * 2)
        seconds = time.monotonic() - start
        code, kib = (int(word) for word in launcher.stdout.split())
        err.seek(0)
        return code, err.read().decode(), seconds, kib


SPECIAL_STATES = {  # what is at OUT.bake or its .json → (exit code, what the message says)
    "state FIFO": (1, "is a FIFO that nothing reads"),
    "state link to /dev/zero": (1, "is a symbolic link (to a character device"),
    "timing FIFO": (0, ""),  # a rebake follows; only a full bake writes the timing record
}


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this system")
@pytest.mark.parametrize("special", list(SPECIAL_STATES))
def test_a_special_file_as_the_bake_state_is_neither_read_nor_replaced(case, capsys, special):
    """``OUT.bake`` (or its ``.json``) a FIFO nothing reads, or a link to ``/dev/zero``: not a
    byte read from it, and never renamed over (``--report /dev/stdout`` as root replaced the
    device's link with a regular file): a link is refused before any work, a FIFO is written
    into, and refused when nothing reads it; within the time and memory limits, the FIFO or
    the link left as it was."""
    code, err = case.bake(capsys)
    assert code == 0, err
    state = case.out / "baked.glb.bake"
    target = state if special.startswith("state") else state.with_name(state.name + ".json")
    target.unlink()
    if special.endswith("FIFO"):
        os.mkfifo(target)
    else:
        target.symlink_to("/dev/zero")
    case.gltf.write_text(json.dumps(case.json))
    code, err, seconds, kib = run_measured("bake", str(case.gltf), "-o", str(case.output), *FAST)
    expected, says = SPECIAL_STATES[special]
    assert code == expected and says in err, err
    assert seconds < LIMIT_SECONDS and kib < CEILING_KIB, (seconds, kib)
    assert target.is_fifo() if special.endswith("FIFO") else target.is_symlink()


def deflate_bomb(name: bytes, gib: int) -> bytes:
    """A ZIP archive of one member ``name`` deflated from ``gib`` GiB of spaces, a few MB:
    one deflated MiB (a full flush: a block that stands alone) repeated, then the final block."""
    import struct
    import zlib

    block = b" " * (1 << 20)
    squeeze = zlib.compressobj(9, zlib.DEFLATED, -15)
    chunk = squeeze.compress(block) + squeeze.flush(zlib.Z_FULL_FLUSH)
    data = chunk * (gib << 10) + squeeze.flush(zlib.Z_FINISH)
    crc = 0
    for _ in range(gib << 10):
        crc = zlib.crc32(block, crc)
    size = gib << 30
    local = struct.pack("<IHHHHHIIIHH", 0x04034B50, 20, 0, 8, 0, 33, crc, len(data), size,
                        len(name), 0) + name
    central = struct.pack("<IHHHHHHIIIHHHHHII", 0x02014B50, 20, 20, 0, 8, 0, 33, crc, len(data),
                          size, len(name), 0, 0, 0, 0, 0, 0) + name
    end = struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, 1, 1, len(central), len(local) + len(data),
                      0)
    return local + data + central + end


def test_a_deflate_bomb_in_the_state_is_not_inflated(case, capsys):
    """A 3 MB state whose header.json inflates to 3 GiB: refused from its directory entry (baker
    writes its header stored), a full bake within the time and memory limits."""
    import zipfile

    code, err = case.bake(capsys)
    assert code == 0, err
    state = case.out / "baked.glb.bake"
    state.write_bytes(deflate_bomb(b"header.json", 3))
    with zipfile.ZipFile(state) as archive:  # a valid archive that would inflate to 3 GiB
        assert archive.getinfo("header.json").file_size == 3 << 30
    assert state.stat().st_size < 8 << 20
    case.gltf.write_text(json.dumps(case.json))
    code, err, seconds, kib = run_measured("bake", str(case.gltf), "-o", str(case.output), *FAST)
    assert code == 0, err
    assert seconds < LIMIT_SECONDS and kib < CEILING_KIB, (seconds, kib)


@pytest.mark.parametrize("asked", [{"rays": "many"}, {"page_size": -3}, "not an object"])
def test_rebake_with_unusable_stored_settings_does_not_fail(case, capsys, asked):
    """``baker rebake`` takes the last bake's settings from the state; stored settings that
    are not settings: exit 1 saying so (never 3), the previous output kept."""
    code, err = case.bake(capsys)
    assert code == 0, err
    _edit_state(case.out / "baked.glb.bake",
                _header(lambda h: h["fingerprints"].update(asked=asked)))
    before = snapshot(case.root)
    code = main(["rebake", str(case.gltf), "-o", str(case.output), "--quiet"])
    out, err = capsys.readouterr()
    assert code == 1 and "stored in the bake state" in err and "unusable" in err, err
    assert err.startswith("baker: error: ") and "Traceback" not in err, err
    assert snapshot(case.root) == before


# ------------------------------------------------------------------------------------------------
# no internal error for any input: the JSON parser bounded, overflow-safe checks, Ctrl-C anywhere


def _json_text(case: Case, extra: str) -> None:
    """Save the scene with ``"extras": <extra>`` as raw JSON text at its top."""
    text = json.dumps(case.json)
    case.gltf.write_text('{"extras": ' + extra + ", " + text[1:])


@pytest.mark.parametrize("extra, message", [
    ("1" * 5000, "an integer of 5,000 digits"),
    ("-" + "9" * 401, "an integer of 401 digits"),
    ("[" * 100_000 + "]" * 100_000, "nested more than 64"),
    ("[" * 900 + "]" * 900, "nested more than 64"),  # parses, then too deep for what follows
    ('{"a": ' * 65 + "0" + "}" * 65, "nested more than 64"),
])
def test_json_numbers_and_nesting_are_bounded(case, capsys, extra, message):
    _json_text(case, extra)
    code = main(["bake", str(case.gltf), "-o", str(case.output), *FAST])
    err = capsys.readouterr().err
    assert code == 1, err
    case.assert_refused(err, message)


def test_json_within_the_bounds_bakes(case, capsys):
    _json_text(case, '{"a": ' * 60 + str(int(1e300)) + "}" * 60)
    code = main(["bake", str(case.gltf), "-o", str(case.output), *FAST])
    assert code == 0, capsys.readouterr().err


@pytest.mark.parametrize("scales", [[1e300], [1e200, 1e200], [1e13], [-1e300]])
def test_a_node_scale_that_overflows_is_refused_naming_the_node(case, capsys, scales):
    """Scales of 1e300 (or two nested of 1e200: infinity) made the density check overflow
    (exit 3); a mesh beyond 1e12 units is refused naming the node (the innermost)."""
    nodes = case.json["nodes"]
    for scale in scales[1:]:  # parents around the mesh's node
        nodes.append({"children": [len(nodes) - 1], "scale": [scale] * 3})
    nodes[0]["scale"] = [scales[0]] * 3
    case.json["scenes"][0]["nodes"] = [len(nodes) - 1]
    code, err = case.bake(capsys)
    assert code == 1, err
    case.assert_refused(err, "nodes[0]", "from the origin")


def test_ctrl_c_while_the_pipeline_is_imported_exits_130_with_one_line(monkeypatch, capsys):
    """``baker`` imports the pipeline (numpy, numba, Embree: about a second) inside ``entry``:
    a Ctrl-C then exits 130 with one line, not a traceback of the imports."""
    import signal
    import sys

    from baker.cli import main as cli_main

    real = importlib.import_module

    def interrupted(name, *args):
        if name == "baker.api":
            raise KeyboardInterrupt
        return real(name, *args)

    handler = signal.getsignal(signal.SIGINT)
    monkeypatch.setattr(importlib, "import_module", interrupted)
    monkeypatch.setattr(sys, "argv", ["baker", "bake", "x.glb", "-o", "y.glb"])
    try:
        assert cli_main.entry() == 130
    finally:
        signal.signal(signal.SIGINT, handler)
    assert capsys.readouterr().err == "baker: interrupted; no output was changed\n"


def test_importing_baker_loads_no_pipeline():
    """What makes the test above hold for real: ``import baker.cli.main`` (what the ``baker``
    script does first) loads neither numpy nor the pipeline; the first use does."""
    import subprocess
    import sys

    code = ("import sys, baker.cli.main; "
            "print(sorted(m for m in ('numpy', 'numba', 'embreex', 'baker.api') if m in sys.modules))")
    root = Path(__file__).resolve().parents[1]
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True)
    assert out.stdout.strip() == "[]", out


def _started_as(tmp_path, name: str, ignore_sigint: bool = False):
    """A process that starts as the ``baker`` console script does, from a file named ``name``,
    and gets a Ctrl-C once ``baker.cli`` is imported, before the rest of the command line is:
    its exit code and stderr."""
    import signal
    import subprocess
    import sys

    script = tmp_path / name
    script.write_text("import os, signal, sys\nimport baker.cli\n"
                      "os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C while the rest loads\n"
                      "from baker.cli.main import entry\nsys.exit(entry())\n")
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run(
        [sys.executable, str(script), "--version"], cwd=root, capture_output=True, text=True,
        env=dict(os.environ, PYTHONPATH=str(root)),
        # ignored as a background job's, or at its default as a terminal's foreground job's,
        # whatever the suite was started with
        preexec_fn=lambda: signal.signal(signal.SIGINT,
                                         signal.SIG_IGN if ignore_sigint else signal.SIG_DFL))
    return done.returncode, done.stderr


def test_ctrl_c_while_the_command_line_loads_exits_130_with_one_line(tmp_path):
    """From the moment ``baker.cli`` is imported (the first of baker the command runs, as
    ``import baker`` runs nothing) a Ctrl-C exits 130 with the one line, before ``entry``'s own
    handler; a program named otherwise that imports ``baker.cli`` keeps Python's handler (a
    KeyboardInterrupt), and a command started with SIGINT ignored keeps ignoring it."""
    code, err = _started_as(tmp_path, "baker")
    assert (code, err) == (130, "baker: interrupted; no output was changed\n")
    code, err = _started_as(tmp_path, "other_program.py")
    assert code != 0 and "KeyboardInterrupt" in err
    code, err = _started_as(tmp_path, "baker", ignore_sigint=True)
    assert code == 0 and err == "", err


# ------------------------------------------------------------------------------------------------
# baker watch: every file the scene uses


def test_watch_rebakes_when_the_bin_or_an_image_alone_changes(case):
    """``baker watch`` on a .gltf: touching only its .bin, then only its texture, rebakes each
    time (it watched the .gltf alone: an edit to the .bin was never baked)."""
    import subprocess
    import sys

    case.with_texture("tex.png")
    case.gltf.write_text(json.dumps(case.json))
    root = Path(__file__).resolve().parents[1]
    child = subprocess.Popen(
        [sys.executable, "-m", "baker.cli.main", "watch", str(case.gltf), "-o", str(case.output),
         "--interval", "0.05", "--max-bakes", "3", "--rays", "2", "--page-size", "32"],
        cwd=root, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    watchdog = threading.Timer(LIMIT_SECONDS * 2, child.kill)
    watchdog.start()
    try:
        for touched in (case.bin, case.png, None):
            line = child.stdout.readline()
            while line and not line.startswith("baked "):
                line = child.stdout.readline()
            assert line.startswith("baked "), child.stderr.read()
            if touched is not None:
                stamp = touched.stat().st_mtime_ns
                os.utime(touched, ns=(stamp + 10 ** 9, stamp + 10 ** 9))
        assert child.wait() == 0, child.stderr.read()
    finally:
        watchdog.cancel()
        child.kill()


def test_a_bake_beyond_its_ray_budget_is_refused_before_any_ray(case, capsys, tmp_path):
    """A few bytes a light in the JSON multiply every texel's rays (a 3 KB file can ask for
    years): the bake's texels × rays a texel is checked against ``max_total_rays`` before any
    ray. Refused: exit 1 with the figures (texels, the rays of each, the lights); the figures
    are the bake's own (the report of the same bake allowed counts as many texels), and a
    budget of exactly that many rays bakes while one ray less is refused."""
    import re

    lights = 40
    case.json.setdefault("extensionsUsed", []).append("KHR_lights_punctual")
    case.json["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"type": "point", "intensity": 1.0}] * lights}}
    first = len(case.json["nodes"])
    case.json["nodes"] += [{"translation": [0.01 * i, 1.0, 0.0],
                            "extensions": {"KHR_lights_punctual": {"light": i}}}
                           for i in range(lights)]
    case.json["scenes"][0]["nodes"] += list(range(first, first + lights))
    code, err = case.bake(capsys, "--max-total-rays", "1000")
    assert code == 1, err
    case.assert_refused(err, "max_total_rays", f"{lights} lights", "--max-total-rays")
    texels, per_texel = (int(x.replace(",", "")) for x in
                         re.search(r"([\d,]+) texels × ([\d,]+) rays each", err).groups())
    assert per_texel == 2 + lights + 36  # --rays 2, a hard shadow ray a light, the probes
    code, err = case.bake(capsys, "--max-total-rays", str(texels * per_texel - 1))
    assert code == 1 and "max_total_rays" in err, err
    report = tmp_path / "report.json"
    code, err = case.bake(capsys, "--max-total-rays", str(texels * per_texel), "--report",
                          str(report))
    assert code == 0, err
    assert json.loads(report.read_text())["texels"] == texels


@pytest.mark.parametrize("accessors, count", [(6, 1 << 25), (1, 1 << 27)])
def test_accessors_declaring_gigabytes_are_refused_before_allocating(case, accessors, count):
    """A 2 KB glTF whose accessors have no bufferView (zeros: nothing in the file bounds their
    count) and declare 6 × 2^25 VEC3 or one 2^27 VEC3 (4.8 and 3.2 GB as float64): refused from
    the declared counts, naming the largest accessor and the figure, in a child well under the
    memory ceiling."""
    first = len(case.json["accessors"])
    attributes = case.json["meshes"][0]["primitives"][0]["attributes"]
    for k in range(accessors):
        case.json["accessors"].append({"componentType": 5126, "count": count, "type": "VEC3"})
        attributes[f"COLOR_{k}" if k else "NORMAL"] = first + k
    case.gltf.write_text(json.dumps(case.json))
    assert case.gltf.stat().st_size < 4096
    code, err, seconds, kib = run_measured("bake", str(case.gltf), "-o", str(case.output), *FAST)
    assert code == 1, err
    assert f"accessors[{first}]" in err and f"{3 * count:,}" in err, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 2, err
    assert seconds < LIMIT_SECONDS and kib < CEILING_KIB, (seconds, kib)
