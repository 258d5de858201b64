"""Benchmark: the fixed cost of a bake — every stage but the tracing — per texel and triangle.

Two scenes, classic AO (``--rho step --d-max 1``) at a 512² page as issue 27 measured them: the
demo Cornell room (36 triangles: the cost per texel shows) and a room of 200 boxes and a sphere
(``assets/many_objects.py``, 98,732 triangles in 202 meshes: the cost per triangle and object
shows). For each, after one bake to load numba's kernels and fill a fresh unwrap cache
(``baker/atlas/unwrap_cache.py``), ``--repeat`` bakes in this process (medians), printing every stage's seconds, µs per texel and per triangle, the share of the
stages other than trace and direct light against the tracing, and the raw embreex rate on the
bake's own rays measured in the same run (``bench_cornell.raw_embree_rate``: nearest hits, and
the occlusion query that ``--rho step`` casts its rays with), the unwrap without the cache
(every mesh charted: the cold cost, what a first bake pays), and the unwrap after an edit of
one mesh (the charts of the instance of median triangle count, a box, gone from the cache: it
is charted again and every instance's charts packed again).
Then the cost of a new process: Python with baker's imports, against Python alone (medians of ``--repeat``).

    python benchmarks/bench_fixed_cost.py [--rays 64] [--repeat 3] [--scenes cornell boxes]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.make_scenes import cornell_box  # noqa: E402
from assets.many_objects import boxes_and_sphere  # noqa: E402
from baker.atlas.charts import chart_name  # noqa: E402
from baker.atlas.unwrap import baked_instances, frame_meshes, unwrap  # noqa: E402
from baker.atlas.unwrap_cache import entries  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.pipeline.full import compute  # noqa: E402
from baker.run.parallel import cores  # noqa: E402
from baker.settings import Settings  # noqa: E402
from benchmarks.bench_cornell import raw_embree_rate, stage_query  # noqa: E402

SCENES = {"cornell": ("Cornell room", cornell_box), "boxes": ("200 boxes + sphere", boxes_and_sphere)}
TRACING = ("trace", "direct", "gi")  # the stages that cast the bake's rays
ROOT = Path(__file__).resolve().parent.parent


def bake_scene(name: str, rays: int, repeat: int) -> None:
    """Bake one scene ``repeat`` times after a warm-up; print the medians per stage."""
    title, make = SCENES[name]
    with tempfile.TemporaryDirectory() as folder:
        scene = load(make().save(Path(folder) / f"{name}.glb"))
    settings = Settings(page_size=512, rays=rays, rho="step", d_max=1.0)
    compute(scene, settings)  # numba's kernels loaded (or compiled), xatlas warmed
    runs, walls = [], []
    for _ in range(repeat):
        started = time.perf_counter()
        done = compute(scene, settings)
        walls.append(time.perf_counter() - started)
        runs.append(done.stage_seconds)
    texels, triangles = len(done.texels), len(done.world.triangles)
    threads = done.settings.threads or cores()
    nearest, raw_rays = raw_embree_rate(done, threads)
    query = stage_query(done)
    raw = raw_embree_rate(done, threads, query)[0] if query != "INTERSECT" else nearest
    print(f"\n{title}: {triangles:,} triangles in {len(done.atlas.instances)} baked instances, "
          f"{texels:,} texels on {done.atlas.page_count} page(s) of {done.atlas.width}², "
          f"{rays} rays/texel, {threads} thread(s); medians of {repeat}")
    print(f"  {'stage':<10}{'s':>8}{'µs/texel':>10}{'µs/triangle':>13}")
    stages = {stage: statistics.median(run.get(stage, 0.0) for run in runs)
              for stage in runs[0]}
    for stage, seconds in stages.items():
        print(f"  {stage:<10}{seconds:8.3f}{seconds / texels * 1e6:10.3f}"
              f"{seconds / triangles * 1e6:13.3f}")
    tracing = sum(s for stage, s in stages.items() if stage in TRACING)
    fixed = sum(s for stage, s in stages.items() if stage not in TRACING)
    print(f"  wall {statistics.median(walls):.3f} s; fixed stages {fixed:.3f} s against "
          f"tracing {tracing:.3f} s ({fixed / tracing:.2f}×)")
    rate = done.terms.rays / stages['trace']
    print(f"  obscurance rays {rate / 1e6:.2f} M/s end to end; raw embreex on {raw_rays:,} of "
          f"the same rays: {nearest / 1e6:.2f} M/s nearest hits ({rate / nearest:.0%}), "
          f"{raw / 1e6:.2f} M/s with the stage's query, {query} ({rate / raw:.0%})")
    print(f"  unwrap cold (no cache, every mesh charted): {cold_unwrap(done, repeat):.3f} s; "
          f"one mesh edited: {edited_unwrap(done, repeat):.3f} s; "
          f"from the cache (above): {stages['unwrap']:.3f} s")


def cold_unwrap(done, repeat: int) -> float:
    """Median seconds of the bake's unwrap with the cache off."""
    cache, os.environ["BAKER_CACHE_DIR"] = os.environ["BAKER_CACHE_DIR"], "off"
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        unwrap(done.scene, done.world, done.settings)
        times.append(time.perf_counter() - started)
    os.environ["BAKER_CACHE_DIR"] = cache
    return statistics.median(times)


def edited_unwrap(done, repeat: int) -> float:
    """Median seconds of the bake's unwrap with one mesh charted again: the charts of the
    baked instance of median triangle count removed from the cache before each run."""
    meshes = frame_meshes(done.scene, done.world, baked_instances(done.scene))
    edited = sorted(range(len(meshes)), key=lambda m: (len(meshes[m][1]), m))[len(meshes) // 2]
    times = []
    for _ in range(repeat):
        (entries() / f"{chart_name(meshes[edited])}.npz").unlink(missing_ok=True)
        started = time.perf_counter()
        unwrap(done.scene, done.world, done.settings)
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def seconds_of(command: list[str], repeat: int) -> float:
    """Median wall time of running ``command`` from the repository root."""
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        subprocess.run(command, cwd=ROOT, check=True, capture_output=True)
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def start_up(repeat: int) -> None:
    """Print what a new process costs before a bake starts: Python, then with baker imported."""
    bare = seconds_of([sys.executable, "-c", "pass"], repeat)
    print(f"\nprocess start, medians of {repeat}:")
    print(f"  python alone                      {bare:6.3f} s")
    for what, code in (("import baker (the API)", "import baker"),
                       ("import baker.cli.main (the CLI)", "import baker.cli.main"),
                       ("baker --help", "import sys; sys.argv = ['baker', '--help']\n"
                        "from baker.cli.main import main\ntry: main()\nexcept SystemExit: pass")):
        seconds = seconds_of([sys.executable, "-c", code], repeat)
        print(f"  {what:<33} {seconds:6.3f} s (+{seconds - bare:.3f} s)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=64)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--scenes", nargs="+", choices=sorted(SCENES), default=list(SCENES))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as cache:
        os.environ["BAKER_CACHE_DIR"] = cache  # starts empty: the warm-up bake fills it
        for name in args.scenes:
            bake_scene(name, args.rays, args.repeat)
    start_up(max(args.repeat, 5))


if __name__ == "__main__":
    main()
