"""Benchmark: the bake state's size, write and read time, member by member.

Bakes the demo Cornell box (assets/scenes/cornell_box.glb, default settings) and the 60-crate
room of ``bench_rebake.py`` (page 1024², 64 rays), then writes each state again from memory
(``state.write_state``, as a rebake does) and reads it back (``state.load``, as a rebake does)
``--repeat`` times, in turns with its members stored (as format version 7 wrote them) and
deflated (as this version does), and prints per member its bytes as an array (``.npy``) and
deflated, and the median milliseconds spent writing and reading it each way, then the totals
(whole write and read: the header, the directory, the checks as well).

    python benchmarks/bench_state.py [--repeat 5] [--scenes demo crates] [--threads 2]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import tempfile
import time
import zipfile
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import baker  # noqa: E402
from assets.rebake_scenes import box_room, grid_boxes  # noqa: E402
from baker.rebake import state as state_file  # noqa: E402
from baker.rebake.incremental import state_classes  # noqa: E402
from baker.rebake.zipwriter import ZipWriter  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def scene(name: str, folder: Path) -> tuple[Path, baker.Settings]:
    """The scene file to bake and its settings."""
    if name == "demo":
        return ROOT / "assets" / "scenes" / "cornell_box.glb", baker.Settings()
    boxes = grid_boxes(60, room=(12.0, 3.0, 12.0), size=0.4)
    return (box_room(boxes, room=(12.0, 3.0, 12.0)).save(folder / "crates.glb"),
            baker.Settings(page_size=1024, rays=64))


class Clock:
    """Seconds spent per member, summed over a run: ``ZipWriter.add`` (the write of one member)
    and ``state._read_member`` (the read of one array) wrapped to time each call. ``stored``:
    every member written stored, as format version 7 wrote them (the reader reads both)."""

    def __init__(self, stored: bool):
        self.stored = stored
        self.seconds: dict[str, float] = defaultdict(float)

    def __enter__(self):
        self._add, self._read = ZipWriter.add, state_file._read_member
        clock = self

        def add(archive, name, write, most, deflate=True):
            start = time.perf_counter()
            clock._add(archive, name, write, most, deflate and not clock.stored)
            clock.seconds[name] += time.perf_counter() - start

        def read(archive, file, name):
            start = time.perf_counter()
            out = clock._read(archive, file, name)
            clock.seconds[f"{name}.npy"] += time.perf_counter() - start
            return out

        ZipWriter.add, state_file._read_member = add, read
        return self

    def __exit__(self, *_):
        ZipWriter.add, state_file._read_member = self._add, self._read


def rewrite(state, classes, copy: Path, stored: bool, times: dict) -> list[zipfile.ZipInfo]:
    """Write ``state`` to ``copy`` and read it back, adding each member's seconds (and the
    whole's, under "") to ``times[(stored, "write" or "read", name)]``; the members written."""
    for what in ("write", "read"):
        with Clock(stored) as clock:
            start = time.perf_counter()
            if what == "write":
                with open(copy, "wb") as file:
                    state_file.write_state(file, state)
            else:
                state_file.load(copy, classes)
            clock.seconds[""] = time.perf_counter() - start
        for name, seconds in clock.seconds.items():
            times[(stored, what, name)].append(seconds)
    with zipfile.ZipFile(copy) as archive:
        return archive.infolist()


def measure(path: Path, repeat: int) -> None:
    """Print the table of the state at ``path``: rewritten and read ``repeat`` times with its
    members stored (as version 7) and deflated (this version), in turns."""
    classes = state_classes()
    state = state_file.load(path, classes)
    copy = path.with_name("again.bake")
    times: dict = defaultdict(list)
    for _ in range(repeat):
        stored = rewrite(state, classes, copy, True, times)
        deflated = rewrite(state, classes, copy, False, times)
    same = copy.read_bytes() == path.read_bytes()

    def ms(stored: bool, what: str, name: str) -> str:
        return f"{1e3 * statistics.median(times.get((stored, what, name), [0.0])):>7.1f}"

    print(f"{'member':<32} {'array bytes':>12} {'stored':>15} {'deflated bytes':>15} "
          f"{'ratio':>6} {'deflated':>15}")
    print(f"{'':<32} {'':>12} {'write ms read':>15} {'':>15} {'':>6} {'write ms read':>15}")
    for info in sorted(deflated, key=lambda i: -i.file_size):
        name = info.filename
        if info.file_size >= 100_000:
            print(f"{name:<32} {info.file_size:>12,} {ms(True, 'write', name)} "
                  f"{ms(True, 'read', name)} {info.compress_size:>15,} "
                  f"{info.file_size / max(info.compress_size, 1):>6.2f} "
                  f"{ms(False, 'write', name)} {ms(False, 'read', name)}")
    raw = sum(i.compress_size for i in stored)
    small = sum(i.compress_size for i in deflated)
    print(f"{'all ' + str(len(deflated)) + ' members':<32} {raw:>12,} {ms(True, 'write', '')} "
          f"{ms(True, 'read', '')} {small:>15,} {raw / small:>6.2f} {ms(False, 'write', '')} "
          f"{ms(False, 'read', '')}")
    print(f"state file {copy.stat().st_size:,} bytes (format version {state_file.VERSION}), "
          f"stored members: {sum(i.compress_size for i in stored):,}; rewritten from memory: "
          f"{'the same bytes as the bake' if same else 'OTHER BYTES than the bake'}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--scenes", nargs="+", choices=("demo", "crates"),
                        default=["demo", "crates"])
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        for name in args.scenes:
            source, settings = scene(name, folder)
            settings = dataclasses.replace(settings, threads=args.threads)
            output = folder / f"{name}_baked.glb"
            start = time.perf_counter()
            result = baker.bake(source, output, settings)
            print(f"\n{name}: {source.name}, {result.texels:,} texels, baked in "
                  f"{time.perf_counter() - start:.1f} s")
            measure(state_file.default_path(output), args.repeat)


if __name__ == "__main__":
    main()
