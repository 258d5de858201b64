"""Benchmark: one full net against two half nets for the obscurance (issue 22, ``netgain``).

Since d5adc2c a texel's n obscurance rays are two independently scrambled nets of n/2
(``sampling.fill_points``), so that the halves' difference measures the error without bias;
the cost is the mean's accuracy (a single net of n converges faster). This measures, in one
run and on the same texels, for each scene of ``bench_calibration.SCENES`` that bakes the
obscurance alone (no special materials) and each ``--rays`` n:

- "halves": RMSE of the shipped design (``integrate``) against a reference of ``--reference``
  × n rays (seed 2), and its reported ÷ measured RMSE (``Terms.rmse``);
- "net": RMSE of one Owen-scrambled net of n (``sampling.sample_2d``, the scrambles of
  ``OBSCURANCE``: the design before d5adc2c) against the same reference;
- the candidate estimate for "net": its own halves' e² (biased high: a net's halves are
  anti-correlated) × a gain c measured on a seeded 1/``--every`` of the texels that get one
  more independent net of n (seed 3): c = Σ (m_net − m_extra)²/2 ÷ Σ e²; reported ÷ measured
  overall and in the four quarters of the texels (in ``Texels`` order: regions of the atlas),
  which shows whether one c fits the whole scene;
- per texel, the share within 2σ / 3σ of each design's error map (its e², c·e² for "net",
  pooled over the 5 × 5 window as ``errormap.texel_errors`` pools them, the reference's
  added in quadrature; obscurance alone, without I_A's error).

Lightmap units (I_A · luminance of W). Costs 1/``--every`` more rays where used.

    python benchmarks/bench_netgain.py [--rays 64 --rays 256] [--reference 16] [--every 16]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_calibration import SCENES, _probe_only  # noqa: E402

from baker.geometry.surface import LUMINANCE  # noqa: E402
from baker.gltf.load import load  # noqa: E402
from baker.image.compose import effective_r_ave  # noqa: E402
from baker.image.errormap import pooled  # noqa: E402
from baker.light.hemisphere import (  # noqa: E402
    _TEXEL_MAJOR, accumulate_kernel, hit_shading, surfaces_of, world_rays)
from baker.light.integrate import integrate  # noqa: E402
from baker.light.obscurance import RHO_KINDS  # noqa: E402
from baker.pipeline.full import compute  # noqa: E402
from baker.rays.dimensions import OBSCURANCE  # noqa: E402
from baker.rays.sampling import cosine_hemisphere, hash_u32, sample_2d  # noqa: E402
from baker.rays.trace import Tracer  # noqa: E402
from baker.settings import Settings  # noqa: E402

_CHUNK = 4096  # texels whose rays are held at once


def net_values(done, tracer, surfaces, rows: np.ndarray, rays: int, seed: int, lum: float
               ) -> np.ndarray:
    """(k, rays) luminance of W per ray for the texels ``rows`` (k,), the rays one scrambled
    net of ``rays`` per texel (seed ``seed``), shaded as ``accumulate_kernel`` shades them
    (one ray per row of its sums)."""
    settings = done.settings
    out = np.empty((len(rows), rays))
    for start in range(0, len(rows), _CHUNK):
        part = rows[start:start + _CHUNK]
        points = sample_2d(seed, done.texels.key[part][:, None], np.arange(rays)[None, :],
                           OBSCURANCE)
        local = cosine_hemisphere(points).reshape(-1, 3)
        origins, directions = world_rays(done.texels, part, np.repeat(np.arange(len(part)), rays),
                                         local[:, 0].copy(), local[:, 1].copy(),
                                         local[:, 2].copy(), tracer.center,
                                         np.tile(np.arange(rays), len(part)))
        hits = tracer.cast_local(origins, directions,
                                 np.full(len(origins), settings.d_max, np.float32))
        kind, albedo = hit_shading(surfaces, settings, hits)
        sums = np.zeros((len(origins), 7))
        accumulate_kernel(1, hits.triangle, hits.distance, np.float32(settings.d_max),
                          RHO_KINDS[settings.rho], surfaces.table, kind, albedo, LUMINANCE,
                          sums, *_TEXEL_MAJOR, 1.0)
        out[start:start + len(part)] = (sums[:, :3] @ LUMINANCE + lum * sums[:, 3]).reshape(
            len(part), rays)
    return out


def coverage(done, own: np.ndarray, error: np.ndarray) -> tuple[float, float]:
    """Shares of texels with |``error``| (N,) within 2 and 3 of their error-map value, the
    map pooled from the variances ``own`` (N,) as ``errormap.texel_errors`` pools them."""
    atlas = done.atlas
    around = pooled(own, done.texels.pixels(), (atlas.page_count, atlas.height, atlas.width))
    sigma = np.sqrt(around * own.sum() / max(around.sum(), 1e-300))
    return (float(np.mean(np.abs(error) <= 2 * sigma)),
            float(np.mean(np.abs(error) <= 3 * sigma)))


def compare(name: str, rays: int, factor: int, every: int, folder: Path) -> dict:
    """The figures of the module docstring for scene ``name`` at ``rays`` rays."""
    make, overrides = SCENES[name]
    scene = _probe_only(load(make().save(folder / "scene.glb")))
    done = compute(scene, Settings(rays=rays, seed=1, **overrides))
    context = done.context()
    tracer, surfaces = context.tracer, surfaces_of(context)
    assert not surfaces.special, name
    r_ave = effective_r_ave(done.ambient, done.settings.rho)
    lum, intensity = float(r_ave @ LUMINANCE), float(done.ambient.intensity @ LUMINANCE)

    def bake(count: int, seed: int):
        settings = replace(done.settings, rays=count, seed=seed, target_error=None)
        return integrate(context.with_settings(settings), done.texels)

    fine = bake(rays * factor, 2)
    reference = (fine.obscurance(r_ave) @ LUMINANCE) * intensity
    fine_e2 = fine.split_errors(r_ave) * intensity ** 2
    halves = bake(rays, 1)
    rows = np.arange(len(done.texels))
    values = net_values(done, tracer, surfaces, rows, rays, 1, lum) * intensity
    net = values.mean(axis=1)
    half = rays // 2
    e2 = (0.5 * (values[:, :half].mean(axis=1) - values[:, half:].mean(axis=1))) ** 2
    subset = np.flatnonzero(hash_u32(np.uint64(1), done.texels.key, np.uint64(0x6E6574))
                            % np.uint32(every) == 0)
    extra = net_values(done, tracer, surfaces, subset, rays, 3, lum).mean(axis=1) * intensity
    gain = float(np.sum((net[subset] - extra) ** 2) / 2 / max(np.sum(e2[subset]), 1e-300))

    def rmse(x):
        return float(np.sqrt(np.mean(x)))

    measured_net = rmse((net - reference) ** 2)
    halves_error = (halves.obscurance(r_ave) @ LUMINANCE) * intensity - reference
    measured_halves = rmse(halves_error ** 2)
    quarters = [float(np.sqrt(gain * np.mean(e2[q]) / np.mean((net[q] - reference[q]) ** 2)))
                for q in np.array_split(rows, 4)]
    return {"texels": len(rows), "subset": len(subset), "halves": measured_halves,
            "halves ratio": halves.rmse(r_ave) * intensity / measured_halves,
            "net": measured_net, "gain": gain,
            "net ratio": rmse(gain * e2) / measured_net, "quarters": quarters,
            "halves cover": coverage(done, halves.split_errors(r_ave) * intensity ** 2
                                     + fine_e2, halves_error),
            "net cover": coverage(done, gain * e2 + fine_e2, net - reference)}


def _shares(pair: tuple[float, float]) -> str:
    return f"{pair[0]:.1%}/{pair[1]:.1%}".replace("%", "", 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, action="append")
    parser.add_argument("--reference", type=int, default=16, help="reference rays / --rays")
    parser.add_argument("--every", type=int, default=16,
                        help="one texel in this many gets a second net, for c")
    parser.add_argument("--only", action="append", help="a scene name (repeatable)")
    args = parser.parse_args()
    names = args.only or [n for n, (_, s) in SCENES.items() if s.get("method") != "gi"
                          and "light" not in n and "sky" not in n]
    print(f"{'scene':30} {'rays':>5} {'texels':>6} {'subset':>6} {'halves':>9} {'ratio':>6} "
          f"{'net':>9} {'net/h':>6} {'gain c':>7} {'ratio':>6} {'h 2σ/3σ':>11} {'net 2σ/3σ':>11}"
          "  quarters' ratios")
    with tempfile.TemporaryDirectory() as folder:
        for rays in args.rays or [64]:
            for name in names:
                r = compare(name, rays, args.reference, args.every, Path(folder))
                print(f"{name:30} {rays:5d} {r['texels']:6d} {r['subset']:6d} "
                      f"{r['halves']:9.3g} {r['halves ratio']:6.2f} {r['net']:9.3g} "
                      f"{r['net'] / r['halves']:6.2f} {r['gain']:7.3f} {r['net ratio']:6.2f} "
                      f"{_shares(r['halves cover']):>11} {_shares(r['net cover']):>11}  "
                      + " ".join(f"{q:.2f}" for q in r["quarters"]), flush=True)


if __name__ == "__main__":
    main()
