"""The bake's progress: one bar over the rays there are to cast, on every method; its total
known early enough for an ETA to mean something; drawn on any terminal, never in pipelines;
one line per stage with its time, everywhere but with --quiet."""

from __future__ import annotations

import io
import json
import os
import re
import pty
import subprocess
import sys
from pathlib import Path

import pytest

import baker.pipeline.full as full
import baker.run.progress as progress
from assets.make_scenes import cornell_box
from baker.run.progress import Meter
from bakehelp import computed

ROOT = Path(__file__).resolve().parents[1]


def test_a_stage_is_re_estimated_from_its_mean_so_far():
    """A stage guessed at 10 rays a texel that casts 14: after its first report the total is
    the other stages' plus 14 a texel; at the end done == total, whatever the guess."""
    meter = Meter()
    exact = meter.stage(100, 8)
    guessed = meter.stage(50, 10)
    assert meter.total() == 800 + 500
    exact(100, 800)
    guessed(10, 140)
    assert meter.total() == 800 + 50 * 14
    guessed(40, 40 * 14 + 3)
    assert meter.done() == meter.total() == 800 + 50 * 14 + 3


class _Recorded(progress.tqdm):
    """tqdm drawing into a string, recording (rays done, total) at every update."""

    updates: list[tuple[int, int]] = []

    def __init__(self, **options):
        super().__init__(file=io.StringIO(), **options)

    def update(self, n=1):
        super().update(n)
        _Recorded.updates.append((self.n, self.total))


@pytest.mark.parametrize("method", ["obscurance", "gi"])
def test_the_eta_after_a_tenth_of_the_work_is_within_a_quarter(tmp_path, monkeypatch, method):
    """On a fake clock where time is the rays cast (a steady rate), the bar's ETA when a tenth
    of the rays are cast, elapsed × (total − done)/done, is within 25 % of the time left; it
    is off only by the total's estimate (GI's path lengths are guessed until its first chunk).
    The bar ends at its total, advancing with every stage, GI included."""
    monkeypatch.setattr(progress, "tqdm", _Recorded)
    monkeypatch.setattr(full, "wanted", lambda quiet: True)
    _Recorded.updates = []
    done = computed(cornell_box(), tmp_path, rays=16, page_size=128, method=method)
    updates = _Recorded.updates
    final = updates[-1][1]
    assert updates[-1][0] == final
    assert all(b[0] >= a[0] for a, b in zip(updates, updates[1:]))  # never backwards
    cast = done.tally.rays + done.tally.shadow_rays  # obscurance and direct light's rays
    assert final > cast if method == "gi" else final == cast
    n, total = next((n, total) for n, total in updates if n >= 0.1 * final)
    # In rays, on this clock: elapsed = n, rate 1, ETA = elapsed × (total − n) / n.
    eta, left = total - n, final - n
    assert 0.75 <= eta / left <= 1.25, (n, total, final)


def _bake_with_stderr_on(stderr, env, tmp_path, *more: str) -> subprocess.Popen:
    source = cornell_box().save(tmp_path / "box.glb")
    return subprocess.Popen(
        [sys.executable, "-m", "baker.cli.main", "bake", str(source), "-o",
         str(tmp_path / "baked.glb"), "--rays", "64", "--page-size", "256", "--no-state", *more],
        cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=stderr)


STAGES = ("load", "lights and plan", "unwrap", "rasterise", "texels and rays", "post-process",
          "write")  # a full bake's stage lines, in order
def test_the_bar_is_drawn_on_a_terminal_that_gives_no_size(tmp_path):
    """A new pseudo-terminal has a size of 0 × 0 (as under ``script`` or a CI runner's tty):
    the bar is drawn all the same (tqdm alone hides it there)."""
    master, slave = pty.openpty()
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    process = _bake_with_stderr_on(slave, env, tmp_path)
    os.close(slave)
    drawn = b""
    while True:
        try:
            chunk = os.read(master, 1 << 16)
        except OSError:  # the child closed the terminal
            break
        if not chunk:
            break
        drawn += chunk
    os.close(master)
    assert process.wait(timeout=300) == 0
    text = drawn.decode(errors="replace")
    assert "baking:" in text and "%|" in text and "ray/s" in text
    for stage in STAGES:  # shown while it runs, then completed with its time
        assert f"baker: {stage}" in text
        assert re.search(rf"baker: {re.escape(stage)}[^\r\n]* …", text)
        assert re.search(rf"\r\x1b\[Kbaker: {re.escape(stage)}[^\r\n]* \d+\.\d\d s\r?\n", text)


def test_a_pipeline_gets_one_line_per_stage_with_its_true_time(tmp_path):
    """Not a terminal (a pipe; CI likewise): no bar, no redraws, one line per stage, in order,
    each with the stage's wall time; the unwrap's is the report's unwrap time."""
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    report = tmp_path / "report.json"
    process = _bake_with_stderr_on(subprocess.PIPE, env, tmp_path, "--report", str(report))
    _, err = process.communicate(timeout=300)
    assert process.returncode == 0
    text = err.decode()
    assert "\r" not in text and "%|" not in text
    lines = text.splitlines()
    assert len(lines) == len(STAGES)
    seconds = {}
    for line, stage in zip(lines, STAGES):
        found = re.fullmatch(rf"baker: ({re.escape(stage)})(?: \([\d,]+ texels\))? "
                             rf"(\d+\.\d\d) s", line)
        assert found, line
        seconds[stage] = float(found.group(2))
    stage_seconds = json.loads(report.read_text())["stage_seconds"]
    assert abs(seconds["unwrap"] - stage_seconds["unwrap"]) <= 0.01 + 0.05 * stage_seconds["unwrap"]
    assert abs(seconds["write"] - stage_seconds["write"]) <= 0.01 + 0.05 * stage_seconds["write"]


def test_quiet_prints_no_stage_line(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    process = _bake_with_stderr_on(subprocess.PIPE, env, tmp_path, "--quiet")
    _, err = process.communicate(timeout=300)
    assert process.returncode == 0 and err == b""
