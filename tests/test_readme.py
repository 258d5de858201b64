"""Every command in the README's fenced ``sh`` and ``python`` blocks runs, as written, in a fresh
folder, in the order the README gives them: a new user who types them gets no error.

The mapping from the README to this test, and nothing else, is:

- ``python3 -m venv .venv && . .venv/bin/activate`` is not run, and ``pip install . && `` and
  ``pip install -e ".[test]" &&`` are dropped: the checkout is on PYTHONPATH and ``baker`` is the
  console script pyproject.toml's ``[project.scripts]`` names (made here as pip makes it).
  ``bash .ci/run`` runs those lines as written, in a new virtual environment.
- ``pip install -e ".[test]" && npm ci … && python -m pytest`` is not run: it is the command
  that runs this test.
- The scene files the README names (``level.glb``, ``level.gltf``, ``prop.glb``) are the demo
  Cornell box that the README's first line makes.
- Small settings, so the whole README runs in well under a minute: ``--rays N`` becomes
  ``--rays 4`` and ``rays=N`` ``rays=4``; each ``baker bake`` and ``baker watch`` gets
  ``--page-size 128`` and each ``baker.Settings(`` ``page_size=128`` (about 9,000 texels
  instead of 530,000).
- ``baker watch`` runs until its first bake is done, ``baker view`` until its page answers
  at the address it printed; then each gets Ctrl-C (SIGINT to its process group, as a
  terminal sends it) and must exit 130, as the README says.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import tomllib
import urllib.request
from pathlib import Path

import pytest

from assets.make_scenes import cornell_box

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
SMALL_RAYS = "4"
SMALL_PAGE = "128"
NOT_RUN = ("python -m pytest", "python3 -m venv")  # this suite's line; the venv is CI's (.ci/run)
DROPPED = ('pip install -e ".[test]" && ', "pip install . && ")  # the checkout is on PYTHONPATH


def fenced_blocks(text: str) -> list[tuple[str, str]]:
    """The README's fenced blocks as (language, body), in order."""
    return re.findall(r"^```(\w+)\n(.*?)^```", text, flags=re.S | re.M)


def commands(text: str) -> list[tuple[str, str]]:
    """(kind, command) in README order: each line of an ``sh`` block, each ``python`` block whole."""
    found = []
    for language, body in fenced_blocks(text):
        if language == "sh":
            found += [("sh", line) for line in body.splitlines()
                      if line.strip() and not any(words in line for words in NOT_RUN)]
        elif language == "python":
            found.append(("python", body))
    return found


def small(kind: str, command: str) -> str:
    """The command with the test's small settings (the module docstring's mapping)."""
    for dropped in DROPPED:
        command = command.replace(dropped, "")
    command = re.sub(r"--rays \d+", f"--rays {SMALL_RAYS}", command)
    command = re.sub(r"\brays=\d+", f"rays={SMALL_RAYS}", command)
    command = command.replace("baker.Settings(", f"baker.Settings(page_size={SMALL_PAGE}, ")
    return re.sub(r"\bbaker (bake|watch) (?!--help)", rf"baker \1 --page-size {SMALL_PAGE} ",
                  command)


def outputs(command: str) -> list[str]:
    """The files a shell command names with ``-o``, ``--report``, or a Python bake's second
    argument, which must exist once it has run."""
    named = re.findall(r"(?:-o|--report) (\S+)", command)
    return named + re.findall(r'baker\.bake\("[^"]+", "([^"]+)"', command)


def console_script(folder: Path) -> None:
    """``baker`` (and ``python``) in ``folder`` as pip installs them: a script calling the entry
    point that pyproject.toml names."""
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    module, function = scripts["baker"].split(":")
    script = folder / "baker"
    script.write_text(f"#!{sys.executable}\nimport sys\nfrom {module} import {function}\n"
                      f"sys.exit({function}())\n")
    script.chmod(0o755)
    # a script, not a link: a venv's python found through a link in another folder finds no
    # pyvenv.cfg beside it and runs without the venv's packages
    python = folder / "python"
    python.write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
    python.chmod(0o755)


def scene_files(folder: Path) -> None:
    """The scene files the README's commands name, in ``folder`` (the module docstring)."""
    demo = folder / "assets" / "scenes" / "cornell_box.glb"
    for name in ("level.glb", "prop.glb"):
        shutil.copy(demo, folder / name)
    cornell_box().save(folder / "level.gltf")


@pytest.fixture
def newcomer(tmp_path):
    """A fresh folder holding the repository's assets/ (no scenes made yet), and the environment
    a user has after ``pip install``."""
    shutil.copytree(ROOT / "assets", tmp_path / "assets",
                    ignore=shutil.ignore_patterns("scenes", "__pycache__"))
    bin_folder = tmp_path / ".bin"
    bin_folder.mkdir()
    console_script(bin_folder)
    env = dict(os.environ, PATH=f"{bin_folder}{os.pathsep}{os.environ['PATH']}",
               PYTHONPATH=str(ROOT))
    return tmp_path, env


# Commands that run until Ctrl-C, and the line each prints once it is ready.
UNTIL_CTRL_C = {" watch ": "baked ", " view ": "baker view: "}


def _until_ctrl_c(command: str) -> str | None:
    """The ready line of a command that runs until Ctrl-C, None for one that ends."""
    return next((ready for word, ready in UNTIL_CTRL_C.items() if word in command), None)


def run(kind: str, command: str, folder: Path, env: dict) -> subprocess.CompletedProcess:
    """Run one README command in ``folder``. ``baker watch`` and ``baker view`` are stopped by
    Ctrl-C once ready (watch: its first bake done; view: its page fetched from the address it
    printed, which must answer 200)."""
    argv = ["bash", "-c", command] if kind == "sh" else [sys.executable, "-c", command]
    ready = _until_ctrl_c(command)
    if ready is None:
        return subprocess.run(argv, cwd=folder, env=env, capture_output=True, text=True,
                              timeout=600)
    # SIGINT at its default, as a terminal's foreground job has it, even where the suite was
    # started with it ignored (a background job of a shell script)
    process = subprocess.Popen(argv, cwd=folder, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, start_new_session=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    lines, served = [], True
    for line in process.stdout:
        lines.append(line)
        if line.startswith(ready):
            break
    address = re.search(r"http://127\.0\.0\.1:\d+/\S*", "".join(lines))
    if " view " in command:
        try:
            with urllib.request.urlopen(address.group(0), timeout=30) as page:
                served = page.status == 200
        except (AttributeError, OSError):
            served = False
    os.killpg(process.pid, signal.SIGINT)
    out, err = process.communicate(timeout=60)
    return subprocess.CompletedProcess(argv, process.returncode if served else -1,
                                       "".join(lines) + out, err)


def test_readme_lists_the_commands_this_test_runs():
    """The extraction sees the README's blocks: the first line, the bake variants, Python, the
    rebake commands, the viewer (so a README reshuffle cannot make this test run nothing)."""
    found = [command for _, command in commands(README.read_text())]
    assert any("make_scenes.py" in c for c in found)
    for expected in ("baker bake level.gltf -o out/level.gltf", "baker watch", "baker relight",
                     "baker rebake", "baker view", "baker.bake("):
        assert any(expected in c for c in found), expected


def test_every_readme_command_runs_as_written(newcomer):
    folder, env = newcomer
    failures = []
    for kind, command in commands(README.read_text()):
        failures += _failures(kind, command, folder, env)
    assert not failures, "\n\n".join(failures)


def _failures(kind: str, command: str, folder: Path, env: dict) -> list[str]:
    """What went wrong running one README command: nothing ([]), or one message."""
    ran = run(kind, small(kind, command), folder, env)
    if "make_scenes.py" in command:  # the demo scenes are made: the README's scene names
        scene_files(folder)
    expected = 130 if _until_ctrl_c(command) else 0
    missing = [name for name in outputs(command) if not (folder / name).is_file()]
    if ran.returncode == expected and not missing and "Traceback" not in ran.stderr:
        return []
    return [f"{command!r}: exit {ran.returncode} (expected {expected}), missing {missing}\n"
            f"{ran.stdout[-600:]}\n{ran.stderr[-1500:]}"]
