"""Benchmark: what materials cost (issue 4).

1. The paper's figure 7 comparison: a floor beside a perfect mirror wall (assets
   ``material_scenes.mirror_wall``) baked with each specular strategy — (a) ρ of the first
   distance, following the reflection for the colour; (b) ρ of the summed path length, stopping
   past d_max (the default); (c) R_ave with ρ = 1, no extra ray. Prints the trace stage's time,
   the rays cast (the texels' own plus the mirror chains' extra rays), rays per second, and W
   (luminance) on the floor within 0.3 m of the wall and far from it.
2. The plan on an all-diffuse scene (the Cornell box): a bake as it runs (the plan finds no
   material stage to run) against the same bake with every material stage cut out of the code
   (no special-hit shading, no alpha table, no leaves/inner pass): the bytes written must be the
   same and the time the same within noise. Bakes alternate, best of ``--repeat``.
3. What leaves and inner obscurances cost when they run: a leaf over a floor and a wax cylinder
   (assets ``material_scenes.leaf``, ``wax_cylinder``): the trace stage with and without them,
   and the rays they add (a leaf's back face doubles its texels' rays; a wax texel casts
   ``rays`` more into the object).

    python benchmarks/bench_materials.py [--rays 64] [--repeat 5]

Timings are wall-clock on whatever else the machine is running: compare within one run.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import baker  # noqa: E402
import baker.geometry.world as world_module  # noqa: E402
import baker.light.hemisphere as hemisphere_module  # noqa: E402
import baker.light.integrate as integrate_module  # noqa: E402
from assets.make_scenes import cornell_box  # noqa: E402
from assets.material_scenes import leaf, mirror_wall, wax_cylinder  # noqa: E402
from baker.pipeline.full import compute  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.geometry.surface import LUMINANCE  # noqa: E402

bake_module = sys.modules["baker.pipeline.full"]  # the module (``baker.bake`` is also the function)


def strategies(folder: Path, rays: int, repeat: int) -> None:
    """Part 1: strategies (a), (b), (c) on the mirror wall."""
    builder = mirror_wall()
    scene = load(builder.save(folder / "mirror.glb"))
    wall_x = builder.info["wall_x"]
    print(f"mirror wall (figure 7): {rays} rays/texel, d_max 1 m")
    print(f"  {'strategy':9} {'trace s':>8} {'own rays':>11} {'chain rays':>11} {'rays/s':>10} "
          f"{'W near wall':>12} {'W far':>7}")
    for strategy in "abc":
        settings = baker.Settings(rays=rays, texel_density=64, d_max=1.0, specular=strategy)
        best, done = min(((_trace_seconds(d), d) for d in
                          (compute(scene, settings) for _ in range(repeat))),
                         key=lambda pair: pair[0])
        own, chain = done.terms.rays, int(done.terms.chain_rays.sum())
        w = done.terms.obscurance(done.ambient.r_ave) @ LUMINANCE
        tx = done.texels
        floor = (done.world.tri_instance[tx.triangle] == builder.info["floor"]) & (
            np.abs(tx.position[:, 2]) < 1.0)
        near, far = floor & (tx.position[:, 0] > wall_x - 0.3), floor & (tx.position[:, 0] < -1.0)
        print(f"  ({strategy}){'':6} {best:8.3f} {own:11,} {chain:11,} {(own + chain) / best:10.3g} "
              f"{w[near].mean():12.4f} {w[far].mean():7.4f}")
    print(f"  ({len(done.texels):,} texels)")


def _trace_seconds(done) -> float:
    return done.stage_seconds["trace"]


@contextmanager
def diffuse_only():
    """The baker with every material stage cut out: no special-hit shading, no alpha table, no
    leaves or inner obscurances (what the bake was before issue 4, for a diffuse scene)."""
    surfaces, alpha = hemisphere_module.surfaces_of, world_module.alpha_test

    def plain_surfaces(scene, world):
        s = surfaces(scene, world)
        kind = np.where(s.kind == hemisphere_module._SPECIAL, hemisphere_module._CONSTANT, s.kind)
        return hemisphere_module.Surfaces(s.scene, s.world, s.table, s.varying,
                                          kind.astype(np.uint8), s.materials, np.zeros((0, 3)),
                                          s.step)

    hemisphere_module.surfaces_of = bake_module.surfaces_of = plain_surfaces
    world_module.alpha_test = lambda scene, world: None
    try:
        with without_translucency():
            yield
    finally:
        hemisphere_module.surfaces_of, world_module.alpha_test = surfaces, alpha
        bake_module.surfaces_of = surfaces


@contextmanager
def without_translucency():
    """The baker without leaves and inner obscurances (every other stage as it is)."""
    translucency = integrate_module.add_translucency
    integrate_module.add_translucency = lambda *args, **kwargs: args[6]
    try:
        yield
    finally:
        integrate_module.add_translucency = translucency


def plan_cost(folder: Path, rays: int, repeat: int) -> None:
    """Part 2: an all-diffuse scene with and without the material stages in the code."""
    path = cornell_box().save(folder / "cornell.glb")
    settings = baker.Settings(rays=rays, texel_density=64)
    times = {"as it runs": [], "diffuse only": []}
    plan_seconds, outputs = [], {}
    for _ in range(repeat):
        for name in times:
            out = folder / f"{name.replace(' ', '_')}.glb"
            started = time.perf_counter()
            if name == "diffuse only":
                with diffuse_only():
                    result = baker.bake(path, out, settings, state=False)
            else:
                result = baker.bake(path, out, settings, state=False)
                plan_seconds.append(result.report["stage_seconds"]["plan"])
            times[name].append(time.perf_counter() - started)
            outputs[name] = out.read_bytes()
    stages = result.plan.stages
    off = [s for s in ("specular chains", "refraction", "translucency", "alpha testing",
                       "inner obscurances", "leaves") if stages[s].startswith("off")]
    print(f"\nall-diffuse Cornell box: {result.texels:,} texels, {rays} rays/texel, "
          f"best of {repeat}; material stages off in the plan: {len(off)} of 6")
    for name, seconds in times.items():
        print(f"  {name:13} bake {min(seconds):6.3f} s (all: "
              + ", ".join(f"{s:.3f}" for s in seconds) + ")")
    a, b = min(times["as it runs"]), min(times["diffuse only"])
    print(f"  difference {a - b:+.3f} s ({(a - b) / b:+.1%}); plan stage {min(plan_seconds):.4f} s;"
          f" same bytes: {outputs['as it runs'] == outputs['diffuse only']}")


def translucency_cost(folder: Path, rays: int, repeat: int) -> None:
    """Part 3: the trace stage of the leaf and wax scenes with and without their §4 terms."""
    print(f"\nleaves and inner obscurances: {rays} rays/texel, best of {repeat}")
    for name, builder in (("leaf", leaf()), ("wax cylinder", wax_cylinder())):
        scene = load(builder.save(folder / f"{name.replace(' ', '_')}.glb"))
        settings = baker.Settings(rays=rays, texel_density=48, d_max=1.0)
        on = min((compute(scene, settings) for _ in range(repeat)), key=_trace_seconds)
        with without_translucency():
            off = min((compute(scene, settings) for _ in range(repeat)), key=_trace_seconds)
        extra = int(on.terms.chain_rays.sum() - off.terms.chain_rays.sum())
        print(f"  {name:13} {len(on.texels):8,} texels: trace {_trace_seconds(off):.3f} s -> "
              f"{_trace_seconds(on):.3f} s, rays {on.terms.rays:,} + {extra:,} for §4")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rays", type=int, default=64)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as name:
        strategies(Path(name), args.rays, args.repeat)
        plan_cost(Path(name), args.rays, args.repeat)
        translucency_cost(Path(name), args.rays, args.repeat)


if __name__ == "__main__":
    main()
