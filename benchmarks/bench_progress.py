"""Benchmark: is the progress bar's ETA true in real time?

Bakes the demo Cornell box (assets/scenes/cornell_box.glb) with the bar drawn into a string,
recording (seconds since the bar's clock started, work done, total, time left shown) at every
update; then, when 10 %, 25 % and 50 % of the bar's final total is done, prints the time left
the bar showed (``Meter.seconds_left``) and tqdm's own estimate (elapsed × (total − done) /
done, what the bar showed before) against the time that was really left until the bar's work
ended (its last update), on the wall clock or (``--clock cpu``) on the process's CPU time,
which another job on the machine does not change. Also the seconds each tenth of the work took,
and each ray stage's seconds per million rays. ``--cold``: numba's
cache in a new temporary folder, so every kernel compiles.

    python benchmarks/bench_progress.py [--method obscurance gi] [--rays 256 16]
                                        [--page-size 1024] [--threads 2] [--cold]

``--rays`` gives each method's rays (paths, for gi) per texel, in the order of ``--method``;
the defaults bake each in about 30–60 s on 2 cores.
"""

from __future__ import annotations

import argparse
import atexit
import os
import io
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
if "--cold" in sys.argv:  # before numba is imported, which reads it then
    os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="bench-progress-numba-")
    atexit.register(shutil.rmtree, os.environ["NUMBA_CACHE_DIR"], True)

import baker  # noqa: E402
import baker.pipeline.full as full  # noqa: E402
import baker.run.progress as progress  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


class Recorded(progress.Bar):
    """The bar drawing into a string, recording at every update (seconds since its clock
    started, done, total, the time left it shows: ``Meter.seconds_left``)."""

    updates: list[tuple[float, int, int, float | None]] = []
    began = 0.0  # progress.CLOCK() when the bar's clock started

    def __init__(self, **options):
        super().__init__(file=io.StringIO(), **options)
        Recorded.began = progress.CLOCK()

    def reset(self, total=None):
        super().reset(total)
        Recorded.began = progress.CLOCK()

    def update(self, n=1):
        super().update(n)
        left = self.meter.seconds_left() if self.meter is not None else None
        Recorded.updates.append((progress.CLOCK() - Recorded.began, self.n, self.total, left))


def report(method: str, rays: int, page_size: int, threads: int, folder: Path) -> None:
    Recorded.updates = []
    settings = baker.Settings(method=method, rays=rays, page_size=page_size, threads=threads)
    start = progress.CLOCK()
    result = baker.bake(ROOT / "assets" / "scenes" / "cornell_box.glb", folder / f"{method}.glb",
                        settings, state=False)
    returned = progress.CLOCK()
    updates = Recorded.updates
    end, final = updates[-1][0], updates[-1][2]
    after = returned - Recorded.began  # when the bake returned, on the bar's clock
    print(f"\n--method {method} --rays {rays} --page-size {page_size}: bake "
          f"{returned - start:.1f} s; the bar's clock {end:.1f} s from its start to its last "
          f"update, {after:.1f} s to the bake's return; total {final:,}")
    report, times = result.report, result.report["stage_seconds"]
    costs = [("trace", report["rays"]), ("direct", report["shadow_rays"]),
             ("gi", report.get("gi", {}).get("rays", 0))]
    print("stage seconds per million rays: " + ", ".join(
        f"{stage} {times.get(stage, 0.0):.1f} s / {rays:,} = "
        f"{1e6 * times.get(stage, 0.0) / rays:.2f}" for stage, rays in costs if rays)
        + "; stages without rays: " + ", ".join(
        f"{stage} {seconds:.1f}" for stage, seconds in times.items()
        if stage not in ("trace", "direct", "gi")))
    print("ETA: the bar's (Meter.seconds_left); tqdm's: elapsed × (total − done) / done; "
          "/left: over the time left to the bar's last update")
    print(f"{'done':>6} {'at s':>7} {'left s':>7} {'ETA s':>7} {'/left':>6} "
          f"{'tqdm s':>7} {'/left':>6}")
    for fraction in (0.10, 0.25, 0.50):
        t, n, total, eta = next(u for u in updates if u[1] >= fraction * final)
        plain = t * (total - n) / n
        print(f"{fraction:>6.0%} {t:>7.1f} {end - t:>7.1f} {eta:>7.1f} {eta / (end - t):>6.2f} "
              f"{plain:>7.1f} {plain / (end - t):>6.2f}")
    tenths = [next(u[0] for u in updates if u[1] >= k / 10 * final) for k in range(11)]
    print("seconds per tenth of the work: " + " ".join(
        f"{b - a:.1f}" for a, b in zip(tenths, tenths[1:])))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--method", nargs="+", default=["obscurance", "gi"])
    parser.add_argument("--rays", nargs="+", type=int, default=[256, 16])
    parser.add_argument("--page-size", type=int, default=1024)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                        help="cpu: the bar and the truth on the process's CPU time (what the "
                             "bake needs of the machine, whatever else runs on it)")
    parser.add_argument("--cold", action="store_true",
                        help="numba's cache in an empty folder: every kernel compiles, as in "
                             "the first bake after an install")
    args = parser.parse_args()
    progress.Bar = Recorded
    if args.clock == "cpu":
        progress.CLOCK = time.process_time
    full.wanted = lambda quiet: True
    with tempfile.TemporaryDirectory() as folder:
        for method, rays in zip(args.method, args.rays):
            report(method, rays, args.page_size, args.threads, Path(folder))


if __name__ == "__main__":
    main()
