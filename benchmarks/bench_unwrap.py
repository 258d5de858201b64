"""Benchmark: where xatlas's time goes in an unwrap — charting against packing, per option.

On the room of 200 boxes and a sphere (``assets/many_objects.py``, 98,732 triangles in 202
meshes, a 512² page as ``bench_fixed_cost.py``) and, with ``--million``, the 1M-triangle terrain
of ``bench_million.py`` (default settings), each xatlas run in a forked child as a bake runs it
(``run/forked.py``), timed inside the child (xatlas's call alone):

- whole: xatlas charting and packing every instance in one run (baker before per-mesh charts);
- charts: each mesh charted alone (``unwrap._chart``: charting and a cheap placing), summed
  and the slowest mesh;
- pack: every instance's charts packed together as UV meshes (``unwrap._pack``), at the size
  xatlas picks (resolution 0) and into pages;
- the packing again with one option changed from baker's (padding 0, bilinear off,
  bruteForce, blockAlign, rotate_charts off), and the whole run at max_iterations 0 and 2.

With ``--times``: what a bake's unwrap (``unwrap.unwrap``, default derived density) costs
cold (empty cache), after an edit (the mesh of (lower) median triangle count stretched 10 % along x,
which changes the derived density: the cache holds the scene before the edit) and from the
cache, medians of ``--repeat``, with the atlas's pages, utilisation (texels the charts cover
over the pages') and stretch (triangles' texel area over world area × density², area-weighted
mean and 5–95 % range). ``--against DIR`` first runs the same in a child with DIR's baker
(e.g. /work/main), scene by scene, interleaved: an A/B in one run.

    python benchmarks/bench_unwrap.py [--million] [--times [--repeat 3] [--against DIR]]
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CODE = os.environ.get("BENCH_UNWRAP_CODE", str(ROOT))  # whose baker (``--against``)
sys.path.insert(0, str(ROOT))
sys.path.insert(0, CODE)

import xatlas  # noqa: E402

from assets.many_objects import boxes_and_sphere  # noqa: E402
from baker.atlas import unwrap  # noqa: E402
from baker.geometry.world import build_world  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.pipeline.full import bounds_of_baked  # noqa: E402
from baker.run.forked import call_forked  # noqa: E402
from baker.settings import Settings, resolve  # noqa: E402
from benchmarks.bench_million import terrain  # noqa: E402

LIMIT = 3600.0  # CPU seconds a child may use


def timed(function, *args):
    """(seconds, value) of ``function(*args)``."""
    started = time.perf_counter()
    value = function(*args)
    return time.perf_counter() - started, value


def whole(meshes, settings, resolution, chart_options=None):
    """Seconds of one xatlas run charting and packing every mesh; its atlas size."""
    atlas = xatlas.Atlas()
    for mesh in meshes:
        atlas.add_mesh(*mesh)
    seconds, _ = timed(atlas.generate, chart_options or xatlas.ChartOptions(),
                       unwrap._pack_options(settings, resolution, turn=True))
    return seconds, (atlas.width, atlas.height, atlas.atlas_count)


def charts(meshes):
    """Seconds of each mesh charted alone, and the charts."""
    runs = [timed(unwrap._chart, mesh) for mesh in meshes]
    return [s for s, _ in runs], [c for _, c in runs]


def pack(charted, settings, resolution, **changed):
    """Seconds of packing the charts with pack options changed by ``changed``; the size."""
    real = unwrap._pack_options

    def options(s, r):
        chosen = real(s, r)
        for name, value in changed.items():
            setattr(chosen, name, value)
        return chosen

    unwrap._pack_options = options
    try:
        seconds, packed = timed(unwrap._pack, charted, settings, resolution)
    finally:
        unwrap._pack_options = real
    return seconds, (packed.width, packed.height, packed.atlas_count)


def forked(function, *args, **kwargs):
    return call_forked(functools.partial(function, *args, **kwargs), "xatlas", LIMIT)


def measure(title: str, builder, settings: Settings) -> None:
    with tempfile.TemporaryDirectory() as folder:
        scene = load(builder.save(Path(folder) / "scene.glb"))
    world = build_world(scene)
    resolved = resolve(settings, *bounds_of_baked(world, scene))
    meshes = unwrap.xatlas_meshes(scene, world, unwrap.baked_instances(scene), resolved)
    page = resolved.page_size
    print(f"\n{title}: {sum(len(t) for _, t in meshes):,} triangles in {len(meshes)} meshes, "
          f"texel density {resolved.texel_density:.4g}, page {page}")
    for resolution in (0, page):
        seconds, size = forked(whole, meshes, resolved, resolution)
        print(f"  whole run (chart + pack) at resolution {resolution}: {seconds:.2f} s {size}")
    times, charted = forked(charts, meshes)
    print(f"  charts, each mesh alone: {sum(times):.2f} s in all, slowest mesh {max(times):.2f} s")
    for resolution in (0, page):
        seconds, size = forked(pack, charted, resolved, resolution)
        print(f"  pack of the charts at resolution {resolution}: {seconds:.2f} s {size}")
    for name, value in (("padding", 0), ("bilinear", False), ("bruteForce", True),
                        ("blockAlign", True), ("rotate_charts", False)):
        seconds, size = forked(pack, charted, resolved, page, **{name: value})
        print(f"  pack at {page} with {name} {value}: {seconds:.2f} s {size}")
    for iterations in (0, 2):
        options = xatlas.ChartOptions()
        options.max_iterations = iterations
        seconds, size = forked(whole, meshes, resolved, page, options)
        print(f"  whole run at {page} with max_iterations {iterations} (baker: 1): "
              f"{seconds:.2f} s {size}")


def edited(scene):
    """``scene`` with the primitive of the baked instance of (lower) median triangle count
    stretched by 10 % along its x axis (every instance of it)."""
    instances = unwrap.baked_instances(scene)
    counts = [len(scene.primitives[scene.instances[i].primitive].triangles) for i in instances]
    lower_median = int(np.argsort(counts, kind="stable")[(len(counts) - 1) // 2])
    chosen = scene.instances[instances[lower_median]]
    primitives = list(scene.primitives)
    prim = primitives[chosen.primitive]
    primitives[chosen.primitive] = dataclasses.replace(prim, positions=prim.positions * [1.1, 1, 1])
    return dataclasses.replace(scene, primitives=tuple(primitives))


def quality(atlas, world) -> str:
    """Pages, utilisation and stretch of ``atlas`` (see the module's docstring)."""
    uv_area, world_area = [], []
    for inst in atlas.instances:
        c = inst.uv[inst.triangles] * [atlas.width, atlas.height]
        a, b = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
        uv_area.append(0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]))
        p, q, r = world.corners(world.instance_triangles(inst.instance))
        world_area.append(0.5 * np.linalg.norm(np.cross(q - p, r - p), axis=1))
    uv_area, world_area = np.concatenate(uv_area), np.concatenate(world_area)
    ratio = uv_area / np.maximum(world_area * atlas.texel_density ** 2, 1e-30)
    keep = world_area > 0
    order = np.argsort(ratio[keep])
    ratio, weights = ratio[keep][order], world_area[keep][order] / world_area[keep].sum()
    cumulative = np.cumsum(weights)
    low, high = (ratio[min(np.searchsorted(cumulative, q), len(ratio) - 1)] for q in (0.05, 0.95))
    used = uv_area.sum() / (atlas.page_count * atlas.width * atlas.height)
    return (f"density {atlas.texel_density:.4g}, {atlas.page_count} page(s) of "
            f"{atlas.width}x{atlas.height}, utilisation {used:.3f}, stretch "
            f"{float(weights @ ratio):.3f} [{low:.3f}, {high:.3f}]")


def unwrap_seconds(scene, settings: Settings):
    """(wall seconds, CPU seconds of the forked xatlas children) of one ``unwrap.unwrap`` at
    the derived density, the atlas and world. The CPU time is steadier on a loaded machine."""
    world = build_world(scene)
    resolved = resolve(settings, *bounds_of_baked(world, scene))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    atlas = unwrap.unwrap(scene, world, resolved, fit_one_page=True)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return (wall, cpu), atlas, world


def times(title: str, builder, settings: Settings, repeat: int) -> None:
    """Print the cold / one-edit / cached unwrap seconds of a scene, medians of ``repeat``."""
    with tempfile.TemporaryDirectory() as folder:
        scene = load(builder.save(Path(folder) / "scene.glb"))
    changed = edited(scene)
    cold, edit, cached = [], [], []
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as cache:
            os.environ["BAKER_CACHE_DIR"] = cache
            seconds, atlas, world = unwrap_seconds(scene, settings)
            cold.append(seconds)
            cached.append(unwrap_seconds(scene, settings)[0])
            edit.append(unwrap_seconds(changed, settings)[0])

    def median(runs, k):
        return statistics.median(run[k] for run in runs)

    print(f"  {title} [{CODE}]: unwrap cold {median(cold, 0):.2f} s (xatlas CPU "
          f"{median(cold, 1):.2f} s), one mesh edited {median(edit, 0):.2f} s (CPU "
          f"{median(edit, 1):.2f} s), cached {median(cached, 0):.3f} s (medians of {repeat}, "
          f"load {os.getloadavg()[0]:.1f}); {quality(atlas, world)}", flush=True)


SCENES = {"boxes": ("200 boxes + sphere", boxes_and_sphere,
                    Settings(page_size=512, rays=4, rho="step", d_max=1.0)),
          "million": ("1M-triangle terrain", terrain, Settings())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--million", action="store_true", help="also the 1M-triangle terrain")
    parser.add_argument("--times", action="store_true", help="cold / edited / cached unwraps")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--against", help="a checkout whose baker is timed first (A/B)")
    parser.add_argument("--scene", choices=sorted(SCENES), help=argparse.SUPPRESS)
    args = parser.parse_args()
    names = [args.scene] if args.scene else ["boxes"] + (["million"] if args.million else [])
    for name in names:
        title, builder, settings = SCENES[name]
        if not args.times:
            measure(title, builder(), settings)
            continue
        if args.against:
            subprocess.run([sys.executable, __file__, "--times", "--scene", name, "--repeat",
                            str(args.repeat)], check=True,
                           env=dict(os.environ, BENCH_UNWRAP_CODE=args.against))
        times(title, builder(), settings, args.repeat)


if __name__ == "__main__":
    main()
