"""Benchmark: how the rays of a bake are split across kinds, against hand-tuned splits.

Bakes a scene (by default the shared lamp scene, /work/shared/scenes/LightsPunctualLamp: five
point lights inside a lampshade, 444 emissive triangles of its bulb) at ``--page-size`` with the
default ray counts and with each split of ``--splits`` (obscurance rays, emissive rays, shadow
rays, sky rays), and a reference with ``--reference`` × the default's rays of every kind and
another seed. Prints each bake's RMSE of the lightmap's luminance against the reference, its
seconds (the whole bake, on a shared machine: noisy) and its efficiency 1 / (RMSE² × s) over
the default's: the issue-39 goal is a default within 1.25× of the best split.

    python benchmarks/bench_ray_split.py [--scene PATH] [--page-size 256] [--reference 8]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from baker.geometry.surface import LUMINANCE  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.pipeline.full import compute  # noqa: E402
from baker.settings import Settings  # noqa: E402

LAMP = Path("/work/shared/scenes/LightsPunctualLamp/LightsPunctualLamp.gltf")
SPLITS = ["64,16,16,64", "32,32,16,64", "32,64,16,64", "16,64,16,64", "16,128,16,64",
          "32,128,16,64", "8,128,16,64", "16,256,16,64"]


def bake(scene, page: int, seed: int, split: tuple[int, ...] | None = None):
    """(luminance of the covered texels, seconds, resolved settings) of one bake."""
    counts = {} if split is None else dict(zip(("rays", "emissive_rays", "shadow_rays",
                                                "sky_rays"), split))
    start = time.perf_counter()
    done = compute(scene, Settings(page_size=page, seed=seed, **counts))
    seconds = time.perf_counter() - start
    covered = done.lightmaps.covered
    return (done.lightmaps.light @ LUMINANCE)[covered], seconds, done.settings


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", type=Path, default=LAMP)
    parser.add_argument("--page-size", type=int, default=256)
    parser.add_argument("--reference", type=int, default=8,
                        help="the reference's rays of every kind over the default's")
    parser.add_argument("--splits", nargs="*", default=SPLITS,
                        help="rays,emissive_rays,shadow_rays,sky_rays of each hand-tuned split")
    args = parser.parse_args()
    scene = load(args.scene)
    d = Settings()
    f = args.reference
    reference, ref_seconds, _ = bake(scene, args.page_size, 99,
                                     (64 * f, d.emissive_rays * f, d.shadow_rays * f, 64 * f))
    print(f"{args.scene.name}, page {args.page_size}; reference {f}× the default rays "
          f"({ref_seconds:.0f} s)")
    rows = []
    for label, split in [("default", None)] + [(s, tuple(map(int, s.split(",")))) for s in args.splits]:
        value, seconds, resolved = bake(scene, args.page_size, 1, split)
        rmse = float(np.sqrt(np.mean((value - reference) ** 2)))
        rows.append((label, resolved, rmse, seconds, 1.0 / (rmse * rmse * seconds)))
        print(f"  {label:14} rays {resolved.rays:4d} emissive {resolved.emissive_rays:4d} "
              f"shadow {resolved.shadow_rays:3d} sky {resolved.sky_rays:4d}: RMSE {rmse:.4g}, "
              f"{seconds:6.1f} s", flush=True)
    default = rows[0][4]
    best = max(rows, key=lambda row: row[4])
    for label, _, rmse, seconds, efficiency in rows:
        print(f"  {label:14} efficiency {efficiency / default:5.2f}× the default's")
    print(f"best split {best[0]}: the default's efficiency is {default / best[4]:.2f} of it "
          f"(goal ≥ 0.8, within 1.25×)")


if __name__ == "__main__":
    main()
