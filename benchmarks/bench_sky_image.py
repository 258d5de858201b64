"""Benchmark: a sky image importance-sampled against cosine rays alone (issue 42).

A 3 m floor with a 0.6 m box on it under a sun-like panorama (``assets.sky_images.sun``: a
disc of 1° radius at 50° elevation, 2·10⁴ times brighter than the sky around it, over a
uniform sky and a darker ground). For every texel, the direct sky irradiance
(``direct_estimators.sky_irradiance``) with ``n`` rays: drawn by the image and the cosine half and
half (``Sky.draw``, what a bake does) or by the cosine alone (``image_share`` 0, as a constant sky's
rays are drawn). RMSE (luminance, over the texels) against a reference of ``--reference``
rays of the mixture with another seed. Then, for each count of the mixture, the cosine rays
that reach the same RMSE (the cosine's RMSE falls as n^-½ here: log-log interpolation of its
measured points, extrapolated with that slope past the last) and their ratio; issue 42 asks
for ≥ 10×. The same for a uniform image (where cosine rays are exact on the open floor and
nothing stands out of the image: no peak, and the bake's rays are the cosine's).

    python benchmarks/bench_sky_image.py [--reference 8192]
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

from assets import sky_images  # noqa: E402
from assets.light_scenes import floor_under_box  # noqa: E402
from baker.geometry.surface import LUMINANCE  # noqa: E402
from baker.light.direct import texel_receivers  # noqa: E402
from baker.light.direct_estimators import sky_irradiance  # noqa: E402
from baker.light.sky import Sky  # noqa: E402
from baker.rays.trace import Tracer  # noqa: E402
from tests.bakehelp import computed  # noqa: E402

BAKED_RAYS = (4, 8, 16, 32, 64)
COSINE_RAYS = (16, 64, 256, 1024, 4096)


def _rmse(sky: Sky, n: int, receivers, tracer, reference: np.ndarray, seed: int = 0) -> float:
    got, _ = sky_irradiance(sky, n, receivers, tracer, seed)
    return float(np.sqrt(np.mean(((got - reference) @ LUMINANCE) ** 2)))


def _cosine_rays_for(rmse: float, counts, errors) -> float:
    """The cosine rays at which the measured curve (counts, errors) reaches ``rmse``."""
    logn, loge = np.log(np.asarray(counts, float)), np.log(np.asarray(errors, float))
    if rmse <= errors[-1]:  # past the last point: the n^-1/2 of independent-ish rays
        return float(counts[-1] * (errors[-1] / rmse) ** 2)
    if rmse >= errors[0]:  # before the first, likewise
        return float(counts[0] * (errors[0] / rmse) ** 2)
    return float(np.exp(np.interp(np.log(rmse), loge[::-1], logn[::-1])))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference", type=int, default=8192)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        done = computed(floor_under_box(), Path(folder), texel_density=10.0, rays=2,
                        page_size=256)
    texels, tracer = done.texels, Tracer(done.world)  # the bake's tracer is not kept
    receivers = texel_receivers(texels, slice(None), tracer.center)
    print(f"{len(texels):,} texels (floor under a box)")
    for name, image in (("sun-like", sky_images.sun()), ("uniform", sky_images.constant(
            (0.5, 0.5, 0.5), height=64))):
        baked = Sky.of_image(image, 0.0, name)
        cosine = replace(baked, ceiling=np.inf, image_share=0.0)
        start = time.perf_counter()
        reference, _ = sky_irradiance(baked, args.reference, receivers, tracer, seed=7)
        print(f"\n{name}: image share {baked.image_share:.3f}, ceiling {baked.ceiling:.3g}; "
              f"reference {args.reference} rays a texel "
              f"({time.perf_counter() - start:.1f} s), mean luminance "
              f"{float(np.mean(reference @ LUMINANCE)):.4g}")
        cos_err = [_rmse(cosine, n, receivers, tracer, reference) for n in COSINE_RAYS]
        for n, e in zip(COSINE_RAYS, cos_err):
            print(f"  cosine  {n:5d} rays: RMSE {e:.4g}")
        for n in BAKED_RAYS:
            e = _rmse(baked, n, receivers, tracer, reference)
            same = _cosine_rays_for(e, COSINE_RAYS, cos_err)
            beyond = (f" (at {COSINE_RAYS[-1]} it is still {cos_err[-1] / e:,.0f}x above: "
                      f"at least {COSINE_RAYS[-1] / n:,.0f}x the rays measured)"
                      if e < cos_err[-1] else "")
            print(f"  baked   {n:5d} rays: RMSE {e:.4g}; cosine needs about {same:,.0f} rays "
                  f"for it: {same / n:,.1f}x the rays{beyond}")


if __name__ == "__main__":
    main()
