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

import numpy as np
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


class _Fake:
    """A clock (``now``) and the seconds spent compiling by then (``compiled``), set by hand."""

    def __init__(self):
        self.now, self.compiled = 0.0, 0.0

    def meter(self) -> Meter:
        return Meter(clock=lambda: self.now, compiled=lambda: self.compiled)


def test_each_stage_s_rays_to_come_are_priced_at_its_own_seconds_per_ray():
    """A GI-like stage at 0.03 s a ray, then an obscurance-like one at 0.01: while only the
    first has reported, the second's rays are priced at the first's cost; once both have,
    each at its own. A compile (100 s) during a report's interval is left out."""
    clock = _Fake()
    meter = clock.meter()
    gi, obscurance = meter.stage(100, 10), meter.stage(100, 4)
    assert meter.seconds_left() is None  # nothing to go by yet
    meter.start()
    for chunk in range(5):
        clock.now += 3.0 + (100.0 if chunk == 0 else 0.0)
        clock.compiled += 100.0 if chunk == 0 else 0.0
        gi(10, 100)
    assert meter.seconds_left() == pytest.approx(500 * 0.03 + 400 * 0.03)
    for _ in range(5):
        clock.now += 3.0
        gi(10, 100)
    for _ in range(2):
        clock.now += 0.8
        obscurance(20, 80)
    assert meter.seconds_left() == pytest.approx(240 * 0.01)


@pytest.mark.parametrize("seed", range(6))
def test_once_every_stage_has_reported_the_time_left_is_the_time_left(seed):
    """Generated bakes: 2–4 stages of random costs per ray and rays per texel, in 1–4 parts of
    random chunks (each part runs the stages in turn, as ``full._bake_part``), compiles here
    and there, threads none: once every stage has reported, the time left is exact while each
    stage's cost stays as it was (each stage's rays to come × its seconds per ray)."""
    rng = np.random.default_rng(seed)
    stages, parts = int(rng.integers(2, 5)), int(rng.integers(1, 5))
    cost = rng.uniform(0.1, 5.0, stages)  # seconds per ray
    per_texel = rng.integers(1, 20, stages)
    clock = _Fake()
    meter = clock.meter()
    reports = [meter.stage(60 * parts, rng.uniform(1, 20)) for _ in range(stages)]
    events = []  # (stage, texels) in order
    for _ in range(parts):
        for s in range(stages):
            cuts = np.sort(rng.choice(np.arange(1, 60), int(rng.integers(0, 5)), replace=False))
            events += [(s, int(count)) for count in np.diff(np.r_[0, cuts, 60])]
    left = sum(count * per_texel[s] * cost[s] for s, count in events)
    meter.start()
    seen = set()
    for s, count in events:
        compile_seconds = float(rng.uniform(0, 30)) if rng.random() < 0.2 else 0.0
        clock.now += count * per_texel[s] * cost[s] + compile_seconds
        clock.compiled += compile_seconds
        left -= count * per_texel[s] * cost[s]
        reports[s](count, int(count * per_texel[s]))
        seen.add(s)
        if len(seen) == stages:
            assert meter.seconds_left() == pytest.approx(left, rel=1e-9, abs=1e-9)
    assert meter.seconds_left() == pytest.approx(0.0, abs=1e-9)


class _Recorded(progress.bar_class()):
    """The bar drawing into a string, recording (rays done, total) at every update."""

    updates: list[tuple[int, int]] = []

    def __init__(self, **options):
        super().__init__(file=io.StringIO(), **options)

    def update(self, n=1):
        super().update(n)
        _Recorded.updates.append((self.n, self.total))


@pytest.mark.parametrize("method", ["obscurance", "gi"])
def test_the_total_after_a_tenth_of_the_work_is_within_a_quarter(tmp_path, monkeypatch, method):
    """When a tenth of the rays are cast, the rays the bar says are left, total − done, are
    within 25 % of those really left (GI's path lengths are guessed until its first chunk).
    The bar ends at its total, advancing with every stage, GI included."""
    monkeypatch.setattr(progress, "bar_class", lambda: _Recorded)
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
    assert 0.75 <= (total - n) / (final - n) <= 1.25, (n, total, final)


@pytest.mark.long
@pytest.mark.parametrize("method", ["obscurance", "gi"])
def test_an_adaptive_bake_s_bar_does_not_stand_at_its_total_while_rounds_run(tmp_path,
                                                                             monkeypatch, method):
    """With ``--target-error`` the rounds after the first announce their rays: the bar's
    total is above its rays done at every update but one at each round's end (the next
    round's announcement follows it, at the same rays done), until the last ray."""
    monkeypatch.setattr(progress, "bar_class", lambda: _Recorded)
    monkeypatch.setattr(full, "wanted", lambda quiet: True)
    _Recorded.updates = []
    computed(cornell_box(), tmp_path, page_size=128, method=method, target_error=0.01,
             max_rays=256)
    updates = _Recorded.updates
    final = updates[-1][1]
    assert updates[-1][0] == final
    stood = [i for i, (n, total) in enumerate(updates) if n < final and total <= n]
    assert all(updates[i + 1][0] == updates[i][0] < updates[i + 1][1] for i in stood), [
        (updates[i], updates[i + 1]) for i in stood]
    rounds = sum(1 for a, b in zip(updates, updates[1:]) if b[0] == a[0] and b[1] > a[1])
    assert rounds >= 2  # the test saw rounds announced


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


def test_a_stage_s_steps_are_drawn_with_the_time_left_once_it_has_run_its_delay(
        capsys, monkeypatch):
    """A stage counting its steps draws, on a terminal, a bar of them with the time left at
    its mean pace so far once it has run ``Steps.DELAY``; a stage that ends sooner draws
    nothing but its line."""
    import tqdm.std

    clock = [0.0]
    monkeypatch.setattr(tqdm.std, "time", lambda: clock[0])
    steps = progress.Steps("unwrap", "triangles", draw=True)
    steps.expect(1000)
    clock[0] = 1.0
    steps.advance(100)  # 1 s in: not drawn yet
    assert "baker: unwrap" not in capsys.readouterr().err
    clock[0] = 4.0
    steps.advance(300)  # 400 in 4 s: 600 more at that pace is 6 s
    drawn = capsys.readouterr().err
    assert re.search(r"baker: unwrap:  40%\|[^|]*\| 400/1\.0*k triangles \[00:04<00:06\]", drawn)
    steps.done_so_far(1000)
    steps.close()
    quick = progress.Steps("write", "steps", draw=True)
    quick.expect(10)
    quick.advance(10)
    quick.close()
    assert "baker: write" not in capsys.readouterr().err


def test_the_long_stages_count_their_steps_to_the_end(tmp_path, capsys, monkeypatch):
    """A bake on a terminal whose stages all run longer than ``Steps.DELAY`` (0 here): unwrap,
    post-process and write each draw a bar of their steps, and count every one they announced."""
    monkeypatch.setattr(progress, "wanted", lambda quiet: not quiet)
    monkeypatch.setattr(progress.Steps, "DELAY", 0.0)
    monkeypatch.setenv("BAKER_CACHE_DIR", "off")
    counted = {}
    close = progress.Steps.close

    def recorded(steps):
        counted[steps._name] = (steps.done, steps.total)
        close(steps)

    monkeypatch.setattr(progress.Steps, "close", recorded)
    import baker
    scene = cornell_box().save(tmp_path / "cornell.glb")
    baker.bake(scene, tmp_path / "out.glb", baker.Settings(page_size=64, rays=2), state=False,
               quiet=False)
    drawn = capsys.readouterr().err
    for stage, unit in (("unwrap", "triangles"), ("post-process", "texels"), ("write", "steps")):
        assert re.search(rf"baker: {re.escape(stage)}: +\d+%\|[^|]*\| [\d.]+k?/[\d.]+k? {unit}",
                         drawn)
        done, total = counted[stage]
        assert done == total > 0
