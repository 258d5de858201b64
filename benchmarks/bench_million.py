"""Benchmark: a 1M-triangle scene baked end to end, against the budget the README states.

The scene: a closed 12 × 3 × 12 m room around a rolling terrain of 999,698 triangles (one mesh,
a 707 × 707 grid of quads over 10 × 10 m, heights 0.5 ± 0.3 m), written as a .glb. It is baked
by the ``baker`` command in a new process (``python -m baker.cli.main bake``, default settings,
every core, an empty unwrap cache: what a first bake of such a scene costs), ``--repeat``
times; the bake's stage lines (stderr) and wall time are printed, with the machine's load. The
budget is read from the README's line "a 1M-triangle scene ... within N s"; the script exits 1
when the median bake takes longer.

    python benchmarks/bench_million.py [--repeat 1] [--keep DIR]
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from assets.gltf_builder import GltfBuilder, box  # noqa: E402
from assets.many_objects import ROOM  # noqa: E402

QUADS = 707  # a side: 2 × 707² = 999,698 triangles
BUDGET = re.compile(r"a 1M-triangle scene[^.]*? within (\d+) s")


def terrain(quads: int = QUADS) -> GltfBuilder:
    """The room and a terrain of 2 · quads² triangles (flat-shaded normals up, UVs its x, z)."""
    b = GltfBuilder()
    wall = b.material("wall", (0.73, 0.73, 0.73))
    ground = b.material("ground", (0.45, 0.5, 0.35))
    b.node("room", b.shape_mesh("room", box(ROOM, inward=True), material=wall),
           translation=(0.0, ROOM[1] / 2, 0.0))
    x, z = np.meshgrid(np.linspace(-5, 5, quads + 1), np.linspace(-5, 5, quads + 1), indexing="ij")
    y = 0.5 + 0.3 * np.sin(1.7 * x) * np.cos(1.3 * z)
    positions = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    i, j = np.meshgrid(np.arange(quads), np.arange(quads), indexing="ij")
    a = (i * (quads + 1) + j).ravel()
    triangles = np.concatenate([np.stack([a, a + 1, a + quads + 2], 1),
                                np.stack([a, a + quads + 2, a + quads + 1], 1)])
    normals = np.tile([0.0, 1.0, 0.0], (len(positions), 1))
    uv = np.stack([x.ravel(), z.ravel()], axis=1)
    b.node("terrain", b.shape_mesh("terrain", (positions, triangles, normals, uv),
                                   material=ground))
    return b


def readme_budget() -> float:
    """The seconds the README promises for a 1M-triangle bake."""
    found = BUDGET.search(" ".join((ROOT / "README.md").read_text().split()))
    if found is None:
        raise SystemExit("README.md states no 1M-triangle budget "
                         "(a 1M-triangle scene … within N s)")
    return float(found.group(1))


def bake_once(scene: Path, folder: Path) -> float:
    """One cold bake of ``scene`` in a new process; its wall seconds (stage lines printed)."""
    env = dict(os.environ, BAKER_CACHE_DIR=str(Path(tempfile.mkdtemp(dir=folder))))
    env.pop("CI", None)
    started = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "baker.cli.main", "bake", str(scene), "-o",
                          str(folder / "baked.glb"), "--no-state", "--overwrite"], cwd=ROOT,
                         env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    seconds = time.perf_counter() - started
    if run.returncode != 0:
        raise SystemExit(f"the bake failed ({run.returncode}):\n{run.stderr}")
    print("".join(f"    {line}\n" for line in run.stderr.splitlines()), end="")
    print("    " + next(line for line in run.stdout.splitlines() if "texels on" in line).strip())
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--keep", type=Path, help="write the scene and the output here")
    args = parser.parse_args()
    budget = readme_budget()
    with tempfile.TemporaryDirectory() as temporary:
        folder = args.keep or Path(temporary)
        folder.mkdir(parents=True, exist_ok=True)
        scene = terrain().save(folder / "terrain.glb")
        print(f"{2 * QUADS ** 2 + 12:,} triangles, {scene.stat().st_size / 2 ** 20:.0f} MiB; "
              f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f} at the start")
        times = []
        for k in range(args.repeat):
            print(f"  bake {k + 1}:")
            times.append(bake_once(scene, folder))
            print(f"    {times[-1]:.1f} s wall, load {os.getloadavg()[0]:.1f} at its end")
    median = statistics.median(times)
    verdict = "within" if median <= budget else "OVER"
    print(f"median {median:.1f} s: {verdict} the README's budget of {budget:.0f} s")
    sys.exit(0 if median <= budget else 1)


if __name__ == "__main__":
    main()
