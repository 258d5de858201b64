"""Error against run time: the convergence study behind ``baker study`` (docs/design.md §6).

The scene is unwrapped and rasterised once; then, for each sampling technique and each number
of rays per texel, the obscurance terms are estimated again and timed. Each run's lightmap
(I_A·W, luminance) is compared with a converged reference — the same estimator with many more
rays — to give the measured RMSE, next to the RMSE the bake itself estimates from its samples'
variance (what every bake reports). Units are lightmap units, as in the report.

``calibration`` asks the other question, whether those estimates hold: a bake's estimated
error against its measured one, texel by texel (docs/model.md, ``benchmarks/bench_calibration.py``).
"""

from __future__ import annotations

import io
import time
from dataclasses import dataclass, replace

import numpy as np

from baker.geometry.surface import luminance
from baker.gltf.scene import Scene
from baker.image.compose import effective_r_ave
from baker.image.errormap import texel_errors
from baker.light.direct import texel_receivers
from baker.light.direct_estimators import sky_irradiance
from baker.light.gi import indirect_light
from baker.light.hemisphere import Terms
from baker.light.integrate import integrate
from baker.pipeline.full import Computed, compute
from baker.rays.trace import Tracer
from baker.settings import STUDY_RAYS, TECHNIQUES, Settings

DEFAULT_RAYS = STUDY_RAYS


@dataclass(frozen=True)
class Row:
    """One run of the study: a technique at ``rays`` per texel."""

    technique: str
    rays: int
    seconds: float  # wall time of the integration alone
    rmse: float  # measured against the reference, lightmap units
    estimated_rmse: float  # from the run's own sample variance

    def as_dict(self) -> dict:
        return {"technique": self.technique, "rays": self.rays, "seconds": self.seconds,
                "rmse": self.rmse, "estimated_rmse": self.estimated_rmse}


@dataclass(frozen=True)
class Study:
    """The study's table, its reference, and the fitted convergence rate per technique."""

    rows: tuple[Row, ...]
    texels: int
    reference_rays: int
    reference_seconds: float
    gi: dict | None = None  # obscurances against full GI (``compare_with_gi``)
    sky: tuple[Row, ...] = ()  # an image sky's direct light, as baked and by cosine rays
    # alone (``sky_rows``), against its own reference
    directional: tuple[Row, ...] = ()  # with directional pages: the obscurance's first
    # moment U (``light.directional``) of each technique's runs against the reference's
    def slope(self, technique: str, min_rays: int = 16) -> float:
        """Least-squares slope of log RMSE against log rays (−0.5 for plain Monte Carlo)."""
        rows = [r for r in self.rows + self.sky + self.directional if r.technique == technique
                and r.rays >= min_rays and r.rmse > 0]
        x = np.log([r.rays for r in rows])
        y = np.log([r.rmse for r in rows])
        return float(np.polyfit(x, y, 1)[0])

    def table(self) -> str:
        """The table as aligned text, one run per line, then the slopes."""
        lines = [f"{'technique':<11}{'rays':>6}{'seconds':>10}{'RMSE':>12}{'estimated':>12}"]
        for r in self.rows:
            lines.append(f"{r.technique:<11}{r.rays:>6}{r.seconds:>10.3f}{r.rmse:>12.3e}"
                         f"{r.estimated_rmse:>12.3e}")
        for r in self.sky + self.directional:
            lines.append(f"{r.technique:<11}{r.rays:>6}{r.seconds:>10.3f}{r.rmse:>12.3e}"
                         f"{r.estimated_rmse:>12.3e}")
        for technique in dict.fromkeys(r.technique for r in self.rows + self.sky
                                       + self.directional):
            lines.append(f"{technique}: RMSE ∝ rays^{self.slope(technique):.2f}")
        lines.append(f"reference: {self.reference_rays} rays/texel (sobol), "
                     f"{self.reference_seconds:.1f} s, {self.texels:,} texels")
        if self.gi:
            g = self.gi
            lines.append(
                f"obscurances ({g['rays']} rays, {g['obscurance_seconds']:.2f} s) against full GI "
                f"({g['paths']} paths, {g['gi_seconds']:.2f} s, {g['gi_seconds'] / max(g['obscurance_seconds'], 1e-9):.0f}× the time): "
                f"lightmap RMSE {g['rmse']:.3g} = {g['relative']:.1%} of the GI lightmap's mean "
                f"{g['gi_mean']:.3g}; mean obscurance/GI indirect light {g['indirect_ratio']:.2f}")
        return "\n".join(lines)

    def as_dict(self) -> dict:
        return {"texels": self.texels, "reference_rays": self.reference_rays, "gi": self.gi,
                "reference_seconds": self.reference_seconds,
                "rows": [r.as_dict() for r in self.rows], "sky": [r.as_dict() for r in self.sky],
                "directional": [r.as_dict() for r in self.directional],
                "slopes": {t: self.slope(t) for t in dict.fromkeys(
                    r.technique for r in self.rows + self.sky + self.directional)}}


def _luminance(done: Computed, terms: Terms) -> np.ndarray:
    """(N,) lightmap luminance I_A·W of the terms."""
    w = terms.obscurance(effective_r_ave(done.ambient, done.settings.rho))
    return luminance(w) * float(luminance(done.ambient.intensity))


def _estimated_rmse(done: Computed, terms: Terms) -> float:
    """The RMSE a bake would report for these terms (obscurance part, lightmap units)."""
    rmse = terms.rmse(effective_r_ave(done.ambient, done.settings.rho))
    return rmse * float(luminance(done.ambient.intensity))


def run_study(done: Computed, rays: tuple[int, ...] = DEFAULT_RAYS,
              techniques: tuple[str, ...] = TECHNIQUES, reference_rays: int = 4096,
              progress=None) -> Study:
    """Time and measure every (technique, rays) run on the texels of ``done``.

    ``done`` is a bake computed up to its lightmaps (``bake.compute``); its settings (d_max, ρ,
    seed, threads) are kept, only the rays and the technique change. ``progress(text)`` is told
    of each run as it starts.
    """
    context = done.context()

    def estimate(technique: str, count: int) -> tuple[Terms, float]:
        settings = replace(done.settings, rays=count, sampling=technique, target_error=None)
        started = time.perf_counter()
        terms = integrate(context.with_settings(settings), done.texels)
        return terms, time.perf_counter() - started

    if progress:
        progress(f"reference: {reference_rays} rays per texel")
    reference_terms, reference_seconds = estimate("sobol", reference_rays)
    reference = _luminance(done, reference_terms)
    rows, aims = [], []
    for technique in techniques:
        for count in rays:
            if progress:
                progress(f"{technique}, {count} rays per texel")
            terms, seconds = estimate(technique, count)
            rmse = float(np.sqrt(np.mean((_luminance(done, terms) - reference) ** 2)))
            rows.append(Row(technique, count, seconds, rmse, _estimated_rmse(done, terms)))
            if len(terms.aim_hit):
                aims.append(_aim_row(done, technique, count, seconds, terms, reference_terms))
    return Study(tuple(rows), len(done.texels), reference_rays, reference_seconds,
                 directional=tuple(aims))


def _aim_row(done: Computed, technique: str, count: int, seconds: float, terms: Terms,
             reference: Terms) -> Row:
    """A run's row for the obscurance's first moment U (directional pages), in lightmap
    luminance (× I_A's): the RMS length of its difference from the reference's, and the
    estimate from the rays' halves (``Terms.aim_errors``)."""
    r_ave = effective_r_ave(done.ambient, done.settings.rho)
    scale = float(luminance(done.ambient.intensity))
    gap = (terms.aim(r_ave) - reference.aim(r_ave)) * scale
    rmse = float(np.sqrt(np.mean(np.sum(gap * gap, axis=1))))
    return Row(f"U {technique}", count, seconds, rmse,
               float(np.sqrt(np.mean(terms.aim_errors(r_ave)))) * scale)


_COLOURS = {"sobol": (31, 119, 180), "stratified": (255, 127, 14), "random": (44, 160, 44),
            "gi": (214, 39, 40), "sky image": (148, 103, 189), "sky cosine": (140, 86, 75)}


def sky_rows(done: Computed, rays: tuple[int, ...] = DEFAULT_RAYS,
             reference_rays: int = 4096) -> tuple[Row, ...]:
    """The direct sky light of ``done``'s texels (an image sky: ``--sky-image``) at each of
    ``rays`` rays per texel, drawn as a bake draws them ("sky image": the image's peak by the
    image, light/sky.py) and by cosine rays alone ("sky cosine", as a colour sky's), each timed
    and measured (luminance RMSE) against ``reference_rays`` of the bake's rays, another
    seed; the estimated RMSE from the rays' halves (``direct_estimators.mean_and_variance``). Empty
    without an image sky."""
    sky = done.sources.sky if done.sources is not None else None
    if sky is None or not sky.is_image:
        return ()
    tracer = Tracer(done.world)
    receivers = texel_receivers(done.texels, slice(None), tracer.center)
    reference, _ = sky_irradiance(sky, reference_rays, receivers, tracer, done.settings.seed + 1)
    rows = []
    for name, drawn in (("sky image", sky), ("sky cosine", replace(sky, ceiling=np.inf,
                                                                     image_share=0.0))):
        for count in rays:
            started = time.perf_counter()
            got, variance = sky_irradiance(drawn, count, receivers, tracer, done.settings.seed)
            seconds = time.perf_counter() - started
            rmse = float(np.sqrt(np.mean(luminance(got - reference) ** 2)))
            rows.append(Row(name, count, seconds, rmse, float(np.sqrt(np.mean(variance)))))
    return tuple(rows)


def plot(study: Study, size: tuple[int, int] = (800, 560)) -> bytes:
    """PNG bytes: RMSE (measured: solid, estimated: dashed) against seconds, log–log axes."""
    from PIL import Image, ImageDraw

    width, height = size
    left, right, top, bottom = 80, 20, 40, 60
    rows = [r for r in study.rows + study.sky + study.directional
            if r.seconds > 0 and r.rmse > 0]
    xs = np.log10([r.seconds for r in rows])
    ys = np.log10([v for r in rows for v in (r.rmse, r.estimated_rmse) if v > 0])
    x0, x1 = np.floor(xs.min()), np.ceil(xs.max())
    y0, y1 = np.floor(ys.min()), np.ceil(ys.max())

    def at(seconds: float, rmse: float) -> tuple[float, float]:
        fx = (np.log10(seconds) - x0) / max(x1 - x0, 1e-9)
        fy = (np.log10(rmse) - y0) / max(y1 - y0, 1e-9)
        return left + fx * (width - left - right), height - bottom - fy * (height - top - bottom)

    image = Image.new("RGB", size, "white")
    draw = ImageDraw.Draw(image)
    for decade in range(int(x0), int(x1) + 1):
        x, _ = at(10.0 ** decade, 10.0 ** y0)
        draw.line([(x, top), (x, height - bottom)], fill=(225, 225, 225))
        draw.text((x - 12, height - bottom + 6), f"1e{decade}", fill="black")
    for decade in range(int(y0), int(y1) + 1):
        _, y = at(10.0 ** x0, 10.0 ** decade)
        draw.line([(left, y), (width - right, y)], fill=(225, 225, 225))
        draw.text((left - 40, y - 6), f"1e{decade}", fill="black")
    draw.rectangle([left, top, width - right, height - bottom], outline="black")
    draw.text((width // 2 - 60, height - 24), "seconds (log)", fill="black")
    draw.text((8, top - 28), "RMSE, lightmap units (log): measured solid, estimated dashed",
              fill="black")
    for n, technique in enumerate(dict.fromkeys(r.technique for r in rows)):
        colour = _COLOURS.get(technique, (0, 0, 0))
        mine = [r for r in rows if r.technique == technique]
        draw.line([at(r.seconds, r.rmse) for r in mine], fill=colour, width=3)
        estimated = [at(r.seconds, r.estimated_rmse) for r in mine if r.estimated_rmse > 0]
        for a, b in zip(estimated[:-1], estimated[1:]):
            middle = ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2)
            draw.line([a, middle], fill=colour, width=1)
        draw.text((width - right - 150, top + 10 + 16 * n),
                  f"{technique} (rays^{study.slope(technique):.2f})", fill=colour)
    buffer = io.BytesIO()
    image.save(buffer, "PNG")
    return buffer.getvalue()


def compare_with_gi(done: Computed, rays: int = 64, paths: int = 256) -> dict:
    """How far the obscurance lightmap D + I_A·W sits from full GI, D + E_ind, and at what cost.

    The paper's figure 13 comparison, on the bake's own texels and direct light: the obscurance
    terms at ``rays`` Sobol rays per texel against the path tracer (gi.py) at ``paths`` paths.
    Returns the lightmaps' RMSE (luminance, lightmap units), that RMSE over the GI lightmap's
    mean, the ratio of the mean indirect light of both, and the seconds each took.
    """
    context = done.context(replace(done.settings, rays=rays, sampling="sobol",
                                   target_error=None))
    started = time.perf_counter()
    terms = integrate(context, done.texels)
    obscurance_seconds = time.perf_counter() - started
    started = time.perf_counter()
    indirect = luminance(indirect_light(context, done.sources, done.texels,
                                        paths).irradiance)
    gi_seconds = time.perf_counter() - started
    lit = luminance(done.direct.irradiance()) if done.direct is not None else 0.0
    ambient = _luminance(done, terms)
    gi = lit + indirect
    rmse = float(np.sqrt(np.mean((lit + ambient - gi) ** 2)))
    return {"rays": rays, "paths": paths, "obscurance_seconds": obscurance_seconds,
            "gi_seconds": gi_seconds, "rmse": rmse, "gi_mean": float(gi.mean()),
            "relative": rmse / max(float(gi.mean()), 1e-30),
            "indirect_ratio": float(ambient.mean() / max(indirect.mean(), 1e-30))}


_ROUNDING = 2.0 ** -23  # float32's relative rounding: two bakes of an exact texel may differ by it
_RAY_KINDS = ("shadow_rays", "emissive_rays", "sky_rays")  # with ``rays``: every term's rays


def _calibration_bake(scene: Scene, settings: dict, rays: int, seed: int
                      ) -> tuple[np.ndarray, np.ndarray, float]:
    """A bake of ``scene`` at ``rays`` rays of every kind (I_A's power estimate follows them,
    ``power.power_samples``): the baked texels' lightmap luminance, their ``texel_errors`` and
    the ``rmse_estimate``."""
    done = compute(scene, Settings(rays=rays, seed=seed,
                                   **{**settings, **dict.fromkeys(_RAY_KINDS, rays)}))
    covered = done.lightmaps.covered
    pages = np.zeros(covered.shape)
    pages[done.texels.pixels()] = texel_errors(done)
    return luminance(done.lightmaps.light)[covered], pages[covered], done.rmse_estimate()


def calibration(scene: Scene, settings: dict, rays: int, factor: int) -> dict:
    """Do a bake's error estimates hold? (issue 22; ``benchmarks/bench_calibration.py``)

    Bakes ``scene`` with ``settings`` (a dict of ``Settings`` fields) at ``rays`` rays of
    every kind a texel (obscurance rays or GI paths, shadow, emissive and sky rays), seed 1,
    and a reference with ``factor`` × as many of each (and so of I_A's power samples),
    seed 2. Returns, over the baked texels' post-processed lightmap luminance: "reported"
    (the bake's ``rmse_estimate``), "measured" (the RMS difference × sqrt(f/(f + 1)): the
    reference's error taken out as if it fell as 1/sqrt(rays)), their "ratio", "2σ" and "3σ"
    (the share of texels within 2 and 3 of their error-map value, the reference's added in
    quadrature; an exact texel counts within), "reference" (its ``rmse_estimate``), "texels".
    """
    value, sigma, reported = _calibration_bake(scene, settings, rays, 1)
    ref_value, ref_sigma, ref_reported = _calibration_bake(scene, settings, rays * factor, 2)
    error = value - ref_value
    measured = float(np.sqrt(np.mean(error ** 2) * factor / (factor + 1)))
    band = np.sqrt(sigma ** 2 + ref_sigma ** 2) + _ROUNDING * np.abs(ref_value)
    return {"reported": reported, "measured": measured, "reference": ref_reported,
            "ratio": reported / measured if measured > 0 else float("inf"),
            "2σ": float(np.mean(np.abs(error) <= 2 * band)),
            "3σ": float(np.mean(np.abs(error) <= 3 * band)), "texels": len(value)}
