"""Benchmark: relighting (new light colour and intensity) against a full bake.

Bakes a floor under a point light at a 1024² page with its bake state, changes the light's
colour and intensity, and times ``baker.bake(..., relight=True)`` (recomposition from the state,
no ray) against a full bake of the edited scene; prints both and the rays each cast.

    python benchmarks/bench_relight.py [--rays 64]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import baker  # noqa: E402
from assets.light_scenes import lit_floor  # noqa: E402
from benchmarks.bench_rebake import print_stage_seconds  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rays", type=int, default=64, help="obscurance rays per texel")
    settings = baker.Settings(page_size=1024, rays=parser.parse_args().rays)
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        scene = lit_floor("point", intensity=10.0).save(folder / "scene.glb")
        baker.bake(scene, folder / "lit.glb", settings)
        edited = lit_floor("point", intensity=40.0, color=(1.0, 0.6, 0.4)).save(folder / "b.glb")
        started = time.perf_counter()
        relit = baker.bake(edited, folder / "lit.glb", settings, relight=True)
        relight_seconds = time.perf_counter() - started
        started = time.perf_counter()
        full = baker.bake(edited, folder / "full.glb", settings, state=False)
        full_seconds = time.perf_counter() - started
        same = (folder / "lit.glb").read_bytes() == (folder / "full.glb").read_bytes()
    print(f"floor under a point light, {full.texels:,} texels, {settings.rays} rays/texel")
    print(f"  full bake: {full_seconds:6.2f} s, {full.rays:,} obscurance rays")
    print(f"  relight:   {relight_seconds:6.2f} s, {relit.rebake['rays']:,} rays "
          f"({relight_seconds / full_seconds:.0%} of the full bake); identical output: {same}")
    print_stage_seconds({"full": full, "relight": relit})


if __name__ == "__main__":
    main()
