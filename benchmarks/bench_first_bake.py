"""Benchmark: a user's first bake after ``pip install``, against the same bake once warm, and
the first rebake.

Makes a fresh virtual environment, installs this checkout into it as a user does
(``pip install <checkout>``: setup.py compiles the kernels into the wheel), then times the
README's first bake (the demo Cornell box, default settings, a new ``baker`` process each
time) ``--repeat`` times: the first run is the one a new user waits for, the others are warm.
Then a room of boxes is baked, one box moved, and ``baker rebake`` run in a new process: the
kernels it compiled are counted (none, when the install compiled them). With ``--unwarmed``
it does the same in a second environment installed with ``BAKER_NO_WARM=1`` (kernels compiled
on first use), for comparison.

    python benchmarks/bench_first_bake.py [--repeat 3] [--unwarmed] [--keep DIR]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def install(venv: Path, warm: bool) -> float:
    """A new venv at ``venv`` with this checkout installed; the install's seconds."""
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    if not warm:
        env["BAKER_NO_WARM"] = "1"
    started = time.perf_counter()
    subprocess.run([str(venv / "bin" / "pip"), "install", "-q", str(ROOT)], check=True, env=env,
                   cwd=venv)
    return time.perf_counter() - started


def bake_seconds(venv: Path, scene: Path, folder: Path) -> tuple[float, float, int]:
    """(wall, CPU) seconds of ``baker bake scene`` as a new process, from outside the checkout,
    and how many kernels it compiled (numba's cache saves, NUMBA_DEBUG_CACHE). CPU (user +
    system, every thread and child) is what a compile adds to; on a shared machine the wall
    time also holds the other work's share of the cores."""
    env = dict(os.environ, NUMBA_DEBUG_CACHE="1")
    env.pop("PYTHONPATH", None)
    env.pop("NUMBA_CACHE_DIR", None)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run([str(venv / "bin" / "baker"), "bake", str(scene), "-o",
                           str(folder / "cornell_box_baked.glb"), "--no-state", "--quiet"],
                          check=True, env=env, cwd=folder, capture_output=True, text=True)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    compiled = sum("data saved" in line for line in done.stdout.splitlines())
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), compiled


def first_rebake(venv: Path, folder: Path) -> tuple[float, int]:
    """(wall seconds, kernels compiled) of the first ``baker rebake`` in a new process after a
    box of a room of 36 moved (``assets/rebake_scenes.py``)."""
    make = ("import sys; sys.path.insert(0, {root!r})\n"
            "from assets.rebake_scenes import box_room, grid_boxes, moved\n"
            "boxes = grid_boxes(6)\n"
            "room = box_room(moved(boxes, boxes[0]['name'], at=(1.0, 1.0)) if {edit} else boxes,"
            " lamp={{'intensity': 20.0, 'radius': 0.1}})\n"
            "room.save({path!r})\n")
    scene, out = folder / "room.glb", folder / "room_baked.glb"
    python, baker = str(venv / "bin" / "python"), str(venv / "bin" / "baker")
    env = dict(os.environ, NUMBA_DEBUG_CACHE="1")
    env.pop("PYTHONPATH", None)
    env.pop("NUMBA_CACHE_DIR", None)
    for edit in (False, True):
        subprocess.run([python, "-c", make.format(root=str(ROOT), edit=edit, path=str(scene))],
                       check=True, env=env, cwd=folder)
        if not edit:
            subprocess.run([baker, "bake", str(scene), "-o", str(out), "--quiet"], check=True,
                           env=env, cwd=folder, capture_output=True)
    started = time.perf_counter()
    done = subprocess.run([baker, "rebake", str(scene), "-o", str(out), "--quiet"], check=True,
                          env=env, cwd=folder, capture_output=True, text=True)
    return (time.perf_counter() - started,
            sum("data saved" in line for line in done.stdout.splitlines()))


def measure(folder: Path, warm: bool, repeat: int) -> None:
    venv = folder / ("venv" if warm else "venv-unwarmed")
    seconds = install(venv, warm)
    subprocess.run([str(venv / "bin" / "python"), "assets/make_scenes.py"], check=True, cwd=ROOT,
                   stdout=subprocess.DEVNULL)  # the README's second step
    scene = ROOT / "assets" / "scenes" / "cornell_box.glb"
    runs = [bake_seconds(venv, scene, folder) for _ in range(repeat)]
    label = "kernels compiled at install" if warm else "kernels compiled on first use"
    print(f"{label}: install {seconds:.1f} s; kernels compiled by each bake: "
          f"{', '.join(str(run[2]) for run in runs)}")
    for i, what in enumerate(("wall", "CPU")):
        first, later = runs[0][i], statistics.median(run[i] for run in runs[1:])
        print(f"  {what}: first bake {first:.2f} s, warm {later:.2f} s (median of "
              f"{len(runs) - 1}): first / warm = {first / later:.2f}")
    seconds, compiled = first_rebake(venv, folder)
    print(f"  first rebake in a new process: {seconds:.2f} s, kernels compiled: {compiled}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="bakes in each venv (≥ 2)")
    parser.add_argument("--unwarmed", action="store_true",
                        help="also install with BAKER_NO_WARM=1 and compare")
    parser.add_argument("--keep", type=Path, help="make the venvs here and keep them")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as temporary:
        folder = args.keep or Path(temporary)
        folder.mkdir(parents=True, exist_ok=True)
        measure(folder, True, max(args.repeat, 2))
        if args.unwarmed:
            measure(folder, False, max(args.repeat, 2))


if __name__ == "__main__":
    main()
