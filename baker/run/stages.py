"""A bake as a named list of stages, run in order by one runner that times, logs and reports each.

A ``Stage`` names a step of the bake and the function that does it: it takes the work so far
(a frozen dataclass of what was asked and what the stages before it made) and returns it with
what it made. ``run_stages`` runs each in turn inside its stage line (``progress.StageLines``:
``baker: unwrap 0.42 s``), with the ``Steps`` it counts (triangles charted, texels cleaned)
and its wall time added to its key of the report's ``stage_seconds`` (``timed``). A stage whose
time goes to several keys (a part's validity, trace and direct light) times them itself. The
list reads as the bake's outline; the plumbing is here once, not around every stage.
"""

from __future__ import annotations

import time
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Callable, Generic, Protocol, Sequence, TypeVar

from baker.run.interruptible import check_interrupted
from baker.run.progress import StageLines, Steps


class timed:
    """Adds the wall time of a ``with`` block to ``times[name]``, in seconds, and keeps it as
    ``seconds`` (a stage's line prints it: one clock for the line and the report). A block
    ended by an error adds nothing. An interrupt some code swallowed is raised again as the
    block starts and ends (``run.interruptible``)."""

    def __init__(self, times: dict[str, float], name: str):
        self._times, self._name = times, name
        self.seconds = 0.0

    def __enter__(self) -> "timed":
        check_interrupted()
        self._start = time.perf_counter()
        return self

    def __exit__(self, kind, *_) -> None:
        if kind is None:
            self.seconds = time.perf_counter() - self._start
            self._times[self._name] = self._times.get(self._name, 0.0) + self.seconds
            check_interrupted()


class Work(Protocol):
    """What the stages hand on: ``times``, the seconds of each key of ``stage_seconds`` so far;
    ``abandon()`` lets go of what the work holds outside memory (spilled rows) when a stage
    fails."""

    times: dict[str, float]

    def abandon(self) -> None: ...


W = TypeVar("W", bound=Work)


@dataclass(frozen=True)
class Stage(Generic[W]):
    """One step of a bake.

    ``name``: what its stage line says (``detail``, if any, adds a word of the work in
    brackets: ``texels and rays (11,934 texels)``); ``run(work)``: the work with what the
    stage made, or ``run(work, steps)`` for a stage that counts its own progress in ``unit``
    (``progress.Steps``: triangles charted, texels cleaned); ``seconds``: the
    ``stage_seconds`` key its wall time adds to (None: the stage times its own keys); ``when``:
    whether it runs for this work (None: always); ``shown``: False for a step with no line of
    its own (a check between two stages)."""

    name: str
    run: Callable[..., W]
    seconds: str | None = None
    unit: str = ""
    when: Callable[[W], bool] | None = None
    detail: Callable[[W], str] | None = None
    shown: bool = True


def run_stages(stages: Sequence[Stage[W]], work: W, lines: StageLines) -> W:
    """Run each of ``stages`` that applies (``Stage.when``) on ``work`` in order, each inside
    its line of ``lines`` and timed into ``work.times``; return the work the last one made. A
    stage that fails (an error, Ctrl-C) abandons the work before the exception goes on."""
    for stage in stages:
        if stage.when is not None and not stage.when(work):
            continue
        line = f"{stage.name} ({stage.detail(work)})" if stage.detail else stage.name
        clock = None if stage.seconds is None else timed(work.times, stage.seconds)
        try:
            with (lines.stage(line, stage.unit, clock) if stage.shown
                  else nullcontext(Steps())) as steps, clock or nullcontext():
                work = stage.run(work, steps) if stage.unit else stage.run(work)
        except BaseException:
            work.abandon()
            raise
    return work
