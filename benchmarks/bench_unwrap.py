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

    python benchmarks/bench_unwrap.py [--million]
"""

from __future__ import annotations

import argparse
import functools
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

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
                       unwrap._pack_options(settings, resolution))
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--million", action="store_true", help="also the 1M-triangle terrain")
    args = parser.parse_args()
    measure("200 boxes + sphere", boxes_and_sphere(),
            Settings(page_size=512, rays=4, rho="step", d_max=1.0))
    if args.million:
        measure("1M-triangle terrain", terrain(), Settings())


if __name__ == "__main__":
    main()
