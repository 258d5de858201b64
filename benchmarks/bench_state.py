"""Benchmark: the bake state's size, write and read time, member by member.

Bakes the demo Cornell box (assets/scenes/cornell_box.glb, default settings) and the 60-crate
room of ``bench_rebake.py`` (page 1024², 64 rays), then writes each state again from memory
(``state.write_state``, as a rebake does) and reads it back (``state.load``, as a rebake does)
``--repeat`` times, in turns with its members stored (as format version 7 wrote them),
deflated (as versions 8–12 did) and deflated where it pays (as this version does), and prints
per member its bytes as an array (``.npy``) and as written each way, and the median
milliseconds spent writing and reading it each way, then the totals (whole write and read: the
header, the directory, the checks as well).

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
from baker.rebake.state import state_classes  # noqa: E402
from baker.rebake.zipwriter import ZipWriter  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def scene(name: str, folder: Path) -> tuple[Path, baker.Settings]:
    """The scene file to bake and its settings."""
    if name == "demo":
        return ROOT / "assets" / "scenes" / "cornell_box.glb", baker.Settings()
    boxes = grid_boxes(60, room=(12.0, 3.0, 12.0), size=0.4)
    return (box_room(boxes, room=(12.0, 3.0, 12.0)).save(folder / "crates.glb"),
            baker.Settings(page_size=1024, rays=64))


MODES = {"stored": "every member stored, as format version 7 wrote them",
         "deflated": "every .npy member deflated, as versions 8 to 12 wrote them",
         "chosen": "deflated where it pays (state.MIN_RATIO), as this version writes them"}


class Clock:
    """Seconds spent per member, summed over a run: ``ZipWriter.add`` (the write of one member)
    and ``state._read_member`` (the read of one array) wrapped to time each call; members
    written as ``mode`` (``MODES``) says (the reader reads them all)."""

    def __init__(self, mode: str):
        self.mode = mode
        self.seconds: dict[str, float] = defaultdict(float)

    def __enter__(self):
        self._add, self._read = ZipWriter.add, state_file._read_member
        clock = self

        def add(archive, name, write, most, deflate=True):
            npy = name.endswith(".npy")
            chosen = {"stored": False, "deflated": npy, "chosen": deflate}[clock.mode]
            start = time.perf_counter()
            clock._add(archive, name, write, most, chosen)
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


def rewrite(state, classes, copy: Path, mode: str, times: dict) -> list[zipfile.ZipInfo]:
    """Write ``state`` to ``copy`` as ``mode`` says and read it back, adding each member's
    seconds (and the whole's, under "") to ``times[(mode, "write" or "read", name)]``; the
    members written."""
    for what in ("write", "read"):
        with Clock(mode) as clock:
            start = time.perf_counter()
            if what == "write":
                with open(copy, "wb") as file:
                    state_file.write_state(file, state)
            else:
                state_file.load(copy, classes)
            clock.seconds[""] = time.perf_counter() - start
        for name, seconds in clock.seconds.items():
            times[(mode, what, name)].append(seconds)
    with zipfile.ZipFile(copy) as archive:
        return archive.infolist()


def measure(path: Path, repeat: int) -> None:
    """Print the table of the state at ``path``: rewritten and read ``repeat`` times in each
    of the ``MODES``, in turns."""
    classes = state_classes()
    state = state_file.load(path, classes)
    copy = path.with_name("again.bake")
    times: dict = defaultdict(list)
    members: dict[str, list[zipfile.ZipInfo]] = {}
    for _ in range(repeat):
        for mode in MODES:
            members[mode] = rewrite(state, classes, copy, mode, times)
    same = copy.read_bytes() == path.read_bytes()  # "chosen" was written last

    def ms(mode: str, what: str, name: str) -> str:
        return f"{1e3 * statistics.median(times.get((mode, what, name), [0.0])):>7.1f}"

    print(f"{'member':<32} {'array bytes':>12} " + " ".join(
        f"{mode + ' bytes':>15} {'write ms read':>15}" for mode in MODES))
    sizes = {mode: {i.filename: i.compress_size for i in infos} for mode, infos in members.items()}
    for info in sorted(members["stored"], key=lambda i: -i.file_size):
        name = info.filename
        if info.file_size >= 100_000:
            print(f"{name:<32} {info.file_size:>12,} " + " ".join(
                f"{sizes[mode][name]:>15,} {ms(mode, 'write', name)} {ms(mode, 'read', name)}"
                for mode in MODES))
    print(f"{'all ' + str(len(members['stored'])) + ' members':<32} {'':>12} " + " ".join(
        f"{sum(sizes[mode].values()):>15,} {ms(mode, 'write', '')} {ms(mode, 'read', '')}"
        for mode in MODES))
    print(f"state file {copy.stat().st_size:,} bytes (format version {state_file.VERSION}); "
          f"rewritten from memory: "
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
