"""Benchmark: does ``--target-error E`` meet its target, with few rays? (issue 22 item 2)

For each scene, at each ``--target E``: the adaptive bake's lightmap luminance over the baked
texels (D + I_A · W, the direct light and the obscurance term) against a reference (the same
scene at ``--reference`` rays a texel of every kind, seed 2), and uniform bakes at 16, 32, …
``--max-rays`` rays of every kind (obscurance, shadow, emissive and sky rays alike; bisection
over powers of two: the error falls with the rays, so the first count that passes is found in
log₂ steps). Prints for each: the achieved RMSE, the share of texels with |error| ≤ E, the rays
a texel (obscurance and direct), and the ratio of the adaptive bake's rays to those of the
smallest uniform count meeting the same acceptance (RMSE ≤ E and ≥ 95 % of texels within E).
The reference's own error is taken out of the RMSE as ``study.calibration`` does; it cannot
be taken out of the share within E, so the reference has 8× ``--max-rays`` (at 4× the sky at
E = 0.002 seemed out of reach of 2048 rays: its errors were the reference's too). The adaptive
bake's first round is ``--rays`` of every kind.

The GI scene (``--method gi``: the lightmap is D + E_ind, rays counted are GI and shadow rays)
is judged at its own targets (``GI_TARGETS``), with ``--reference`` / 4 paths and at most
``--max-rays`` / 4 paths a texel (a path casts several rays).

    python benchmarks/bench_target_error.py [--target 0.004] [--max-rays 4096] [--only NAME]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench_calibration import SCENES, _probe_only  # noqa: E402

from baker.geometry.surface import LUMINANCE  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.image.compose import effective_r_ave  # noqa: E402
from baker.pipeline.full import compute  # noqa: E402
from baker.settings import Settings  # noqa: E402

NAMES = ("ceiling sqrt", "ceiling step, h = 0.9 d_max", "ceiling step, h = 0.3 d_max",
         "cornell (emissive lamp)", "soft light penumbra", "sky over a box",
         "gi, cornell (emissive lamp)")
GI_TARGETS = (0.08, 0.04, 0.02)  # path-traced GI is far noisier: its own targets


def lightmap_term(scene, settings: dict, scale=None, rays: int = 16,
                  **extra) -> tuple[np.ndarray, int, tuple]:
    """(N,) luminance of D + I_A · W at the baked texels with ``rays`` rays of every kind,
    the rays cast (obscurance and direct), and the (R_ave, lum I_A) used: ``scale``, by
    default this bake's own (I_A's estimate depends on the seed: every bake is judged at the
    reference's, so that only the texels' noise is measured). With ``method="gi"``: D + E_ind,
    ``rays`` paths, the GI and shadow rays cast (the obscurance's are not in the lightmap)."""
    counts = dict(rays=rays, shadow_rays=rays, emissive_rays=rays, sky_rays=rays)
    done = compute(scene, Settings(**{**settings, **counts, **extra}))
    if settings.get("method") == "gi":  # L = D + E_ind: the baked texels of the pages
        value = done.lightmaps.light[done.lightmaps.covered] @ LUMINANCE
        return value, done.tally.gi_rays + done.tally.shadow_rays, ()
    if scale is None:
        scale = (effective_r_ave(done.ambient, done.settings.rho),
                 float(done.ambient.intensity @ LUMINANCE))
    value = done.terms.obscurance(scale[0]) @ LUMINANCE * scale[1]
    if done.direct is not None:
        value = value + done.direct.irradiance() @ LUMINANCE
    rays = done.terms.rays + (done.direct.rays if done.direct is not None else 0)
    return value, rays, scale


def judged(value: np.ndarray, reference: np.ndarray, factor: float, target: float) -> dict:
    """RMSE (the reference's share, 1/factor of the variance, taken out) and share within E."""
    error = value - reference
    rmse = float(np.sqrt(np.mean(error ** 2) * factor / (factor + 1)))
    within = float(np.mean(np.abs(error) <= target))
    return {"rmse": rmse, "within": within, "ok": rmse <= target and within >= 0.95}


def best_uniform(scene, settings, scale, reference, factor, target, max_rays
                 ) -> tuple[int, dict, int]:
    """The smallest power-of-two ray count ≤ max_rays meeting the acceptance (bisection), its
    judgement and the rays its bake cast."""
    low, high = 4, int(np.log2(max_rays))  # 16 … max_rays
    found = None
    while low <= high:
        mid = (low + high) // 2
        value, rays, _ = lightmap_term(scene, settings, scale, rays=2 ** mid, seed=1)
        result = judged(value, reference, factor, target)
        if result["ok"]:
            found, high = (2 ** mid, result, rays), mid - 1
        else:
            low = mid + 1
    return found if found is not None else (0, {}, 0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--target", type=float, action="append")
    parser.add_argument("--rays", type=int, default=16, help="the adaptive first round")
    parser.add_argument("--max-rays", type=int, default=4096)
    parser.add_argument("--reference", type=int, default=32768)
    parser.add_argument("--only", action="append", help="a scene name (repeatable)")
    args = parser.parse_args()
    targets = args.target or [0.004]
    print("| scene | E | adaptive RMSE | within E | rays/texel | uniform N (RMSE, within) "
          "| adaptive ÷ uniform rays | s |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as folder:
        for name in args.only or NAMES:
            make, settings = SCENES[name]
            gi = settings.get("method") == "gi"
            most, most_reference = ((args.max_rays // 4, args.reference // 4) if gi
                                    else (args.max_rays, args.reference))
            scene = _probe_only(load(make().save(Path(folder) / "scene.glb")))
            reference, _, scale = lightmap_term(scene, settings, rays=most_reference, seed=2)
            for target in GI_TARGETS if gi else targets:
                start = time.perf_counter()
                factor = most_reference / most
                value, rays, _ = lightmap_term(scene, settings, scale, rays=args.rays, seed=1,
                                               target_error=target, max_rays=most)
                got = judged(value, reference, factor, target)
                count, uniform, uniform_rays = best_uniform(scene, settings, scale, reference,
                                                            factor, target, most)
                ratio = rays / uniform_rays if count else float("nan")
                shown = (f"{count} ({uniform['rmse']:.5f}, {100 * uniform['within']:.1f} %)"
                         if count else f"none ≤ {most}")
                print(f"| {name} | {target:g} | {got['rmse']:.5f} | {100 * got['within']:.1f} % "
                      f"| {rays / len(value):.1f} | {shown} | {ratio:.2f} "
                      f"| {time.perf_counter() - start:.0f} |", flush=True)


if __name__ == "__main__":
    main()
