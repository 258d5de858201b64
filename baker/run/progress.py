"""A bake's progress: one line per stage with its time, and a bar of its rays on a terminal;
nothing with ``quiet``.

``StageLines`` prints ``baker: <stage> <seconds> s`` to stderr as each stage ends, wherever
stderr goes (a pipeline's or CI's log gets one line per stage); on a terminal the line is shown
while the stage runs (``baker: unwrap …``) and completed with the time when it ends. A stage
that counts its own steps (``Steps``: the unwrap its triangles charted, the post-process its
passes over the pages' texels, the write its texels encoded and triangles written) has them
drawn in the line's place, with the time left at its pace so far, once it has run 2 s.

The bar counts rays, the work there is: a texel of a 256-path GI bake costs a hundred times one
of a 4-ray obscurance bake. Each stage (obscurance, direct light, GI) is registered with its
texels and an estimate of the rays a texel casts (``Meter.stage``); as it reports the texels
done and the rays they cast, its remaining rays are re-estimated from its mean so far, and the
bar's total follows (GI's paths end by Russian roulette: their length is known only by casting
them). An adaptive round (``--target-error``) announces its rays before it starts, so the
bar does not stand at its total while the rounds after the first cast most of the rays; the
rounds after it are not known until it ends. tqdm draws it, only on a terminal, not in CI (a
log would get every redraw).

Its time left is the Meter's (``Meter.seconds_left``), not tqdm's elapsed × to do / done: a
ray's cost differs by stage (a GI path's ray, shaded in numpy, costs 3.6–4.6 times an
obscurance ray in its numba kernel, benchmarks/bench_progress.py), so each stage's remaining rays are priced at that stage's
own seconds per ray so far — the wall time between reports, each interval put to the stage that
reports at its end (texel set-up between parts goes to the stage that follows it) — and a
stage not yet begun at the mean of those that have. The clock leaves out the seconds numba
spends compiling kernels (``compile_clock``: a first bake's compile is paid once; counted,
it made a cold GI bake's ETA 1.15–2 times the time left at 10–50 % of its rays).
"""

from __future__ import annotations

import functools
import os
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Iterator

if TYPE_CHECKING:  # imported where a bar is drawn: 0.06 s of every command's start else
    from tqdm import tqdm

_DEFAULT_SIZE = (80, 24)  # columns and rows of a terminal that gives no size
CLOCK: Callable[[], float] = time.perf_counter  # the Meter's clock, in seconds (wall time)


def wanted(quiet: bool) -> bool:
    """Whether to draw a bar: not when asked to be quiet, not in CI, only on a terminal."""
    return not quiet and not os.environ.get("CI") and sys.stderr.isatty()


@dataclass
class _Stage:
    """One stage's texels, its first estimate of rays per texel, what it reported done, the
    rays its adaptive rounds announced and have not cast yet, and the seconds (compile
    excluded) put to it."""

    texels: int
    per_texel: float
    texels_done: int = 0
    rays_done: int = 0
    coming: int = 0
    seconds: float = 0.0

    def expected(self) -> float:
        """The stage's rays in all: those cast, those its rounds announced, and the texels
        not done at the mean so far per texel (at the first estimate before any texel is
        done). Without the announced rays an adaptive bake's bar stood at its total, no time
        left, while the rounds after the first cast most of its rays."""
        if self.texels_done == 0:
            return self.texels * self.per_texel
        rest = max(0, self.texels - self.texels_done)
        return self.rays_done + self.coming + rest * self.rays_done / self.texels_done


class Meter:
    """The work of a bake's stages, in rays, drawn as one bar (``bar``: a tqdm, or None).

    ``clock()``: seconds (by default ``CLOCK``); ``compiled()``: the seconds spent compiling
    so far, left out of the stages' times (none by default)."""

    def __init__(self, bar: tqdm | None = None, clock: Callable[[], float] | None = None,
                 compiled: Callable[[], float] = lambda: 0.0):
        self._bar = bar
        self._stages: list[_Stage] = []
        self._lock = threading.RLock()  # the stages report from their worker threads
        self._started = False
        self._clock, self._compiled = clock or (lambda: CLOCK()), compiled
        self._last: float | None = None  # the clock, compile excluded, at the last report

    def stage(self, texels: int, rays_per_texel: float) -> Callable[..., None]:
        """Register a stage of ``texels`` texels casting about ``rays_per_texel`` rays each;
        return its ``report(texels, rays, coming=None)``: that many more texels done, casting
        that many rays (the time since the last report, or since ``start``, is the stage's);
        ``coming``: the rays an adaptive round about to start will cast (each report's rays
        count against them until the next round says its own)."""
        stage = _Stage(int(texels), float(rays_per_texel))
        with self._lock:
            self._stages.append(stage)
            self._show(0)

        def report(texels_done: int, rays: int, coming: int | None = None) -> None:
            with self._lock:
                now = self._now()
                if self._last is not None:
                    stage.seconds += max(0.0, now - self._last)
                self._last = now
                stage.texels_done += int(texels_done)
                stage.rays_done += int(rays)
                stage.coming = max(0, stage.coming - int(rays)) if coming is None else int(coming)
                self._show(int(rays))

        return report

    def total(self) -> int:
        """The rays of every stage registered: cast, and estimated to come."""
        return round(sum(stage.expected() for stage in self._stages))

    def done(self) -> int:
        """The rays the stages reported cast."""
        return sum(stage.rays_done for stage in self._stages)

    def seconds_left(self) -> float | None:
        """Seconds until the stages' rays are all cast: each stage's rays to come at its own
        seconds per ray so far, a stage with none cast yet at the mean of the others' (None
        before any time was put to a stage)."""
        with self._lock:
            begun = [stage for stage in self._stages if stage.rays_done]
            seconds = sum(stage.seconds for stage in begun)
            if seconds <= 0:
                return None
            mean = seconds / sum(stage.rays_done for stage in begun)
            return sum(max(0.0, stage.expected() - stage.rays_done)
                       * (stage.seconds / stage.rays_done if stage.rays_done else mean)
                       for stage in self._stages)

    def start(self) -> None:
        """The first rays are about to be cast: the bar's clock (its rate, its ETA) starts now
        (the first time only), not with the texels' set-up before them."""
        with self._lock:
            if not self._started:
                if self._bar is not None:
                    self._bar.reset(self._bar.total)
                self._last = self._now()
            self._started = True

    def _now(self) -> float:
        return self._clock() - self._compiled()

    def _show(self, rays: int) -> None:
        if self._bar is not None:
            self._bar.total = max(self.total(), self.done())
            self._bar.update(rays)


@functools.cache
def bar_class() -> type:
    """The rays' bar: tqdm showing its ``meter``'s time left (``Meter.seconds_left``) in place
    of its own. Made at the first bar drawn: importing tqdm (0.06 s, most of it its version's
    lookup in the installed packages' metadata) is no part of a bake in a pipeline or of
    ``baker --help``."""
    from tqdm import tqdm

    class Bar(tqdm):
        FORMAT = "{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}<{left}, {rate_fmt}]"
        meter: Meter | None = None

        @property
        def format_dict(self) -> dict:
            values = super().format_dict
            left = self.meter.seconds_left() if self.meter is not None else None
            values["left"] = "?" if left is None else self.format_interval(left)
            return values

    return Bar


@contextmanager
def bar(label: str, show: bool) -> Iterator[Meter]:
    """Yield a ``Meter`` for the stages to register with; drawn as a bar when ``show``."""
    if not show:
        yield Meter()
        return
    from baker.run.compile_clock import CompileClock  # numba: not for ``import baker.cli``

    sized, drawing = _has_size(), bar_class()
    with CompileClock() as compiling, drawing(
            total=0, desc=label, unit="ray", unit_scale=True, leave=False, smoothing=0,
            bar_format=drawing.FORMAT, dynamic_ncols=sized,
            ncols=None if sized else _DEFAULT_SIZE[0],
            nrows=None if sized else _DEFAULT_SIZE[1]) as drawn:
        drawn.meter = Meter(drawn, compiled=lambda: compiling.seconds)
        yield drawn.meter


def _has_size() -> bool:
    """Whether stderr's terminal gives its size. One made by ``script``, ``docker run -t`` or a
    CI runner often says 0 × 0, where tqdm draws nothing (a bar below the screen's last row
    is hidden): such a terminal gets ``_DEFAULT_SIZE``."""
    try:
        size = os.get_terminal_size(sys.stderr.fileno())
    except (OSError, ValueError):
        return False
    return size.columns > 0 and size.lines > 0


class Steps:
    """A stage's work in steps of its own (triangles charted, texels cleaned, bytes written):
    the stage announces them (``expect``) and counts them done (``advance``, ``done_so_far``),
    from any thread. Drawn (``draw``) as a bar with the time left on a terminal once the
    stage has run ``DELAY`` seconds: a shorter stage shows only its line. The time left is the
    steps to come at the stage's mean seconds per step so far (tqdm's rate, unsmoothed)."""

    DELAY = 2.0  # seconds a stage runs before its bar is drawn
    FORMAT = "{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} {unit} [{elapsed}<{remaining}]"

    def __init__(self, name: str = "", unit: str = "", draw: bool = False):
        self._name, self._unit, self._draw = name, unit, draw
        self._bar: tqdm | None = None  # made at the first ``expect``: a stage that never
        self.total = 0  # counts (the rays' own bar draws it) has none beside its other bars
        self.done = 0
        self._lock = threading.Lock()

    def expect(self, steps: int) -> None:
        """``steps`` more steps to do."""
        with self._lock:
            self.total += int(steps)
            if self._draw and self._bar is None:
                from tqdm import tqdm

                sized = _has_size()
                self._bar = tqdm(total=self.total, initial=self.done,
                                 desc=f"baker: {self._name}",
                                 unit=self._unit, unit_scale=True, leave=False, smoothing=0,
                                 delay=self.DELAY, bar_format=self.FORMAT, dynamic_ncols=sized,
                                 ncols=None if sized else _DEFAULT_SIZE[0],
                                 nrows=None if sized else _DEFAULT_SIZE[1])
            if self._bar is not None:
                self._bar.total = self.total

    def advance(self, steps: int = 1) -> None:
        """``steps`` more steps done."""
        with self._lock:
            self.done += int(steps)
            if self._bar is not None:
                self._bar.update(int(steps))

    def done_so_far(self, steps: int) -> None:
        """``steps`` done in all (a count polled from elsewhere, e.g. forked children)."""
        with self._lock:
            change = int(steps) - self.done
        if change > 0:
            self.advance(change)

    def close(self) -> None:
        """Take the bar off the terminal (a stage's line follows)."""
        if self._bar is not None:
            self._bar.close()


class StageLines:
    """One line per stage of a bake, with its wall time, to stderr (none when not ``show``)."""

    def __init__(self, show: bool):
        self.show = show
        self._live = show and wanted(False)  # a terminal: the line shows while the stage runs

    @contextmanager
    def stage(self, name: str, unit: str = "", clock=None) -> Iterator[Steps]:
        """Print ``baker: NAME S s`` when the block ends (S: its wall seconds, or the
        ``seconds`` of ``clock``, the block's own timer, ended inside it: the report's figure,
        not a second clock's that a busy machine can set apart); on a terminal ``baker: NAME
        …`` from its start, and the bar of the ``Steps`` yielded (counted in ``unit``) once it
        has run ``Steps.DELAY``. A block ended by an error prints no time (on a terminal its
        line is ended, so that the error starts a line of its own)."""
        if not self.show:
            yield Steps()
            return
        if self._live:
            self._write(f"baker: {name} …")
        started = time.perf_counter()
        steps = Steps(name, unit, draw=self._live)
        try:
            yield steps
        except BaseException:
            steps.close()
            if self._live:
                self._write("\n")
            raise
        steps.close()
        seconds = time.perf_counter() - started if clock is None else clock.seconds
        self._write(("\r\x1b[K" if self._live else "") + f"baker: {name} {seconds:.2f} s\n")

    @staticmethod
    def _write(text: str) -> None:
        sys.stderr.write(text)
        sys.stderr.flush()
