"""How the default environment (``--escape auto``) changes the bakes of props, measured.

For each scene, bakes with the model's R_ave environment (``--escape scene``, what baker did
before) and with the default, and prints the share of baked texels whose lightmap is mostly
black (luminance below 5 % of an open surface's, 1) or colour-cast (brightest channel over
1.5 times the dimmest), with I_A and what the plan chose. Scenes: the real ones in tests/scenes,
and three props made here: a sphere lit only by a small emissive decal (0.9 % of the area, as
DamagedHelmet's), a yellow duck-coloured sphere and a red box (as Duck and Box), each alone.

    python benchmarks/bench_prop_defaults.py [--rays 64]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from assets.gltf_builder import GltfBuilder, box, uv_sphere  # noqa: E402
from baker.geometry.surface import LUMINANCE  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.pipeline.full import compute  # noqa: E402
from baker.settings import Settings  # noqa: E402
from tests.bakehelp import REAL_SCENES  # noqa: E402


def decal_sphere() -> GltfBuilder:
    """A grey sphere with a small glowing decal on it (0.9 % of the surface area)."""
    b = GltfBuilder()
    b.node("helmet", b.shape_mesh("helmet", uv_sphere(0.5), material=b.material("helmet", (0.5, 0.5, 0.5))))
    decal = b.material("decal", (0.5, 0.5, 0.5), emissive=(1.0, 0.6, 0.2))
    b.node("decal", b.shape_mesh("decal", box((0.1, 0.02, 0.1)), material=decal),
           translation=(0.0, 0.5, 0.0))
    return b


def coloured(shape, colour, name) -> GltfBuilder:
    b = GltfBuilder()
    b.node(name, b.shape_mesh(name, shape, material=b.material(name, colour)))
    return b


def measure(path: Path, settings: Settings) -> dict:
    done = compute(load(path), settings)
    light = done.lightmaps.light[done.lightmaps.covered]
    luminance = light @ LUMINANCE
    cast = light.max(axis=1) > 1.5 * np.maximum(light.min(axis=1), 1e-9)
    return {"black": float((luminance < 0.05).mean()), "cast": float(cast.mean()),
            "i_a": done.ambient.intensity, "chose": done.plan.stages.get("escaping rays", "")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=64)
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp())
    made = {"decal sphere (decal 0.9 %)": decal_sphere(),
            "yellow sphere (Duck)": coloured(uv_sphere(0.5), (0.9, 0.6, 0.05), "duck"),
            "red box (Box)": coloured(box((1, 1, 1)), (0.8, 0.05, 0.05), "box")}
    scenes = {name: b.save(folder / f"{k}.glb") for k, (name, b) in enumerate(made.items())}
    scenes.update({name: path for name, path in REAL_SCENES.items()
                   if name != "SimpleInstancing"})  # GPU instances only: no texel
    base = Settings(rays=args.rays)
    print(f"{'scene':30s} {'before: black':>14s} {'cast':>6s} {'I_A':>9s}   "
          f"{'after: black':>13s} {'cast':>6s} {'I_A':>9s}  chosen")
    for name, path in scenes.items():
        before = measure(path, replace(base, escape="scene"))
        after = measure(path, base)
        print(f"{name:30s} {before['black']:14.1%} {before['cast']:6.1%} "
              f"{float(before['i_a'] @ LUMINANCE):9.3g}   {after['black']:13.1%} "
              f"{after['cast']:6.1%} {float(after['i_a'] @ LUMINANCE):9.3g}  "
              f"{after['chose'][:60]}")


if __name__ == "__main__":
    main()
