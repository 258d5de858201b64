"""Benchmark: the world-space filter chosen by its own error estimate (``image/world_filter``).

Classic AO (``--rho step --d-max 1``, 512² page, as ``bench_vs_blender.py``) on the Cornell room
and the 200 boxes: for each ray count N, W's luminance per valid texel, raw and smoothed by
``world_filter.smooth`` (the width of least bound on its SURE, σ² from each texel's split,
``bake``), against a reference of ``--reference`` rays of another seed (whose
own noise is in the RMSE). Prints the RMSE of both, the estimates of both (raw: today's,
√mean split²; smoothed: the filter's bound, ``Filtered.error``), estimate ÷ measured, the
width chosen, the filter's seconds, and the rays a raw bake would need for the smoothed RMSE
(log-log between the measured raw points).

    python benchmarks/bench_world_filter.py [--rays 4 16 64 256] [--reference 2048]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.make_scenes import cornell_box  # noqa: E402
from assets.many_objects import boxes_and_sphere  # noqa: E402
from baker.atlas.validity import MOVED, VALID  # noqa: E402
from baker.geometry.surface import LUMINANCE  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.image.compose import effective_r_ave  # noqa: E402
from baker.image.world_filter import smooth  # noqa: E402
from baker.pipeline.full import compute  # noqa: E402
from baker.settings import Settings  # noqa: E402

SCENES = (("Cornell room", cornell_box), ("200 boxes + sphere", boxes_and_sphere))


def bake(scene, rays: int, seed: int):
    """(texels, valid (N,) bool, W luminance (N,), split variance (N,)) of a step AO bake: e²,
    e half the difference of the texel's two halves (``Terms.split_errors`` without its floor
    for texels whose rays all agree, which is no unbiased estimate: it raised the mean
    variance on the Cornell room at 4 rays 8 % above the measured, and SURE, which subtracts
    it, below zero)."""
    done = compute(scene, Settings(page_size=512, rays=rays, rho="step", d_max=1.0, seed=seed))
    r_ave = effective_r_ave(done.ambient, done.settings.rho)
    valid = np.isin(done.validity.state, (VALID, MOVED))
    terms = done.terms
    split = 0.5 * (terms.half_split[:, 0] + float(r_ave @ LUMINANCE) * terms.half_split[:, 1])
    return done.texels, valid, terms.obscurance(r_ave) @ LUMINANCE, split * split


def rays_for(error: float, points: list[tuple[int, float]]) -> float:
    """Rays a raw bake needs for RMSE ``error``, log-log along (rays, RMSE) ``points`` (the
    line through the nearest two past either end)."""
    points = sorted(points)
    pairs = list(zip(points, points[1:]))
    (n0, e0), (n1, e1) = next(((a, b) for a, b in pairs if b[1] <= error <= a[1]),
                              pairs[-1] if error < points[-1][1] else pairs[0])
    f = math.log(error / e0) / math.log(e1 / e0)
    return math.exp(math.log(n0) + f * (math.log(n1) - math.log(n0)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, nargs="+", default=[4, 16, 64, 256])
    parser.add_argument("--reference", type=int, default=2048)
    args = parser.parse_args()
    for title, make in SCENES:
        with tempfile.TemporaryDirectory() as folder:
            scene = load(make().save(Path(folder) / "scene.glb"))
        texels, valid, reference, _ = bake(scene, args.reference, 1000)
        rows = np.flatnonzero(valid)
        position, normal = texels.position[rows], texels.geometric_normal(rows)
        size = texels.size(rows)
        print(f"\n{title}: {len(rows):,} valid texels, reference {args.reference} rays")
        print(f"  {'N':>4} | {'raw RMSE':>9} {'estimate':>9} {'÷':>5} | {'smoothed':>9} "
              f"{'estimate':>9} {'÷':>5} {'width':>5} {'s':>5} | raw rays for it")
        results = []
        for n in args.rays:
            _, _, w, variance = bake(scene, n, 1)
            w, variance = w[rows], variance[rows]
            started = time.perf_counter()
            done = smooth(position, normal, size, w[:, None], w, variance)
            seconds = time.perf_counter() - started
            raw = float(np.sqrt(np.mean((w - reference[rows]) ** 2)))
            smoothed = float(np.sqrt(np.mean((done.values[:, 0] - reference[rows]) ** 2)))
            results.append((n, raw, float(np.sqrt(variance.mean())), smoothed,
                            done.error, done.width, seconds))
        points = [(n, raw) for n, raw, *_ in results]
        for n, raw, raw_est, smoothed, estimate, width, seconds in results:
            print(f"  {n:>4} | {raw:9.5f} {raw_est:9.5f} {raw_est / raw:5.2f} | {smoothed:9.5f} "
                  f"{estimate:9.5f} {estimate / smoothed:5.2f} {width:5.2f} {seconds:5.2f} | "
                  f"{rays_for(smoothed, points):.0f}")


if __name__ == "__main__":
    main()
