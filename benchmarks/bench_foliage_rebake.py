"""Benchmark: incremental rebake in --foliage approx mode against a full bake of the edit.

A generated tree (assets/foliage_scenes.tree_and_boxes: a trunk, a crown of ``--leaves``
alpha-cut leaf quads, grass, a box beside the crown and one far from it, a point light) is
baked once in ``--foliage approx`` mode; then each edit — the tree moved (crown and trunk), the
near box moved, the far box moved — is rebaked from that bake's state and baked fully. Prints,
per edit, the dirty-texel fraction, the rebake's time over the full bake's (medians of
``--repeat``) and whether the two outputs (glb and bake state) are the same bytes.

    python benchmarks/bench_foliage_rebake.py [--leaves 20000] [--page-size 1024] [--rays 64]
                                              [--repeat 3] [--threads 2]
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import baker  # noqa: E402
from assets.foliage_scenes import tree_and_boxes  # noqa: E402
from baker.rebake.state import default_path  # noqa: E402

EDITS = {
    "tree moved": {"crown": (0.4, 0.0, 0.2), "trunk": (0.4, 0.0, 0.2)},
    "near box moved": {"near": (2.3, 0.25, 0.3)},
    "far box moved": {"far": (5.0, 0.25, -5.0)},
}


def _timed(call) -> tuple[float, object]:
    t = time.perf_counter()
    out = call()
    return time.perf_counter() - t, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--leaves", type=int, default=20_000)
    parser.add_argument("--page-size", type=int, default=1024)
    parser.add_argument("--rays", type=int, default=64)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    settings = baker.Settings(page_size=args.page_size, rays=args.rays, threads=args.threads,
                              foliage="approx", shadow_rays=4)
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        scene = {"base": {}, **EDITS}
        paths = {name: tree_and_boxes(moves, leaf_count=args.leaves).save(
            folder / f"{name.replace(' ', '_')}.glb") for name, moves in scene.items()}
        first_seconds, first = _timed(lambda: baker.bake(paths["base"], folder / "out.glb",
                                                         settings))
        state = default_path(folder / "out.glb")
        shutil.copyfile(state, folder / "base.bake")
        print(f"{args.leaves:,} leaves, page {args.page_size}², {args.rays} rays/texel, "
              f"{first.texels:,} texels; first full bake {first_seconds:.2f} s (unwrap and "
              f"numba compile included)")
        for name in EDITS:
            rebakes, fulls = [], []
            for _ in range(max(1, args.repeat)):
                shutil.copyfile(folder / "base.bake", state)
                seconds, again = _timed(lambda: baker.bake(paths[name], folder / "out.glb",
                                                           settings, incremental=True))
                rebakes.append(seconds)
                seconds, _ = _timed(lambda: baker.bake(paths[name], folder / "full.glb",
                                                       settings))
                fulls.append(seconds)
            info = again.rebake
            same = ((folder / "out.glb").read_bytes() == (folder / "full.glb").read_bytes()
                    and state.read_bytes() == default_path(folder / "full.glb").read_bytes())
            rebake, full = statistics.median(rebakes), statistics.median(fulls)
            if not info["incremental"]:
                print(f"{name}: full bake instead of a rebake ({info['full_bake_reason']}): "
                      f"{rebake:.2f} s, full bake {full:.2f} s = {100 * rebake / full:.0f} %; "
                      f"identical bytes: {same}")
                continue
            print(f"{name}: dirty {100 * info['dirty_fraction']:.1f} % "
                  f"({info['dirty_by_reason']}), {info['rays']:,} rays; rebake {rebake:.2f} s, "
                  f"full bake {full:.2f} s = {100 * rebake / full:.0f} %; "
                  f"identical bytes: {same}")


if __name__ == "__main__":
    main()
