"""Benchmark: the Cornell room at a 1024² page and 64 rays per texel.

Prints the wall time of every stage, the end-to-end ray rate of the trace stage (ray generation,
Embree, shading, accumulation), and — in the same run, on the same rays — the raw embreex rate:
the same origins and directions, already float32, cast by embreex's ``EmbreeScene.run`` alone
from the same number of threads (the yardstick of issue 46: baker's own Embree calls,
``rays.native``, cast faster than it). The ratio is how much of that speed the bake keeps.

    python benchmarks/bench_cornell.py [--page-size 1024] [--rays 64] [--threads 0]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.make_scenes import cornell_box  # noqa: E402
from baker.pipeline.full import compute  # noqa: E402
from baker.light.hemisphere import blocking_only, hemisphere_rays, surfaces_of  # noqa: E402
from baker.light.integrate import integrate  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.run.parallel import cores  # noqa: E402
from baker.settings import Settings  # noqa: E402
from baker.rays.trace import Tracer, embree_mesh, embreex_scene  # noqa: E402

RAW_RAYS = 8_000_000  # how many of the bake's rays the raw measurement casts


def raw_embree_rate(done, threads: int, query: str = "INTERSECT") -> tuple[float, int]:
    """Rays/s of embreex alone (whatever casts the bake's rays) on the bake's own first
    ``RAW_RAYS`` rays, and how many.

    query: "INTERSECT" (the nearest hit with its distance and barycentrics, as ``cast_local``
    asks) or "OCCLUDED" (whether anything is hit, as ``blocked_local`` asks: ``--rho step``'s
    obscurance rays, shadow rays)."""
    s = done.settings
    tracer = Tracer(done.world)
    count = min(len(done.texels), RAW_RAYS // s.rays)
    batches = []
    for start in range(0, count, s.chunk_texels):
        rows = slice(start, min(start + s.chunk_texels, count))
        origins, directions = hemisphere_rays(done.texels, rows, s.rays, s.seed, tracer.center)
        batches.append((origins, directions, np.full(len(origins), s.d_max, np.float32)))
    scene = embreex_scene(*embree_mesh(done.world))
    output = 1 if query == "INTERSECT" else None

    def cast(batch):
        origins, directions, dists = batch
        scene.run(origins, directions, dists=dists.copy(), query=query, output=output)

    started = time.perf_counter()
    with ThreadPoolExecutor(threads) as pool:
        list(pool.map(cast, batches))
    seconds = time.perf_counter() - started
    rays = sum(len(b[0]) for b in batches)
    return rays / seconds, rays


def stage_query(done) -> str:
    """The query the bake's obscurance rays were cast with (``hemisphere.blocking_only``)."""
    surfaces = surfaces_of(done.context())
    return "OCCLUDED" if blocking_only(surfaces, done.settings) else "INTERSECT"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--page-size", type=int, default=1024)
    parser.add_argument("--rays", type=int, default=64)
    parser.add_argument("--threads", type=int, default=0, help="0: one per core")
    args = parser.parse_args()
    threads = args.threads or cores()
    with tempfile.TemporaryDirectory() as folder:
        scene = load(cornell_box().save(Path(folder) / "cornell_box.glb"))
    done = compute(scene, Settings(page_size=args.page_size, rays=args.rays, threads=threads))
    texels, rays = len(done.texels), done.terms.rays
    print(f"Cornell room: {len(done.world.triangles):,} triangles, {texels:,} texels on "
          f"{done.atlas.page_count} page(s) of {done.atlas.width}×{done.atlas.height}, "
          f"{args.rays} rays/texel, {threads} thread(s)")
    for stage, seconds in done.stage_seconds.items():
        print(f"  {stage:<10} {seconds:8.2f} s")
    # The obscurance integration alone, timed between two raw measurements (the machine may be
    # busy with other work: the two raw figures show how much that moved).
    raw_before, raw_rays = raw_embree_rate(done, threads)
    started = time.perf_counter()
    integrate(done.context(), done.texels)
    end_to_end = rays / (time.perf_counter() - started)
    raw_after, _ = raw_embree_rate(done, threads)
    raw = (raw_before + raw_after) / 2
    print(f"  obscurance end to end:    {end_to_end / 1e6:6.2f} M rays/s over {rays:,} rays "
          "(ray generation, Embree, shading, accumulation)")
    print(f"  raw embreex, same rays:   {raw / 1e6:6.2f} M rays/s over {raw_rays:,} rays "
          f"(before {raw_before / 1e6:.2f}, after {raw_after / 1e6:.2f})")
    print(f"  end to end / raw:         {end_to_end / raw:6.1%}")
    print(f"  estimated RMSE:           {done.rmse_estimate():.4g}")


if __name__ == "__main__":
    main()
