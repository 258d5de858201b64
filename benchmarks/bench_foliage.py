"""Benchmark: foliage approx mode against tracing the crown, at the same texels.

A generated tree (assets/foliage_scenes.py: a trunk, a crown of ``--leaves`` alpha-cut leaf
quads, a ground, a patch of grass) is baked once in ``--foliage approx`` mode; on its crown's
texels it then times

- the approximate mode's obscurance: the fit (shells, the traced fit and held-out texels) plus
  the closed form at every crown texel;
- tracing the crown's texels at ``--rays`` (what a bake without the mode does for them);

and the RMSE of W's luminance of both against a reference traced at ``--reference`` rays on
``--sample`` crown texels (chosen by a hash of their keys). Then it traces those texels at 4, 8,
16, … rays until the RMSE is at most the approximate mode's, and times tracing every crown texel
at that count: the time a traced bake needs to be as accurate. Times are medians of
``--repeat`` runs; numba's kernels are compiled (a small tree baked in both modes) before
anything is timed. Also prints both whole bakes' stage times, their total without the unwrap
(the first bake's unwrap is the second's cache hit) and the process's peak memory.

    python benchmarks/bench_foliage.py [--leaves 100000] [--page-size 1024] [--rays 64]
                                       [--repeat 3] [--sample 2000] [--reference 1024]
"""

from __future__ import annotations

import argparse
import resource
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import baker  # noqa: E402
from assets.foliage_scenes import tree  # noqa: E402
from baker.context import context_of
from baker.atlas.rasterise import cover, owners  # noqa: E402
from baker.atlas.validity import Faces  # noqa: E402
from baker.geometry.surface import LUMINANCE  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.image.compose import effective_r_ave  # noqa: E402
from baker.light.foliage import FitInputs, foliage_terms, prepare_foliage  # noqa: E402
from baker.light.hemisphere import surfaces_of  # noqa: E402
from baker.light.integrate import integrate  # noqa: E402
from baker.pipeline.full import compute  # noqa: E402
from baker.rays.sampling import hash_u32  # noqa: E402
from baker.rays.trace import Tracer  # noqa: E402


def median_time(repeat: int, run) -> tuple[float, object]:
    """(median seconds of ``repeat`` calls of ``run()``, the last call's result)."""
    times, out = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        out = run()
        times.append(time.perf_counter() - start)
    return statistics.median(times), out


def peak_rss_gb() -> tuple[float, float]:
    """(this process's, its largest waited-for child's) peak resident memory, GB (Linux KiB)."""
    return tuple(resource.getrusage(who).ru_maxrss / 2**20
                 for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))


def warm_up(settings: baker.Settings) -> None:
    """Bake a 500-leaf tree in both modes: numba compiles what the timed bakes then reuse."""
    with tempfile.TemporaryDirectory() as folder:
        small = load(tree(500, 100).save(Path(folder) / "small.glb"))
    for mode in ("approx", "none"):
        compute(small, replace(settings, foliage=mode, page_size=256))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--leaves", type=int, default=100_000)
    parser.add_argument("--grass", type=int, default=5000)
    parser.add_argument("--page-size", type=int, default=1024)
    parser.add_argument("--rays", type=int, default=64)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--sample", type=int, default=2000,
                        help="crown texels the RMSE is measured on")
    parser.add_argument("--reference", type=int, default=1024,
                        help="rays per texel of the reference")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        path = tree(args.leaves, args.grass).save(Path(folder) / "tree.glb")
        scene = load(path)
    settings = baker.Settings(rays=args.rays, page_size=args.page_size, foliage="approx")
    warm_up(settings)
    whole = {}
    for mode in ("approx", "none"):
        start = time.perf_counter()
        done = compute(scene, replace(settings, foliage=mode))
        whole[mode] = (time.perf_counter() - start, done)
    done = whole["approx"][1]
    s, world, texels = done.settings, done.world, done.texels
    tracer = Tracer(world)  # the whole scene, leaves included
    r_ave = effective_r_ave(done.ambient, s.rho)
    group = done.foliage.texel_groups(texels)
    crown = np.flatnonzero(np.isin(group, [j for j, c in enumerate(done.foliage.crowns)
                                           if c.kind == "crown"]))
    print(f"tree: {args.leaves:,} leaf quads, {args.grass:,} grass blades; {len(texels):,} texels "
          f"on {done.atlas.page_count} page(s) of {done.atlas.width}², {len(crown):,} on the "
          f"crown; {s.rays} rays/texel, d_max {s.d_max:.3g}")
    for mode, (seconds, bake) in whole.items():
        stages = ", ".join(f"{k} {v:.2f}" for k, v in bake.stage_seconds.items())
        rest = seconds - bake.stage_seconds.get("unwrap", 0.0)
        print(f"whole bake, foliage {mode}: {seconds:.2f} s, {rest:.2f} s without the unwrap "
              f"({stages})")

    coverage = cover(done.atlas, world)
    context = context_of(scene, world, tracer, s)
    inputs = FitInputs(done.atlas, coverage, owners(done.atlas, world, coverage),
                       Faces(scene, world), surfaces_of(context), r_ave)

    def approx_run():
        foliage = prepare_foliage(context, inputs)
        return foliage_terms(foliage, world, texels, crown)

    def traced_run(rays: int, rows: np.ndarray):
        return integrate(context.with_settings(replace(s, rays=rays)), texels, rows=rows,
                         surfaces=inputs.surfaces)

    approx_run(), traced_run(4, crown[:64])  # compile numba's kernels before timing
    t_approx, approx = median_time(args.repeat, approx_run)
    t_traced, traced = median_time(args.repeat, lambda: traced_run(s.rays, crown))

    rank = hash_u32(np.uint64(7), texels.key[crown], np.uint64(0), np.uint64(91))
    pick = np.sort(np.argsort(rank, kind="stable")[:args.sample])
    rows = crown[pick]
    start = time.perf_counter()
    reference = traced_run(args.reference, rows).obscurance(r_ave) @ LUMINANCE
    t_reference = time.perf_counter() - start

    def rmse(w: np.ndarray) -> float:
        return float(np.sqrt(np.mean((w - reference) ** 2)))

    e_approx = rmse(approx.obscurance(r_ave)[pick] @ LUMINANCE)
    e_traced = rmse(traced.obscurance(r_ave)[pick] @ LUMINANCE)
    bias = float(np.mean(approx.obscurance(r_ave)[pick] @ LUMINANCE - reference))
    report = done.foliage.report()["error"]
    print(f"reference: {args.reference} rays at {len(rows):,} crown texels ({t_reference:.1f} s); "
          f"mean W {reference.mean():.4f}")
    print(f"crown texels, approx: {t_approx:.3f} s (fit and closed form), RMSE {e_approx:.4f}, "
          f"bias {bias:+.4f}; the bake's report: held-out RMSE "
          f"{report['held_out']['rmse']:.4f}, bias {report['held_out']['bias']:+.4f}")
    print(f"crown texels, traced at {s.rays} rays: {t_traced:.3f} s, RMSE {e_traced:.4f}")
    print(f"speed-up at the same texels: {t_traced / t_approx:.1f}x")
    rays = 4
    while rays <= args.reference // 2:
        e = rmse(traced_run(rays, rows).obscurance(r_ave) @ LUMINANCE)
        if e <= e_approx:
            break
        rays *= 2
    if rays > args.reference // 2:
        print(f"tracing reaches the approx RMSE only beyond {args.reference // 2} rays")
    else:
        t_equal, _ = median_time(args.repeat, lambda: traced_run(rays, crown))
        print(f"traced at {rays} rays: RMSE {e:.4f} <= approx's; all crown texels "
              f"{t_equal:.3f} s = {t_equal / t_approx:.1f}x the approx mode's time")
    print("peak RSS: %.2f GB, largest child %.2f GB" % peak_rss_gb())


if __name__ == "__main__":
    main()
