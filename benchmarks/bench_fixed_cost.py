"""Benchmark: the fixed cost of a bake — every stage but the tracing — per texel and triangle.

Two scenes, classic AO (``--rho step --d-max 1``) at a 512² page as issue 27 measured them: the
demo Cornell room (36 triangles: the cost per texel shows) and a room of 200 boxes and a sphere
(``assets/many_objects.py``, 98,732 triangles in 202 meshes: the cost per triangle and object
shows). For each, after one bake to load numba's kernels and fill a fresh unwrap cache
(``baker/atlas/unwrap_cache.py``), ``--repeat`` bakes in this process (medians), printing every stage's seconds (the
output encoded and written to a temporary .glb as "write"), µs per texel and per triangle, the share of the
stages other than trace and direct light against the tracing, and the raw embreex rate on the
bake's own rays measured in the same run (``bench_cornell.raw_embree_rate``: nearest hits, and
the occlusion query that ``--rho step`` casts its rays with), the unwrap without the cache
(every mesh charted: the cold cost, what a first bake pays), and the unwrap after an edit of
one mesh (the charts of the instance of median triangle count, a box, gone from the cache: it
is charted again and every instance's charts packed again).
Then the cost of a new process: Python with baker's imports, against Python alone (medians of ``--repeat``).
Last, issue 46's figure: ``baker bake`` run as a new process on each scene (the same settings,
``--rays`` 4 and 16 by default, its bake state written, the unwrap and numba caches warm, a new
output each run so that no run is a rebake), its wall time less the seconds its report gives
the stages that cast the bake's rays: the process start, imports, kernel loads and every other
stage (load, validity, compose, write...), against the goal of ``GOAL`` seconds.

    python benchmarks/bench_fixed_cost.py [--rays 64] [--repeat 3] [--scenes cornell boxes]
        [--process-rays 4 16]
"""

from __future__ import annotations

import argparse
import compileall
import json
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
from baker.atlas.unwrap_cache import entry_path  # noqa: E402
from baker.api import encode_pages, write_output  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.pipeline.full import compute  # noqa: E402
from baker.run.parallel import cores  # noqa: E402
from baker.settings import Settings  # noqa: E402
from benchmarks.bench_cornell import raw_embree_rate, stage_query  # noqa: E402

SCENES = {"cornell": ("Cornell room", cornell_box), "boxes": ("200 boxes + sphere", boxes_and_sphere)}
TRACING = ("trace", "direct", "gi")  # the stages that cast the bake's rays
ROOT = Path(__file__).resolve().parent.parent
GOAL = 0.5  # seconds: issue 46's bound on the process start and the stages other than tracing


def bake_scene(name: str, rays: int, repeat: int) -> None:
    """Bake one scene ``repeat`` times after a warm-up; print the medians per stage."""
    title, make = SCENES[name]
    with tempfile.TemporaryDirectory() as folder:
        scene = load(make().save(Path(folder) / f"{name}.glb"))
    settings = Settings(page_size=512, rays=rays, rho="step", d_max=1.0)
    runs, walls = [], []
    with tempfile.TemporaryDirectory() as folder:
        warm = compute(scene, settings)  # numba's kernels loaded (or compiled), xatlas warmed
        write_output(warm, encode_pages(warm), Path(folder) / f"{name}.glb")
        for run in range(repeat):
            started = time.perf_counter()
            done = compute(scene, settings)
            written = time.perf_counter()
            write_output(done, encode_pages(done), Path(folder) / f"{name}{run}.glb")
            walls.append(time.perf_counter() - started)
            runs.append({**done.stage_seconds, "write": time.perf_counter() - written})
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
        entry_path(chart_name(meshes[edited])).unlink(missing_ok=True)
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
        print(f"  {what:<33} {seconds:6.3f} s ({seconds - bare:+.3f} s)")


def whole_process(name: str, rays: int, repeat: int) -> None:
    """Print the median over ``repeat`` new ``baker bake`` processes on scene ``name`` of their
    wall time, their tracing stages' seconds (``TRACING``, from the report) and the rest, the
    fixed cost, against ``GOAL``; after one run not counted (its caches filled)."""
    title, make = SCENES[name]
    walls, tracing = [], []
    with tempfile.TemporaryDirectory() as folder:
        scene = make().save(Path(folder) / f"{name}.glb")
        for run in range(repeat + 1):
            output, report = Path(folder) / f"out{run}.glb", Path(folder) / f"report{run}.json"
            started = time.perf_counter()
            subprocess.run([sys.executable, "-m", "baker", "bake", str(scene), "-o", str(output),
                            "--rho", "step", "--d-max", "1", "--page-size", "512", "--rays",
                            str(rays), "--quiet", "--report", str(report)],
                           cwd=ROOT, check=True, capture_output=True)
            if run:
                walls.append(time.perf_counter() - started)
                stages = json.loads(report.read_text())["stage_seconds"]
                tracing.append(sum(stages.get(stage, 0.0) for stage in TRACING))
    wall, traced = statistics.median(walls), statistics.median(tracing)
    fixed = statistics.median(w - t for w, t in zip(walls, tracing))
    print(f"  {title}, {rays} rays: wall {wall:.3f} s, tracing {traced:.3f} s, process start "
          f"and stages other than tracing {fixed:.3f} s (goal {GOAL} s: "
          f"{'met' if fixed <= GOAL else f'{fixed / GOAL:.1f}× over'})")


def compile_bytecode() -> None:
    """Write baker's bytecode before timing its processes, as ``pip install .`` does: an
    editable install, or a machine with PYTHONDONTWRITEBYTECODE set (as the one these figures
    were measured on), would otherwise compile 26 of its modules in every new process (0.07 s
    of a 1.1 s bake) where a user's install reads them compiled."""
    compileall.compile_dir(str(ROOT / "baker"), quiet=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=64)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--scenes", nargs="+", choices=sorted(SCENES), default=list(SCENES))
    parser.add_argument("--process-rays", type=int, nargs="*", default=[4, 16],
                        help="ray counts of the whole-process bakes (none: skip them)")
    args = parser.parse_args()
    compile_bytecode()
    with tempfile.TemporaryDirectory() as cache:
        os.environ["BAKER_CACHE_DIR"] = cache  # starts empty: the warm-up bake fills it
        for name in args.scenes:
            bake_scene(name, args.rays, args.repeat)
        start_up(max(args.repeat, 5))
        if args.process_rays:
            print(f"\nwhole process (baker bake, bake state written), medians of {args.repeat}:")
        for name in args.scenes:
            for rays in args.process_rays:
                whole_process(name, rays, args.repeat)


if __name__ == "__main__":
    main()
