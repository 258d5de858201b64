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
import secrets
import socket
import threading
from pathlib import Path

import pytest
from PIL import Image as PILImage

from assets.gltf_builder import GltfBuilder, quad
from assets.make_scenes import checker
from baker.cli.main import main

FAST = ["--rays", "2", "--page-size", "32", "--quiet"]
PREVIOUS = b"the previous bake: must survive every failure\n"


class Case:
    """A scene folder beside a decoy: ``root/secret.txt``, ``root/secret.bin`` (the scene's
    buffer + the secret), ``root/secret.png`` (its texture + the secret), ``root/scene/`` with
    ``scene.gltf``, ``scene.bin``, ``tex.png``, and ``root/out/`` holding a previous bake."""

    def __init__(self, root: Path):
        self.root, self.folder, self.out = root, root / "scene", root / "out"
        self.folder.mkdir()
        self.out.mkdir()
        self.secret = f"BAKER-DECOY-{secrets.token_hex(8)}".encode()
        builder = GltfBuilder()
        material = builder.material("floor", (0.8, 0.8, 0.8))
        builder.node("floor", builder.shape_mesh("floor", quad(2.0, 2.0), material=material))
        self.gltf = builder.save(self.folder / "scene.gltf")
        self.json = json.loads(self.gltf.read_text())
        self.bin = self.folder / self.json["buffers"][0]["uri"]
        self.png = self.folder / "tex.png"
        PILImage.fromarray(checker(8, 2)).save(self.png)
        (root / "secret.txt").write_bytes(self.secret)
        (root / "secret.bin").write_bytes(self.bin.read_bytes() + self.secret)
        (root / "secret.png").write_bytes(self.png.read_bytes() + self.secret)
        self.output = self.out / "baked.glb"
        self.output.write_bytes(PREVIOUS)

    def with_texture(self, uri: str, slot: str = "baseColorTexture") -> None:
        """Give the floor's material a texture whose image has ``uri`` (``slot``: which)."""
        self.json["images"] = [{"uri": uri}]
        self.json["textures"] = [{"source": 0}]
        material = self.json["materials"][0]
        if slot == "baseColorTexture":
            material.setdefault("pbrMetallicRoughness", {})[slot] = {"index": 0}
        else:
            material[slot] = {"index": 0}

    def bake(self, capsys, *args: str, output: Path | None = None) -> tuple[int, str]:
        """Save the edited JSON, bake it; return (exit code, stderr)."""
        self.gltf.write_text(json.dumps(self.json))
        code = main(["bake", str(self.gltf), "-o", str(output or self.output), *FAST, *args])
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


def escapes(root: Path, name: str) -> list[str]:
    """URIs of the decoy ``root/name`` (outside the scene's folder ``root/scene``), spelt every
    way an attacker might: ``..``, percent-encoded once, absolute, with a scheme."""
    absolute = (root / name).as_posix()
    return ["../" + name, "..%2F" + name, "%2E%2E/" + name, "%2e%2e%2f" + name, absolute,
            "/" + absolute, "file://" + absolute, "sub/../../" + name,
            "../" * 12 + absolute.lstrip("/"), "sub%2F..%2F..%2F" + name]


ESCAPES = range(len(escapes(Path("/r"), "x")))


@pytest.mark.parametrize("spelling", ESCAPES)
def test_a_buffer_outside_the_scenes_folder_is_refused(case, capsys, spelling):
    uri = escapes(case.root, "secret.bin")[spelling]
    (case.folder / "sub").mkdir()
    case.json["buffers"][0]["uri"] = uri
    code, err = case.bake(capsys)
    assert code == 1, err
    case.assert_refused(err, "buffers[0].uri", uri[:60])
    case.assert_no_secret()


@pytest.mark.parametrize("slot", ["baseColorTexture", "normalTexture"])
@pytest.mark.parametrize("spelling", ESCAPES)
def test_an_image_outside_the_scenes_folder_is_refused(case, capsys, spelling, slot):
    """A colour texture (decoded by the bake) or a normal map (only carried over: copied beside
    an output in another folder) alike."""
    (case.folder / "sub").mkdir()
    uri = escapes(case.root, "secret.png")[spelling]
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

    def stage(path, data, durable=False):
        count.append(path)
        if len(count) - 1 != fail_at:
            return real(path, data, durable)

        def full(stream):
            stream.write(b"half a file")
            raise OSError(28, "No space left on device")
        return real(path, full, durable)

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
