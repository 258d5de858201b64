"""Benchmark: what ``--denoise`` buys against spending the same time on more rays.

For the Cornell room and the vase room (assets/make_scenes.py), measures the RMSE of the final
lightmap (after post-processing) against a converged reference bake, over every covered texel
and colour channel, in lightmap units, for

  (a) a bake at N rays,
  (b) the same bake with ``denoise=True``,
  (c) a bake without denoising at the rays the same wall time buys: N' = N · (1 + t_denoise /
      t_rays), where t_rays is the time (a) spent casting rays (trace + direct light stages),
      since only those stages grow with the ray count;
  (d) the same at the next power of two ≥ N' (Owen-scrambled Sobol sampling is balanced at
      powers of two: other counts lose part of its advantage), which takes longer than (b).

"N rays" scales every ray count together: N obscurance rays, N/4 shadow and emissive rays, N sky
rays (the defaults' proportions, 64/16/16/64). The reference uses N = ``--reference`` (1024).

    python benchmarks/bench_denoise.py [--page-size 256] [--rays 16 64] [--reference 1024]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.make_scenes import cornell_box, vase_room  # noqa: E402
from baker.pipeline.full import Computed, compute  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.run.parallel import cores  # noqa: E402
from baker.settings import Settings  # noqa: E402

SCENES = {"Cornell room": cornell_box, "vase room": vase_room}


def settings(rays: int, page_size: int, threads: int, denoise: bool = False) -> Settings:
    """Every ray count scaled with ``rays`` in the defaults' proportions."""
    return Settings(page_size=page_size, rays=rays, shadow_rays=max(1, rays // 4),
                    emissive_rays=max(1, rays // 4), sky_rays=rays, threads=threads,
                    denoise=denoise)


def timed(scene, s: Settings) -> tuple[Computed, float]:
    """The computed bake and its wall time in seconds."""
    started = time.perf_counter()
    done = compute(scene, s)
    return done, time.perf_counter() - started


def rmse(done: Computed, reference: Computed) -> float:
    """RMSE over covered texels and RGB channels of ``done``'s light against the reference's."""
    covered = reference.lightmaps.covered
    assert np.array_equal(covered, done.lightmaps.covered), "the atlases differ"
    return float(np.sqrt(np.mean((done.lightmaps.light[covered] -
                                  reference.lightmaps.light[covered]) ** 2)))


def ray_seconds(done: Computed) -> float:
    """Seconds the bake spent in the stages whose cost grows with the rays."""
    return sum(done.stage_seconds.get(stage, 0.0) for stage in ("trace", "direct", "gi"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--page-size", type=int, default=256)
    parser.add_argument("--rays", type=int, nargs="+", default=[16, 64])
    parser.add_argument("--reference", type=int, default=1024)
    parser.add_argument("--threads", type=int, default=0, help="0: one per core")
    args = parser.parse_args()
    print(f"{cores()} core(s), page {args.page_size}², reference {args.reference} rays; "
          "RMSE over covered texels (RGB), lightmap units")
    print(f"{'scene':<13}{'N':>5}{'(a) RMSE':>11}{'s':>7}{'(b) denoised':>14}{'s':>7}"
          f"{'gain':>7}{'N′':>6}{'(c) RMSE':>11}{'s':>7}{'(c)/(b)':>9}{'2ᵏ':>6}{'(d) RMSE':>11}"
          f"{'s':>7}{'(d)/(b)':>9}")
    for name, make in SCENES.items():
        with tempfile.TemporaryDirectory() as folder:
            scene = load(make().save(Path(folder) / "scene.glb"))
        reference, _ = timed(scene, settings(args.reference, args.page_size, args.threads))
        # the reference's own noise: a second reference with another seed (independent Owen
        # scrambling) differs from the first by √2 × its RMSE
        again, _ = timed(scene, replace(settings(args.reference, args.page_size, args.threads),
                                        seed=1))
        own = rmse(again, reference) / np.sqrt(2.0)
        mean = float(reference.lightmaps.light[reference.lightmaps.covered].mean())
        for rays in args.rays:
            noisy, t_noisy = timed(scene, settings(rays, args.page_size, args.threads))
            denoised, t_denoised = timed(scene, settings(rays, args.page_size, args.threads, True))
            t_denoise = denoised.stage_seconds["denoise"]
            equal = max(rays + 1, int(round(rays * (1 + t_denoise / ray_seconds(noisy)))))
            more, t_more = timed(scene, settings(equal, args.page_size, args.threads))
            power = 1 << (equal - 1).bit_length()
            most, t_most = timed(scene, settings(power, args.page_size, args.threads))
            a, b, c = rmse(noisy, reference), rmse(denoised, reference), rmse(more, reference)
            d = rmse(most, reference)
            print(f"{name:<13}{rays:>5}{a:>11.2e}{t_noisy:>7.2f}{b:>14.2e}{t_denoised:>7.2f}"
                  f"{a / b:>6.1f}×{equal:>6}{c:>11.2e}{t_more:>7.2f}{c / b:>8.1f}×{power:>6}"
                  f"{d:>11.2e}{t_most:>7.2f}{d / b:>8.1f}×")
        print(f"{name:<13} {len(reference.texels):,} texels, "
              f"{denoised.denoised.charts} patches denoised, mean light {mean:.3f}, the "
              f"reference's own RMSE {own:.1e}")


if __name__ == "__main__":
    main()
