"""Benchmark: what a cluster bake ships to each node and what a worker and the driver hold, on
the level of 400 distinct meshes (``assets/many_objects.level``, 1,024,812 triangles) or, with
``--instances N``, a room of N instances of one box mesh of 48 triangles
(``many_objects.boxes_and_sphere(instanced=True)``), at default settings (docs/cluster.md,
"Memory").

The full bake is run on this machine up to its parts (``full.compute`` with ``_bake_parts``
stopped): then ``cluster._shipped`` of its ``Baking`` (what every node receives once) is measured
as arrays, field by field, and pickled (what Ray sends beside its framing); the driver's resident
memory at that point is printed; a new process unpickles the shipped bake and builds what a
worker builds from it (``cluster._ready_bake``: Embree's scene, back faces, surfaces), and its
resident memory's growth is printed.

    python benchmarks/bench_cluster_memory.py [--count 400] [--instances 20000]
"""

from __future__ import annotations

import argparse
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.many_objects import boxes_and_sphere, level  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.pipeline import cluster, full  # noqa: E402
from baker.settings import Settings  # noqa: E402


class _Stopped(Exception):
    """Raised where the bake's parts would start: its ``Baking`` is in ``args[0]``."""


def _stop(baking, *_rest):
    raise _Stopped(baking)


def resident_mib() -> float:
    """This process's resident memory now, MiB (``/proc/self/statm``)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2 ** 20


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=400, help="distinct meshes of the level")
    parser.add_argument("--instances", type=int, help="instances of one mesh, not the level")
    parser.add_argument("--worker", help=argparse.SUPPRESS)  # the child: a pickled bake's path
    args = parser.parse_args()
    if args.worker:
        return worker(args.worker)
    with tempfile.TemporaryDirectory() as folder:
        built = (boxes_and_sphere(args.instances, cuts=2, sphere_rings=4, instanced=True)
                 if args.instances else level(args.count))
        scene = load(built.save(Path(folder) / "level.glb"))
    before = resident_mib()
    full._bake_parts = _stop
    try:
        full.compute(scene, Settings())
        raise SystemExit("the bake did not reach its parts")
    except _Stopped as stopped:
        baking = stopped.args[0]
    shipped = cluster._shipped(baking)
    triangles = len(baking.world.triangles)
    arrays = cluster._array_bytes(shipped)
    started = time.perf_counter()
    blob = pickle.dumps(shipped, protocol=5)
    pickling = time.perf_counter() - started
    print(f"{triangles:,} triangles, {len(baking.coverage.key):,} texels")
    print(f"  shipped once per node: {arrays / 2 ** 20:.1f} MiB of arrays "
          f"({arrays / triangles:.0f} B a triangle), {len(blob) / 2 ** 20:.1f} MiB pickled "
          f"in {pickling:.2f} s; " + ", ".join(
              f"{name} {cluster._array_bytes(getattr(shipped, name)) / 2 ** 20:.1f} MiB"
              for name in ("scene", "world", "atlas", "owned", "coverage")))
    print(f"  the driver: {resident_mib():.0f} MiB resident at its parts "
          f"({before:.0f} MiB before loading)")
    del baking, shipped
    with tempfile.NamedTemporaryFile(suffix=".pickle") as kept:
        kept.write(blob)
        kept.flush()
        del blob
        subprocess.run([sys.executable, __file__, "--worker", kept.name], check=True)


def worker(path: str) -> None:
    """As a worker process does: the shipped bake unpickled, then made ready; the growth of
    this (new) process's resident memory at each step."""
    base = resident_mib()
    with open(path, "rb") as kept:
        work = pickle.load(kept)
    held = resident_mib()
    cluster._ready_bake((None, work))
    print(f"  a worker process: {base:.0f} MiB with baker imported, +{held - base:.0f} MiB "
          f"holding the shipped bake, +{resident_mib() - held:.0f} MiB for Embree's scene, "
          "back faces and surfaces", flush=True)

if __name__ == "__main__":
    main()
