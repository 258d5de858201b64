"""The scene-wide terms of the obscurance model: average reflectivity and ambient intensity.

Equations (4) and (3) of Méndez-Feliu & Sbert, "Obscurances in general environments":

    R_ave = Σ A_i R_i / A_T            I_A = 1 / (1 − R_ave) · Σ A_i E_i / A_T

over every triangle of the scene (baked or not), per RGB channel. R_i and E_i are the mean albedo
and emission of triangle i, estimated at a few fixed points inside it (so textures count).

1 / (1 − R_ave) is the sum of the geometric series Σ R_ave^k of light bouncing around the scene.
As R_ave → 1 (a closed white room) it diverges — the model's stiff case. We sum the series only up
to ``MAX_BOUNCES`` terms, (1 − R^K) / (1 − R): identical to the closed form to 4 significant
digits for R ≤ 0.99, finite and continuous up to and including R = 1 (where it equals K), and
flagged in the report whenever the truncation changes I_A by more than 0.1 %.

With direct light baked apart (direct.py), the lightmap is L = D + I_A·W and I_A carries only
the light that has bounced at least once: I_A = R_ave·Σ_{k<K} R_ave^k · Φ / A_T, where Φ is the
power every source (punctual lights, emissive surfaces, sky) lays on the scene's surfaces, in
irradiance × area (``power.Power``). docs/direct_light.md derives it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from baker.context import Context
from baker.geometry.surface import albedo_means, emission_means

if TYPE_CHECKING:
    from baker.light.power import Power

MAX_BOUNCES = 1000



@dataclass(frozen=True)
class Ambient:
    """R_ave (3,), the area-weighted mean emission (3,), I_A (3,), and how I_A was chosen."""

    r_ave: np.ndarray
    mean_emission: np.ndarray
    intensity: np.ndarray
    source: str  # "user", "none" (no light in the scene: I_A = 1), "environment" (a neutral
    # one, environment.py: I_A = 1), or the sources I_A comes from: "emission" (equation 3
    # alone), or "+"-joined "lights", "emission", "sky" (with power)
    truncated: bool  # the bounce series was cut (R_ave close to 1)
    escape: np.ndarray | None = None  # (3,) what rays that meet nothing count; None: R_ave
    relative_variance: float = 0.0  # of I_A's estimate (I_A from the power of sources,
    # estimated at points, ``power.Power``); 0 when I_A is exact (the user's, equation 3)


def bounce_factor(r_ave: np.ndarray) -> tuple[np.ndarray, bool]:
    """Σ_{k<K} R^k per channel, and whether it differs from 1 / (1 − R) by more than 0.1 %."""
    r = np.clip(np.asarray(r_ave, np.float64), 0.0, 1.0)
    near_one = r > 1.0 - 1e-12
    safe = np.where(near_one, 0.5, r)
    series = np.where(near_one, float(MAX_BOUNCES), (1.0 - safe ** MAX_BOUNCES) / (1.0 - safe))
    closed = np.divide(1.0, 1.0 - r, out=np.full_like(r, np.inf), where=~near_one)
    return series, bool(np.any(series < 0.999 * closed))


def ambient_terms(context: Context, power: Power | None = None, neutral: bool = False
                  ) -> Ambient:
    """R_ave and I_A of the scene; the settings' ``ambient``, when given, overrides I_A (all
    channels).

    ``power``: what the direct-light sources lay on the surfaces (power.delivered_power); then
    I_A = R_ave·series·Φ/A_T, the light after its first bounce (D holds the direct light). Without
    it, equation (3) on the emissive surfaces alone, as when emission is not baked as direct light.
    ``neutral``: rays that meet nothing count white (``environment.environment``), and without
    punctual lights or sky I_A is 1, not what emissive surfaces would give.
    """
    ambient = _ambient_terms(context, power)
    if not neutral:
        return ambient
    unlit = power is None or not (len(power.punctual) or np.any(power.sky > 0))
    if unlit and ambient.source != "user":
        ambient = Ambient(ambient.r_ave, ambient.mean_emission, np.ones(3), "environment", False)
    return replace(ambient, escape=np.ones(3))


def _ambient_terms(context: Context, power: Power | None) -> Ambient:
    """``ambient_terms`` as the model has it, rays that meet nothing counting R_ave."""
    world, user_intensity = context.world, context.settings.ambient
    areas = world.areas()
    total = areas.sum()
    if total <= 0:
        zero = np.zeros(3)
        return Ambient(zero, zero, np.ones(3), "none", False)
    reflected = albedo_means(context.surfaces, world)
    emitted = emission_means(context.surfaces, world)
    r_ave = (areas[:, None] * reflected).sum(axis=0) / total
    mean_emission = (areas[:, None] * emitted).sum(axis=0) / total
    series, truncated = bounce_factor(r_ave)
    if user_intensity is not None:
        return Ambient(r_ave, mean_emission, np.full(3, float(user_intensity)), "user", False)
    if power is not None:
        names = power.sources()
        if not names:
            return Ambient(r_ave, mean_emission, np.ones(3), "none", False)
        bounced = r_ave * series * power.total() / total
        return Ambient(r_ave, mean_emission, bounced, "+".join(names), truncated,
                       relative_variance=power.relative_variance)
    if not np.any(mean_emission > 0):
        return Ambient(r_ave, mean_emission, np.ones(3), "none", False)
    return Ambient(r_ave, mean_emission, series * mean_emission, "emission", truncated)
