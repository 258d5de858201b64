"""Benchmark: a bake's parts on a Ray cluster of 1, 2 and 4 one-CPU workers on this machine
against the local bake, so that the scaling and the driver's cost can be read.

For the Cornell room (``--page-size``, ``--rays``) cut into parts of ``--part`` texels, prints
for the local bake (every core, and one thread) and for each cluster: the median wall time of
``--repeat`` bakes after one warm-up, texels/s, and per part the driver's own time (texels made
again, composing, spilling) and the bytes sent each way, as pickled (Ray's serialisation is
pickle 5 with the arrays out of band: the same bytes within its framing); the same for a rebake
after the short block moved (median of ``--repeat``, each from the first bake's state), against
the local rebake; then the time and the resident memory of starting the cluster (``ray
start`` head and workers, every process of theirs). The workers share this machine's cores with the driver, so past its core count more
workers only add overhead: the figures read the cost of distribution, and the scaling holds
for workers on machines of their own.

    python benchmarks/bench_cluster.py [--workers 1 2 4] [--page-size 512] [--rays 64]
"""

from __future__ import annotations

import argparse
import os
import pickle
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import baker  # noqa: E402
from assets.make_scenes import cornell_box  # noqa: E402
from baker.pipeline import cluster, parts  # noqa: E402
from tests.ray_cluster import LocalCluster  # noqa: E402

_DRIVER_STAGES = ("rasterise", "compose", "spill", "ship")  # the driver's own work with parts


def _resident_kib(sessions: set[int]) -> int:
    """Resident memory (KiB) of every process whose session is one of ``sessions``."""
    total = 0
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
            session = int(stat.rsplit(")", 1)[1].split()[3])
            if session in sessions:
                status = Path(f"/proc/{pid}/status").read_text()
                total += int(next(line.split()[1] for line in status.splitlines()
                                  if line.startswith("VmRSS:")))
        except (OSError, StopIteration, ValueError):
            continue
    return total


def _timed_bakes(source: Path, out: Path, settings: baker.Settings, repeat: int):
    """One warm-up bake, then ``repeat``: (median seconds, the last result)."""
    baker.bake(source, out, settings)
    seconds = []
    for _ in range(repeat):
        started = time.perf_counter()
        result = baker.bake(source, out, settings)
        seconds.append(time.perf_counter() - started)
    return statistics.median(seconds), result


def _timed_rebakes(edited: Path, baked: Path, out: Path, settings: baker.Settings, repeat: int):
    """``repeat`` rebakes of ``edited`` into ``out``, each from a fresh copy of the output and
    bake state at ``baked`` (the scene before the edit): (median seconds, the last result)."""
    seconds = []
    for _ in range(max(1, repeat)):
        for suffix in ("", ".bake"):
            shutil.copyfile(f"{baked}{suffix}", f"{out}{suffix}")
        started = time.perf_counter()
        result = baker.bake(edited, out, settings, incremental=True)
        seconds.append(time.perf_counter() - started)
        assert result.rebake["incremental"], result.rebake
    return statistics.median(seconds), result


def _short_block_moved():
    """The Cornell room with its short block moved 0.3 m towards the middle (as
    tests/test_cluster.py moves it)."""
    scene = cornell_box()
    node = scene._nodes[scene.info["nodes"]["short_block"]]
    node.translation = [node.translation[0] - 0.3, *node.translation[1:]]
    return scene


def _measure_parts() -> dict[str, list[int]]:
    """Record the pickled bytes (Ray's serialisation is pickle 5 with the arrays out of band:
    the same bytes within its framing) of what each cluster run ships once ("shipped"), each
    part's input ("to") and its result ("from"), bake or rebake: ``cluster.run_parts``
    wrapped."""
    sizes: dict[str, list[int]] = {"to": [], "from": [], "shipped": []}
    real = cluster.run_parts

    def measured(work, counts, item, times, advance):
        sizes["shipped"].append(len(pickle.dumps(work, protocol=5)))

        def sized(k):
            given = item(k)
            sizes["to"].append(len(pickle.dumps(given, protocol=5)))
            return given

        for value in real(work, counts, sized, times, advance):
            sizes["from"].append(len(pickle.dumps(value, protocol=5)))
            yield value

    cluster.run_parts = measured
    return sizes


def _row(label: str, seconds: float, texels: int, baseline: float, extra: str = "") -> None:
    print(f"  {label:<22} {seconds:7.2f} s  {texels / seconds:>10,.0f} texels/s  "
          f"×{baseline / seconds:5.2f} of local{extra}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--page-size", type=int, default=512)
    parser.add_argument("--rays", type=int, default=64)
    parser.add_argument("--part", type=int, default=1 << 14, help="texels a part")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    parts.PART_TEXELS = args.part
    folder = Path(tempfile.mkdtemp(prefix="bench-cluster-"))
    source = cornell_box().save(folder / "cornell.glb")
    settings = baker.Settings(rays=args.rays, page_size=args.page_size)
    local, result = _timed_bakes(source, folder / "local.glb", settings, args.repeat)
    texels = result.texels
    count = len(parts.part_slices(texels))
    print(f"Cornell room, page {args.page_size}², {texels:,} texels, {args.rays} rays, "
          f"{count} parts of ≤{args.part:,} texels, {os.cpu_count()} cores here; "
          f"median of {args.repeat}")
    _row("local, every core", local, texels, local)
    one, _ = _timed_bakes(source, folder / "local1.glb", baker.Settings(
        rays=args.rays, page_size=args.page_size, threads=1), args.repeat)
    _row("local, one thread", one, texels, local)
    local_driver = sum(result.report["stage_seconds"].get(k, 0.0) for k in ("compose", "spill"))

    sizes = _measure_parts()
    edited = _short_block_moved().save(folder / "moved.glb")
    rebake_local, rebaked = _timed_rebakes(edited, folder / "local.glb", folder / "rebake.glb",
                                           settings, args.repeat)
    dirty = rebaked.rebake["dirty_texels"]
    print(f"  rebake after the short block moved: {dirty:,} dirty texels, "
          f"{len(parts.part_slices(dirty))} parts; local, every core {rebake_local:.2f} s")
    starts = []
    for workers in args.workers:
        started = time.perf_counter()
        with LocalCluster(workers=workers) as running:
            start_seconds = time.perf_counter() - started
            memory = _resident_kib({p.pid for p in [running._head, *running.workers]})
            starts.append((workers, start_seconds, memory))
            clustered = baker.Settings(rays=args.rays, page_size=args.page_size,
                                       cluster=running.address)
            sizes["to"].clear(), sizes["from"].clear()
            seconds, done = _timed_bakes(source, folder / f"cluster{workers}.glb", clustered,
                                         args.repeat)
            assert (folder / f"cluster{workers}.glb").read_bytes() == \
                (folder / "local.glb").read_bytes(), "not the local bake's bytes"
            stages, on = done.report["stage_seconds"], done.report["cluster"]
            driver = sum(stages.get(k, 0.0) for k in _DRIVER_STAGES)
            receive = on["worker_stage_seconds"].get("receive", 0.0) / len(on["workers"])
            _row(f"cluster, {workers} worker{'s' * (workers > 1)}", seconds, texels, local,
                 f"; driver {1e3 * driver / count:5.1f} ms/part (local "
                 f"{1e3 * local_driver / count:.1f}), {statistics.mean(sizes['to']) / 1e3:,.0f} kB "
                 f"out, {statistics.mean(sizes['from']) / 1e3:,.0f} kB back a part; "
                 f"{len(on['workers'])} worker processes, each {receive:.2f} s to receive the "
                 "bake and build Embree's scene")
            bake_sizes = {k: list(v) for k, v in sizes.items()}
            for measured in sizes.values():
                measured.clear()
            again, done = _timed_rebakes(edited, folder / "local.glb",
                                         folder / f"rebake{workers}.glb", clustered, args.repeat)
            assert (folder / f"rebake{workers}.glb").read_bytes() == \
                (folder / "rebake.glb").read_bytes(), "not the local rebake's bytes"
            a_part = dirty / done.report["cluster"]["parts"]  # parts of equal size
            print(f"    its rebake: {again:.2f} s (×{rebake_local / again:.2f} of the local "
                  f"rebake); {statistics.mean(sizes['to']) / 1e3:,.0f} kB out, "
                  f"{statistics.mean(sizes['from']) / 1e3:,.0f} kB back a part: "
                  f"{statistics.mean(sizes['to']) / a_part:.1f} B out, "
                  f"{statistics.mean(sizes['from']) / a_part:.1f} B back a dirty texel; "
                  f"shipped once {sizes['shipped'][0] / 1e3:,.0f} kB; driver's "
                  + ", ".join(f"{k} {v:.2f}" for k, v in done.report["stage_seconds"].items())
                  + " s")
            sizes.update(bake_sizes)
    print(f"  shipped once per worker: {sizes['shipped'][0] / 1e3:,.0f} kB (pickled); "
          f"per texel: {statistics.mean(sizes['to']) / (texels / count):.1f} B out, "
          f"{statistics.mean(sizes['from']) / (texels / count):.1f} B back")
    for workers, seconds, memory in starts:
        print(f"  ray start, head + {workers} worker(s): {seconds:.1f} s, "
              f"{memory / 1024:,.0f} MiB resident")


if __name__ == "__main__":
    main()
