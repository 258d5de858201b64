"""Benchmark: baker's own Embree calls (``baker/rays/native.py``) against embreex's.

The same libembree4, the same scene, the same rays: the first ``RAW_RAYS`` obscurance rays of
a bake of the demo Cornell room and of the room of 200 boxes and a sphere (1024² page, 64 rays
a texel), already float32, in the bake's batches, cast by each engine alone from 1 and from
all threads, nearest hits (what ``--rho sqrt``, the default, asks) and occlusion (``--rho
step``, shadow rays). Prints M rays/s for each, and native ÷ embreex, measured A B A B
(``--repeat`` pairs, medians): the machine may be busy.

    python benchmarks/bench_rays.py [--repeat 3] [--scenes cornell boxes]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.make_scenes import cornell_box  # noqa: E402
from assets.many_objects import boxes_and_sphere  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.light.hemisphere import hemisphere_rays  # noqa: E402
from baker.pipeline.full import compute  # noqa: E402
from baker.rays import native  # noqa: E402
from baker.rays.trace import embree_mesh, embreex_scene  # noqa: E402
from baker.run.parallel import cores  # noqa: E402
from baker.settings import Settings  # noqa: E402

SCENES = {"cornell": ("Cornell room", cornell_box), "boxes": ("200 boxes + sphere", boxes_and_sphere)}
RAW_RAYS = 4_000_000


def bake_rays(make) -> tuple[object, list]:
    """A bake of the scene ``make`` builds, and its first ``RAW_RAYS`` obscurance rays as
    (origins, directions, lengths) float32 batches of the bake's chunk."""
    with tempfile.TemporaryDirectory() as folder:
        scene = load(make().save(Path(folder) / "scene.glb"))
    done = compute(scene, Settings(page_size=1024, rays=64))
    s = done.settings
    count = min(len(done.texels), RAW_RAYS // s.rays)
    batches = []
    for start in range(0, count, s.chunk_texels):
        rows = slice(start, min(start + s.chunk_texels, count))
        origins, directions = hemisphere_rays(done.texels, rows, s.rays, s.seed,
                                              done.world.center)
        batches.append((origins, directions, np.full(len(origins), s.d_max, np.float32)))
    return done, batches


def rate(scene, batches: list, threads: int, query: str) -> float:
    """Rays/s of ``scene.run`` on ``batches`` from ``threads`` threads."""
    def cast(batch):
        origins, directions, lengths = batch
        scene.run(origins, directions, dists=lengths.copy(), query=query, output=1)

    with ThreadPoolExecutor(threads) as pool:
        started = time.perf_counter()
        list(pool.map(cast, batches))
        seconds = time.perf_counter() - started
    return sum(len(b[2]) for b in batches) / seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--scenes", nargs="+", choices=sorted(SCENES), default=sorted(SCENES))
    args = parser.parse_args()
    print(f"rays: {native.engine()}")
    if not native.engine().startswith("Embree"):
        return
    for name in args.scenes:
        title, make = SCENES[name]
        done, batches = bake_rays(make)
        mesh = embree_mesh(done.world)
        engines = {"native": native.scene(*mesh), "embreex": embreex_scene(*mesh)}
        rays = sum(len(b[2]) for b in batches)
        print(f"{title}: {len(done.world.triangles):,} triangles, {rays:,} obscurance rays, "
              f"d_max {done.settings.d_max:.3g}")
        for threads in sorted({1, cores()}):
            for query in ("INTERSECT", "OCCLUDED"):
                pairs = [(rate(engines["native"], batches, threads, query),
                          rate(engines["embreex"], batches, threads, query))
                         for _ in range(args.repeat)]
                mine = statistics.median(p[0] for p in pairs)
                theirs = statistics.median(p[1] for p in pairs)
                ratio = statistics.median(p[0] / p[1] for p in pairs)
                print(f"  {threads} thread(s), {query:<9}  native {mine / 1e6:6.2f} M/s   "
                      f"embreex {theirs / 1e6:6.2f} M/s   native ÷ embreex {ratio:.2f}×")


if __name__ == "__main__":
    main()
