"""Benchmark: ``--smooth``, the world-space filter whose width its own error estimate chooses
(``image/world_filter``), in the bake, against the same bake unsmoothed.

Three scenes at baker's default settings but the rays: the demo's Cornell room (its ceiling
lamp an emitter), the room of 200 boxes and a sphere (``assets/many_objects.py``) and Khronos'
LightsPunctualLamp (``tests/scenes``: five hard point lights, whose light smoothing leaves as
it is, and an emissive bulb; only with ``--scenes``: its reference's own noise, from the
emitters, is larger than the errors it would measure). For each ray
count N (N obscurance and sky rays, N/4 shadow and emissive rays but at least 2: one ray has
no halves to measure its noise by), a bake without and with ``smooth``
(``pipeline.full.compute``, in this process after a warm-up), each
against a reference of ``--reference`` rays of another seed: the RMSE of the light's luminance
over the valid texels (the reference's own estimated noise taken out in quadrature), the
bake's ``rmse_estimate`` ÷ that, the width chosen, the bake's and the smoothing's seconds, and
the rays an unsmoothed bake would need for the smoothed RMSE (log-log between the measured
unsmoothed points).

    python benchmarks/bench_world_filter.py [--rays 4 16 64] [--reference 1024]
        [--scenes cornell boxes lamp]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from assets.make_scenes import cornell_box  # noqa: E402
from assets.many_objects import boxes_and_sphere  # noqa: E402
from baker.atlas.validity import MOVED, VALID  # noqa: E402
from baker.geometry.surface import luminance  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.pipeline.full import compute  # noqa: E402
from baker.settings import Settings  # noqa: E402

SCENES = {"cornell": ("Cornell room", cornell_box),
          "boxes": ("200 boxes + sphere", boxes_and_sphere),
          "lamp": ("LightsPunctualLamp", ROOT / "tests" / "scenes" / "LightsPunctualLamp"
                   / "LightsPunctualLamp.gltf")}


def settings_for(rays: int, seed: int = 0, smooth: bool = False) -> Settings:
    """The default settings but the ray counts (``rays`` obscurance and sky rays, a quarter of
    them shadow and emissive rays, at least 2), ``seed`` and ``smooth``."""
    quarter = max(2, rays // 4)
    return Settings(rays=rays, sky_rays=rays, shadow_rays=quarter, emissive_rays=quarter,
                    seed=seed, smooth=smooth)


def valid_luminance(done) -> np.ndarray:
    """(k,) the light's luminance at the bake's valid texels."""
    valid = np.isin(done.validity.state, (VALID, MOVED))
    return luminance(done.lightmaps.light[done.texels.pixels()])[valid]


def rays_for(error: float, points: list[tuple[int, float]]) -> float:
    """Rays an unsmoothed bake needs for RMSE ``error``, log-log along (rays, RMSE) ``points``
    (the line through the nearest two past either end)."""
    points = sorted(points)
    pairs = list(zip(points, points[1:]))
    (n0, e0), (n1, e1) = next(((a, b) for a, b in pairs if b[1] <= error <= a[1]),
                              pairs[-1] if error < points[-1][1] else pairs[0])
    f = math.log(error / e0) / math.log(e1 / e0)
    return math.exp(math.log(n0) + f * (math.log(n1) - math.log(n0)))


def timed_bake(scene, settings: Settings):
    """(the bake, its wall seconds)."""
    started = time.perf_counter()
    done = compute(scene, settings)
    return done, time.perf_counter() - started


def bench_scene(name: str, args) -> None:
    """Print one scene's table."""
    title, source = SCENES[name]
    if isinstance(source, Path):
        scene = load(source)
    else:
        with tempfile.TemporaryDirectory() as folder:
            scene = load(source().save(Path(folder) / "scene.glb"))
    compute(scene, settings_for(4, smooth=True))  # the kernels loaded, the unwrap cached
    reference = compute(scene, settings_for(args.reference, seed=1000))
    truth = valid_luminance(reference)
    floor = reference.rmse_estimate() ** 2
    print(f"\n{title}: {len(truth):,} valid texels, reference {args.reference} rays "
          f"(its own RMSE estimate {reference.rmse_estimate():.2e})")
    print(f"  {'N':>4} | {'RMSE':>9} {'est ÷':>6} {'s':>5} | {'smoothed':>9} {'est ÷':>6} "
          f"{'width':>5} {'s':>5} {'smooth s':>8} | {'RMSE ×':>6} | raw rays for it")
    rows = []
    for n in args.rays:
        measured = {}
        for smooth in (False, True):
            done, seconds = timed_bake(scene, settings_for(n, smooth=smooth))
            error = math.sqrt(max(float(np.mean((valid_luminance(done) - truth) ** 2)) - floor,
                                  0.0))
            measured[smooth] = (error, done.rmse_estimate() / error, seconds, done)
        rows.append((n, measured))
    points = [(n, measured[False][0]) for n, measured in rows]
    for n, measured in rows:
        raw, raw_ratio, raw_seconds, _ = measured[False]
        smoothed, ratio, seconds, done = measured[True]
        print(f"  {n:>4} | {raw:9.2e} {raw_ratio:6.2f} {raw_seconds:5.2f} | {smoothed:9.2e} "
              f"{ratio:6.2f} {done.smoothed.width:5.2f} {seconds:5.2f} "
              f"{done.stage_seconds['smooth']:8.2f} | {raw / smoothed:6.2f} | "
              f"{rays_for(smoothed, points):.0f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, nargs="+", default=[4, 16, 64])
    parser.add_argument("--reference", type=int, default=1024)
    parser.add_argument("--scenes", nargs="+", choices=sorted(SCENES), default=["cornell", "boxes"])
    args = parser.parse_args()
    for name in args.scenes:
        bench_scene(name, args)


if __name__ == "__main__":
    main()
