"""Benchmark: what the two independent half nets per texel cost in error against one full net.

baker draws a texel's N obscurance rays as two independently scrambled Sobol nets of N/2
(``sampling.fill_points``), so that half the difference of their means measures the error
without bias (``hemisphere.Terms.rmse``). One scrambled net of N points converges faster on
smooth integrands, so the split may cost error per ray (issue 46 asks for less). This
measures it: for each scene and N, the RMSE of the luminance of W over a sample of texels
against a reference of ``--reference`` rays (the mean of 4 bakes of other seeds), for the
bake's own two half nets (``first`` = 0) and for one net of N points (the net an adaptive round
draws: ``first`` > 0), each the RMS over 3 seeds. Same texels, same rays otherwise; one thread.

    python benchmarks/bench_split_nets.py [--rays 4 16 64 256] [--reference 1024] [--texels 3000]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from assets.make_scenes import cornell_box  # noqa: E402
from assets.many_objects import boxes_and_sphere  # noqa: E402
from baker.geometry.surface import LUMINANCE  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.image.compose import effective_r_ave  # noqa: E402
from baker.light.hemisphere import _chunk_sums, terms_of_sums, surfaces_of  # noqa: E402
from baker.pipeline.full import compute  # noqa: E402
from baker.rays.trace import Tracer  # noqa: E402
from baker.settings import Settings  # noqa: E402

CASES = (("Cornell room", cornell_box, "step"), ("200 boxes + sphere", boxes_and_sphere, "step"),
         ("Cornell room", cornell_box, "sqrt"))
ONE_NET = 1 << 20  # a first sample > 0: the texel's rays are one net (``fill_points``)
SEEDS = 3


def luminance_w(done, tracer, surfaces, rows, rays: int, first: int, seed: int) -> np.ndarray:
    """(k,) luminance of W of the texels ``rows`` from ``rays`` rays from sample ``first``
    (``fill_points``: not an adaptive round's grown nets, whose first round ``settings.rays``
    says; 0 here)."""
    settings = replace(done.settings, seed=seed, rays=0)
    sums, _ = _chunk_sums(surfaces, tracer, done.texels, rows, first, rays, settings)
    terms = terms_of_sums(sums, np.full(len(rows), rays, np.int64))
    return terms.obscurance(effective_r_ave(done.ambient, settings.rho)) @ LUMINANCE


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, nargs="+", default=[4, 16, 64, 256])
    parser.add_argument("--reference", type=int, default=1024)
    parser.add_argument("--texels", type=int, default=3000)
    args = parser.parse_args()
    for title, make, rho in CASES:
        with tempfile.TemporaryDirectory() as folder:
            scene = load(make().save(Path(folder) / "scene.glb"))
        done = compute(scene, Settings(page_size=256, rays=4, rho=rho, d_max=1.0, threads=1))
        tracer, surfaces = Tracer(done.world), surfaces_of(done.context())
        rows = np.arange(0, len(done.texels), max(1, len(done.texels) // args.texels))
        reference = np.mean([luminance_w(done, tracer, surfaces, rows, args.reference, 0,
                                         1000 + k) for k in range(4)], axis=0)
        print(f"\n{title}, rho {rho}: {len(rows):,} texels, reference {4 * args.reference} rays")
        print(f"  {'N':>4} | {'two half nets':>13} | {'one net':>8} | one ÷ two")
        for n in args.rays:
            errors = []
            for first in (0, ONE_NET):
                squares = [np.mean((luminance_w(done, tracer, surfaces, rows, n, first, s)
                                    - reference) ** 2) for s in range(SEEDS)]
                errors.append(float(np.sqrt(np.mean(squares))))
            print(f"  {n:>4} | {errors[0]:13.5f} | {errors[1]:8.5f} | {errors[1] / errors[0]:.3f}")


if __name__ == "__main__":
    main()
