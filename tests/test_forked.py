"""A call run in a forked child (``baker/run/forked.py``, how xatlas runs): its value or its error
comes back, and a child killed by a signal is run again."""

from __future__ import annotations

import faulthandler
import os
import signal
import sys
import time

import numpy as np
import pytest

from baker.run import forked as forked
from baker.errors import BakerError

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="forked calls are made on Linux only; elsewhere in-process")


def call_forked(function, what: str, seconds: float):
    """One function run as the charting runs its calls (``forked.call_forked_together``)."""
    return forked.call_forked_together([function], what, seconds)[0]


def test_the_childs_value_comes_back_and_the_child_is_another_process():
    def work():
        return os.getpid(), np.arange(5.0) * 2

    pid, values = call_forked(work, "a test", 60)
    assert pid != os.getpid()
    assert np.array_equal(values, np.arange(5.0) * 2)


def _crash() -> None:
    """Die of SIGSEGV, as xatlas's race does (without pytest's fault handler's report)."""
    faulthandler.disable()
    os.kill(os.getpid(), signal.SIGSEGV)


def test_a_child_killed_by_a_signal_is_run_again(tmp_path):
    marker = tmp_path / "first"

    def crashes_once():
        if not marker.exists():
            marker.write_text("crashed")
            _crash()
        return "second run"

    assert call_forked(crashes_once, "a test", 60) == "second run"
    assert marker.read_text() == "crashed"


def test_a_child_that_always_crashes_ends_in_a_clear_error(tmp_path):
    runs = tmp_path / "runs"
    runs.mkdir()

    def always():
        (runs / str(len(list(runs.iterdir())))).touch()
        _crash()

    with pytest.raises(BakerError) as caught:
        call_forked(always, "the unwrapper (xatlas)", 60)
    assert "the unwrapper (xatlas) crashed 3 times in a row (SIGSEGV" in str(caught.value)
    assert "fix:" in str(caught.value)
    assert len(list(runs.iterdir())) == forked.ATTEMPTS


def test_the_childs_error_is_raised_here():
    def fails():
        raise ValueError("no mesh")

    with pytest.raises(ValueError, match="no mesh"):
        call_forked(fails, "a test", 60)


def test_a_child_that_hangs_is_killed_and_run_again(tmp_path):
    marker = tmp_path / "first"

    def hangs_once():
        if not marker.exists():
            marker.write_text("hung")
            time.sleep(600)
        return "second run"

    start = time.monotonic()
    assert call_forked(hangs_once, "a test", 1.0) == "second run"
    assert time.monotonic() - start < 10


def test_a_child_that_spins_is_killed_by_its_cpu_time_and_run_again(tmp_path):
    """A hung xatlas may spin (its main thread yields in a loop): its CPU time passes the limit."""
    marker = tmp_path / "first"

    def spins_once():
        if not marker.exists():
            marker.write_text("spun")
            while True:
                pass
        return "second run"

    start = time.monotonic()
    assert call_forked(spins_once, "a test", 1.0) == "second run"
    assert time.monotonic() - start < 30  # 1 s of CPU, at any share of a core a CI gives


def test_a_child_slowed_by_a_busy_machine_is_not_killed(tmp_path):
    """A child that gets a tenth of a core (a machine loaded by other work) runs three times
    its CPU limit in clock time and is left to finish: hung is judged by CPU time."""
    runs = tmp_path / "runs"
    runs.mkdir()

    def slowed():
        (runs / str(len(list(runs.iterdir())))).touch()
        end = time.monotonic() + 3.0
        while time.monotonic() < end:
            busy = time.thread_time() + 0.01
            while time.thread_time() < busy:  # 10 ms of work, then 90 ms without the core
                pass
            time.sleep(0.09)
        return "finished"

    assert call_forked(slowed, "a test", 1.0) == "finished"
    assert len(list(runs.iterdir())) == 1


def test_cpu_time_is_that_of_the_process_and_none_once_it_has_exited():
    pid = os.fork()
    if pid == 0:
        busy = time.process_time() + 0.3
        while time.process_time() < busy:
            pass
        time.sleep(30)
        os._exit(0)
    try:
        deadline = time.monotonic() + 30
        while (forked.cpu_seconds_of(pid) or 0.0) < 0.28 and time.monotonic() < deadline:
            time.sleep(0.05)  # /proc counts in ticks (10 ms): 0.3 s may read 0.29
        time.sleep(0.5)  # asleep now: no more CPU time
        used = forked.cpu_seconds_of(pid)
        assert used is not None and 0.28 <= used < 0.5
    finally:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    assert forked.cpu_seconds_of(pid) is None


def test_a_bake_whose_chart_builder_crashes_once_gives_the_same_bytes(tmp_path, monkeypatch):
    """The charting goes through ``call_forked_together``: a child dying of SIGSEGV in its first
    run (as xatlas's task scheduler's race makes it) costs a re-run, not the bake."""
    from baker.atlas import charts

    monkeypatch.setenv("BAKER_CACHE_DIR", "off")  # both bakes chart every mesh

    import baker
    from assets.make_scenes import cornell_box

    scene = cornell_box().save(tmp_path / "cornell.glb")
    settings = baker.Settings(page_size=128, rays=4, shadow_rays=1, threads=1)
    baker.bake(scene, tmp_path / "calm.glb", settings, state=False)
    marker = tmp_path / "crashed"
    real = charts.chart_many

    def crashes_once(meshes):
        if not marker.exists():
            marker.write_text("crashed")
            _crash()
        return real(meshes)

    monkeypatch.setattr(charts, "chart_many", crashes_once)
    baker.bake(scene, tmp_path / "crashed.glb", settings, state=False)
    assert marker.read_text() == "crashed"
    assert (tmp_path / "crashed.glb").read_bytes() == (tmp_path / "calm.glb").read_bytes()


def test_calls_made_together_run_at_once_and_come_back_in_order(tmp_path):
    def meets(me: str, other: str):
        def work():
            (tmp_path / me).touch()
            for _ in range(2000):  # up to 20 s: only a child running beside the other's sees it
                if (tmp_path / other).exists():
                    return me, os.getpid()
                time.sleep(0.01)
            return me, None
        return work

    (a, pid_a), (b, pid_b) = forked.call_forked_together([meets("a", "b"), meets("b", "a")],
                                                         "a test", 60)
    assert (a, b) == ("a", "b")
    assert None not in (pid_a, pid_b) and pid_a != pid_b


def test_a_crashed_call_of_several_is_run_again_alone(tmp_path):
    runs = tmp_path / "runs"
    runs.mkdir()

    def steady():
        (runs / f"steady{len(list(runs.iterdir()))}").touch()
        return "steady"

    def crashes_once():
        if not (tmp_path / "crashed").exists():
            (tmp_path / "crashed").touch()
            _crash()
        return "second run"

    assert forked.call_forked_together([steady, crashes_once], "a test", 60) == ["steady",
                                                                                 "second run"]
    assert len(list(runs.iterdir())) == 1
