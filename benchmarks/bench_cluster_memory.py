"""Benchmark: what a cluster bake ships to each node, what a node makes of it once, and what a
worker process and the driver hold, on the level of 400 distinct meshes
(``assets/many_objects.level``, 1,024,812 triangles) or, with ``--instances N``, a room of N
instances of one box mesh (``many_objects.boxes_and_sphere(instanced=True)``; ``--cuts 6``:
864 triangles a box, ``--cuts 2``: 48), at default settings (docs/cluster.md, "Memory").

The full bake is run on this machine up to its parts (``full.compute`` with ``_bake_parts``
stopped), and the driver's resident memory printed. ``cluster._shipped`` of its ``Baking`` (what
every node receives once) is measured as arrays and pickled (what Ray sends beside its
framing). A new process makes what a node makes of it (``cluster._node_bake``: the world,
the texels' per-triangle terms, back faces, surfaces) and writes it as Ray's object store holds
it: pickled, its arrays out of band in a file of /dev/shm. A third process maps that file and
reads the arrays in place, as a worker process reads its node's object (``ray.get``, zero
copy), then builds Embree's scene (``cluster._ready_bake``): its own memory (RssAnon) is
printed apart from the node's shared pages (RssShmem).

    python benchmarks/bench_cluster_memory.py [--count 400] [--instances 20000 --cuts 6]
"""

from __future__ import annotations

import argparse
import mmap
import os
import pickle
import resource
import struct
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

_FIXED_MALLOC = dict(os.environ, MALLOC_MMAP_THRESHOLD_="131072")
"""The children's environment: glibc's malloc maps every block of 128 KiB or more on its own
and unmaps it when freed (its threshold otherwise grows as big blocks are freed, and freed
arrays stay resident in its heap), so that resident memory counts what is held."""
_ALIGN = 64  # bytes: where each out-of-band buffer starts in the node's file, as in Ray's store


class _Stopped(Exception):
    """Raised where the bake's parts would start: its ``Baking`` is in ``args[0]``."""


def _stop(baking, *_rest):
    raise _Stopped(baking)


def memory_mib() -> dict[str, float]:
    """This process's resident memory now, MiB, page by page (``/proc/self/smaps_rollup``;
    ``status``'s counters lag): ``anon`` its own (heap, Embree), ``shmem`` the rest besides its
    code's growth: pages of mapped files, such as a node's object store, ``rss`` both."""
    fields = {}
    with open("/proc/self/smaps_rollup") as f:
        for line in f:
            name, _, value = line.partition(":")
            if name in ("Rss", "Anonymous"):
                fields[name] = int(value.split()[0]) / 1024
    return {"rss": fields["Rss"], "anon": fields["Anonymous"],
            "shmem": fields["Rss"] - fields["Anonymous"]}


def peak_mib() -> float:
    """This process's peak resident memory so far, MiB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=400, help="distinct meshes of the level")
    parser.add_argument("--instances", type=int, help="instances of one mesh, not the level")
    parser.add_argument("--cuts", type=int, default=2, help="an instanced box's grid cuts")
    parser.add_argument("--node", nargs=2, help=argparse.SUPPRESS)  # shipped pickle, node file
    parser.add_argument("--worker", help=argparse.SUPPRESS)  # the node's file
    args = parser.parse_args()
    if args.node:
        return node(*args.node)
    if args.worker:
        return worker(args.worker)
    with tempfile.TemporaryDirectory() as folder:
        built = (boxes_and_sphere(args.instances, cuts=args.cuts, sphere_rings=4, instanced=True)
                 if args.instances else level(args.count))
        scene = load(built.save(Path(folder) / "level.glb"))
    before = memory_mib()["rss"]
    full._bake_parts = _stop
    started = time.perf_counter()
    try:
        full.compute(scene, Settings())
        raise SystemExit("the bake did not reach its parts")
    except _Stopped as stopped:
        baking = stopped.args[0]
    seconds = time.perf_counter() - started
    driver = memory_mib()["rss"]
    shipped = cluster._shipped(full._bake_part, baking)
    triangles = len(baking.world.triangles)
    arrays = cluster._array_bytes(shipped)
    started = time.perf_counter()
    blob = pickle.dumps(shipped, protocol=5)
    pickling = time.perf_counter() - started
    bare = shipped.baking
    print(f"{triangles:,} triangles, {len(baking.coverage.key):,} texels, "
          f"{len(scene.instances):,} instances ({seconds:.0f} s to the parts)")
    print(f"  shipped once per node: {arrays / 2 ** 20:.1f} MiB of arrays "
          f"({arrays / triangles:.1f} B a triangle), {len(blob) / 2 ** 20:.1f} MiB pickled "
          f"in {pickling:.2f} s; " + ", ".join(
              f"{name} {cluster._array_bytes(getattr(bare, name)) / 2 ** 20:.1f} MiB"
              for name in ("scene", "atlas", "coverage"))
          + f", owners {shipped.owns.nbytes / 2 ** 20:.2f} MiB")
    print(f"  the driver: {driver:.0f} MiB resident at its parts ({before:.0f} MiB before "
          f"loading), peak {peak_mib():.0f} MiB with the pickled shipped bake; the world "
          f"{cluster._array_bytes(baking.world) / 2 ** 20:.1f} MiB")
    del baking, shipped, bare
    with tempfile.NamedTemporaryFile(suffix=".pickle") as kept, \
            tempfile.NamedTemporaryFile(dir="/dev/shm", prefix="bench-node-") as store:
        kept.write(blob)
        kept.flush()
        del blob
        subprocess.run([sys.executable, __file__, "--node", kept.name, store.name], check=True,
                       env=_FIXED_MALLOC)
        for _ in range(2):  # two worker processes of one node
            subprocess.run([sys.executable, __file__, "--worker", store.name], check=True,
                           env=_FIXED_MALLOC)


def node(shipped_path: str, store_path: str) -> None:
    """As a node does once: the shipped bake unpickled and made (``cluster._node_bake``), then
    written as Ray's object store holds it (``_store``)."""
    base = memory_mib()["rss"]
    with open(shipped_path, "rb") as kept:
        shipped = pickle.load(kept)
    started = time.perf_counter()
    made = cluster._node_bake(shipped)
    seconds = time.perf_counter() - started
    size = _store(made, store_path)
    print(f"  a node, once: {seconds:.1f} s to build the world and what derives from it "
          f"(CRC checked); {cluster._array_bytes(cluster._made(made[1])) / 2 ** 20:.1f} MiB of "
          f"arrays, {size / 2 ** 20:.1f} MiB in its object store with the shipped bake; the "
          f"task's process peaked at {peak_mib() - base:.0f} MiB over its {base:.0f} MiB",
          flush=True)


def _store(value, path: str) -> int:
    """Write ``value`` pickled (protocol 5) with its buffers out of band at 64-byte offsets, as
    one file: the layout ``_load`` maps. Its size, bytes."""
    buffers: list[pickle.PickleBuffer] = []
    head = pickle.dumps(value, protocol=5, buffer_callback=buffers.append)
    with open(path, "wb") as out:
        out.write(struct.pack("<QQ", len(head), len(buffers)))
        out.write(head)
        for buffer in buffers:
            raw = buffer.raw()
            out.write(b"\0" * (-out.tell() % _ALIGN) + struct.pack("<Q", raw.nbytes))
            out.write(b"\0" * (-out.tell() % _ALIGN))
            out.write(raw)
        return out.tell()


def _load(path: str):
    """The value ``_store`` wrote, its arrays read in place from the mapped file (read-only)."""
    with open(path, "rb") as f:
        mapped = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
    view = memoryview(mapped)
    size, count = struct.unpack_from("<QQ", view, 0)
    at = 16 + size
    head, buffers = view[16:at], []
    for _ in range(count):
        at += -at % _ALIGN
        (length,) = struct.unpack_from("<Q", view, at)
        at += 8
        at += -at % _ALIGN
        buffers.append(view[at:at + length])
        at += length
    return pickle.loads(head, buffers=buffers)


def worker(store_path: str) -> None:
    """As a worker process does: its node's bake read in place, then made ready (Embree's
    scene); its own memory and the node's shared pages it touched."""
    base = memory_mib()
    made = _load(store_path)
    held = memory_mib()
    started = time.perf_counter()
    ready = cluster._ready_bake(made)  # held while measured
    seconds = time.perf_counter() - started
    now = memory_mib()
    print(f"  a worker process: {base['rss']:.0f} MiB with baker imported, {base['anon']:.0f} "
          f"MiB of it its own; then +{held['anon'] - base['anon']:.0f} MiB reading its node's "
          f"bake, +{now['anon'] - held['anon']:.0f} MiB for Embree's scene ({seconds:.1f} s): "
          f"{now['anon']:.0f} MiB its own, {now['shmem'] - base['shmem']:.0f} MiB of the node's "
          f"shared pages touched", flush=True)
    del ready


if __name__ == "__main__":
    main()
