"""Benchmark: peak memory of a whole bake (``baker.bake``: every stage, the output and the bake
state written) against the size of its lightmap.

Bakes the Cornell room at a large page (4096² by default: 8.4 million texels) and samples the
process's resident memory every 5 ms. Prints the texels, the seconds, the resident memory before
the bake (Python, numpy, Embree, the scene), the peak, and the peak against the float light
page (P, H, W, 3 float64), which the bake needs anyway.

    python benchmarks/bench_memory.py [--page-size 4096] [--rays 4]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import baker  # noqa: E402
from assets.make_scenes import cornell_box  # noqa: E402


def resident_mib() -> float:
    """This process's resident memory now, MiB (``/proc/self/statm``)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2 ** 20


class PeakSampler:
    """The largest resident memory seen, sampled every 5 ms on a thread while in ``with``."""

    def __init__(self):
        self.peak, self._stop = 0.0, threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.peak = max(self.peak, resident_mib())
            time.sleep(0.005)

    def __enter__(self) -> "PeakSampler":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--page-size", type=int, default=4096)
    parser.add_argument("--rays", type=int, default=4)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        scene = cornell_box().save(Path(folder) / "cornell.glb")
        settings = baker.Settings(page_size=args.page_size, rays=args.rays)
        baker.bake(scene, Path(folder) / "small.glb", baker.Settings(page_size=64, rays=4))
        before = resident_mib()  # after a first small bake: libraries loaded, kernels compiled
        start = time.perf_counter()
        with PeakSampler() as sampler:
            result = baker.bake(scene, Path(folder) / "cornell_baked.glb", settings)
        seconds = time.perf_counter() - start
    atlas = result.report["atlas"]
    page = atlas["pages"] * atlas["width"] * atlas["height"] * 3 * 8 / 2 ** 20
    print(f"Cornell room, page {args.page_size}, {args.rays} rays: {result.texels:,} texels, "
          f"{seconds:.1f} s")
    print(f"  resident before the bake {before:,.0f} MiB, peak {sampler.peak:,.0f} MiB")
    print(f"  float light page {page:,.0f} MiB ({atlas['pages']} × {atlas['width']} × "
          f"{atlas['height']} × RGB float64)")
    print(f"  peak / page {sampler.peak / page:.1f}; (peak − before) / page "
          f"{(sampler.peak - before) / page:.1f}")


if __name__ == "__main__":
    main()
