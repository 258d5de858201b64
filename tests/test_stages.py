"""The runner of a bake's stages (``run.stages``): order, lines, times, the work abandoned."""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace

import pytest

from baker.run.progress import StageLines
from baker.run.stages import Stage, run_stages


@dataclass(frozen=True)
class _Work:
    done: tuple[str, ...] = ()
    times: dict[str, float] = field(default_factory=dict)
    counted: int = 0
    abandoned: list[str] = field(default_factory=list)

    def abandon(self) -> None:
        self.abandoned.append(self.done[-1] if self.done else "")


def _did(name):
    return lambda w: replace(w, done=w.done + (name,))


def _counts(w, steps):
    steps.expect(3)
    steps.advance(3)
    return replace(w, done=w.done + ("counts",), counted=steps.done)


def test_stages_run_in_order_each_in_its_line_and_timed_under_its_key(capsys):
    stages = (Stage("first", _did("first"), "one"),
              Stage("skipped", _did("skipped"), "two", when=lambda w: False),
              Stage("quiet step", _did("quiet step"), "one", shown=False),
              Stage("counts", _counts, unit="things", detail=lambda w: f"{len(w.done)} before"))
    work = run_stages(stages, _Work(), StageLines(True))
    assert work.done == ("first", "quiet step", "counts") and work.counted == 3
    assert set(work.times) == {"one"} and work.times["one"] >= 0  # a stage without a key: none
    lines = capsys.readouterr().err.splitlines()
    assert [re.sub(r" \d+\.\d\d s$", "", line) for line in lines] == [
        "baker: first", "baker: counts (2 before)"]
    assert not work.abandoned


def test_a_failing_stage_abandons_the_work_and_runs_nothing_after(capsys):
    def fails(w):
        raise KeyboardInterrupt

    stages = (Stage("first", _did("first")), Stage("fails", fails), Stage("never", _did("never")))
    abandoned: list[str] = []
    with pytest.raises(KeyboardInterrupt):
        run_stages(stages, _Work(abandoned=abandoned), StageLines(True))
    assert abandoned == ["first"]  # the work as the failing stage was given it
    assert [line.split(" ")[1] for line in capsys.readouterr().err.splitlines()] == ["first"]


def test_a_stage_line_prints_the_seconds_its_report_key_gets(capsys, monkeypatch):
    """One clock for both: a stage's line and its key of ``stage_seconds`` agree to the line's
    two decimals even when the machine stalls between the stage's end and its line's (here
    a slow stderr: each write takes 0.05 s), as it did when each had its own clock."""
    import time

    write = StageLines._write

    def slow(text):
        time.sleep(0.05)
        write(text)

    monkeypatch.setattr(StageLines, "_write", staticmethod(slow))
    stages = (Stage("first", _did("first"), "one"), Stage("second", _did("second"), "two"))
    work = run_stages(stages, _Work(), StageLines(True))
    printed = [float(re.search(r" (\d+\.\d\d) s$", line).group(1))
               for line in capsys.readouterr().err.splitlines()]
    assert printed == [round(work.times["one"], 2), round(work.times["two"], 2)]
    assert work.times["one"] < 0.04  # the stage's own time, no line's write in it
