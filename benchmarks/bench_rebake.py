"""Benchmark: incremental rebake after moving one small box in a room of many.

A closed room with ``--boxes`` crates on the floor (assets/rebake_scenes.py), baked at one
``--page-size``² page; then one small crate moves across the room and the scene is baked again
incrementally from the bake state, and fully, for comparison. Prints the dirty-texel fraction,
the rebake's time over the full bake's, the stage times of both, and checks that the two outputs
(glb and bake state) are the same bytes.

Each is timed ``--repeat`` times (the rebake from a fresh copy of the first bake's state each
time) and the medians compared: on a shared machine one run can be 30 % off.

    python benchmarks/bench_rebake.py [--boxes 60] [--page-size 1024] [--rays 64] [--d-max 1.0]
                                      [--lamp] [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import baker  # noqa: E402
from assets.rebake_scenes import box_room, grid_boxes, moved  # noqa: E402
from baker.rebake.state import default_path  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--boxes", type=int, default=60)
    parser.add_argument("--room", type=float, nargs=3, default=(12.0, 3.0, 12.0))
    parser.add_argument("--page-size", type=int, default=1024)
    parser.add_argument("--rays", type=int, default=64)
    parser.add_argument("--d-max", type=float, default=None,
                        help="obscurance distance (default: the baker's, 0.2 × the diagonal)")
    parser.add_argument("--lamp", action="store_true", help="add a soft point light")
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--repeat", type=int, default=5,
                        help="rebakes and full bakes timed; their medians are compared")
    args = parser.parse_args()
    room = tuple(args.room)
    boxes = grid_boxes(args.boxes, room=room, size=0.4)
    small = min(boxes, key=lambda b: b["size"][0] * b["size"][1] * b["size"][2])
    lamp = {"at": (0.0, room[1] - 0.3, 0.0), "intensity": 20.0, "radius": 0.1} if args.lamp else None
    settings = baker.Settings(page_size=args.page_size, rays=args.rays, d_max=args.d_max,
                              threads=args.threads)
    x, z = small["at"]
    edit = moved(boxes, small["name"], at=(-x * 0.9, -z * 0.9))  # across the room, still on the floor
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        before = box_room(boxes, room=room, lamp=lamp).save(folder / "before.glb")
        after = box_room(edit, room=room, lamp=lamp).save(folder / "after.glb")
        t = time.perf_counter()
        first = baker.bake(before, folder / "incremental.glb", settings)
        full_before = time.perf_counter() - t
        state = default_path(folder / "incremental.glb")
        shutil.copyfile(state, folder / "first.bake")
        rebakes, fulls = [], []
        for _ in range(max(1, args.repeat)):
            shutil.copyfile(folder / "first.bake", state)
            os.sync()  # the copy written out, as a state written at the last bake would be
            t = time.perf_counter()
            again = baker.bake(after, folder / "incremental.glb", settings, incremental=True)
            rebakes.append(time.perf_counter() - t)
            os.sync()
            t = time.perf_counter()
            full = baker.bake(after, folder / "full.glb", settings)
            fulls.append(time.perf_counter() - t)
        same = ((folder / "incremental.glb").read_bytes() == (folder / "full.glb").read_bytes()
                and state.read_bytes() == default_path(folder / "full.glb").read_bytes())
        state_mb = default_path(folder / "full.glb").stat().st_size / 1e6
    rebake, full_after = statistics.median(rebakes), statistics.median(fulls)
    info = again.rebake
    print(f"room {room}, {args.boxes} boxes, page {args.page_size}², {args.rays} rays/texel, "
          f"d_max {first.settings.d_max:.3g}, {first.texels:,} texels; moved {small['name']} "
          f"(size {', '.join(f'{v:.2f}' for v in small['size'])}) from ({x:.2f}, {z:.2f})")
    if not info["incremental"]:
        print(f"full bake instead of a rebake: {info['full_bake_reason']}")
        return
    print(f"dirty texels: {info['dirty_texels']:,} of {info['texels']:,} = "
          f"{100 * info['dirty_fraction']:.2f} % ({info['dirty_by_reason']}); "
          f"{info['rays']:,} rays re-cast, {info['test_rays']:,} test rays")
    print(f"full bake {full_before:.2f} s (edited scene, median of {len(fulls)}: "
          f"{full_after:.2f} s, {min(fulls):.2f}–{max(fulls):.2f}), rebake median {rebake:.3f} s "
          f"({min(rebakes):.3f}–{max(rebakes):.3f}) = {100 * rebake / full_after:.1f} % of the "
          f"full bake; state file {state_mb:.1f} MB; identical bytes: {same}")
    print_stage_seconds({"full": full, "rebake": again})


def print_stage_seconds(results: dict) -> None:
    """One line per named ``baker.BakeResult``: the seconds of each stage of that bake."""
    for name, result in results.items():
        times = result.report["stage_seconds"]
        print(f"  {name:8s} " + ", ".join(f"{k} {v:.2f}" for k, v in times.items()))


if __name__ == "__main__":
    main()
