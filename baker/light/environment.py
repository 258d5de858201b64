"""What surrounds the scene: the colour that obscurance rays meeting nothing count, by default.

The obscurance model (docs/model.md) counts R_ave, the scene's mean albedo, for a ray that meets
nothing within d_max: in a closed level that stands for the rest of the level, which reflects
about R_ave of the light. Around a lone prop there is nothing: counting R_ave multiplies the
prop's albedo by its own mean colour (a red box's lightmap comes out red, a duck's blue channel 0),
and a prop lit only by its emissive decals gets I_A from them (1.4e-5 for DamagedHelmet: 94 % of
its texels black).

So ``environment`` looks at the scene first: from ``POWER_POINTS`` points spread over its
surfaces by area, one cosine-distributed ray each, the share that meets nothing at any distance.
With ``escape = "auto"`` (the default), a scene where at least ``OPEN_SHARE`` of them escape, and
with no punctual light and no sky, is *open* (a prop, or an open-air scene lit by nothing): its
rays that meet nothing count white, a neutral environment, and I_A is 1 (the lightmap is W, an
open surface 1), whatever emits; its emissive surfaces still light their surroundings as direct
light. Any other scene keeps R_ave and I_A as the model has them. ``escape = "white"`` or
``"scene"`` chooses either whatever the scene is. The choice and its reason are in the plan.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from baker.geometry.world import World
from baker.light.direct_estimators import sky_irradiance
from baker.light.power import power_points
from baker.light.sources import Sources
from baker.light.sky import Sky
from baker.rays.trace import Tracer

OPEN_SHARE = 0.5
"""Share of the surfaces' cosine rays that escape, at or above which a scene is open."""
_WHITE_SKY = Sky.of_gradient(np.ones(3))


@dataclass(frozen=True)
class Environment:
    """escaped: the share of cosine-distributed rays from the scene's surfaces that meet nothing
    at any distance (NaN when not measured). neutral: rays that meet nothing count white and,
    without punctual lights or sky, I_A is 1. reason: why, for the plan and the report."""

    escaped: float
    neutral: bool
    reason: str


def escaped_share(world: World, tracer: Tracer, seed: int) -> float:
    """The share of cosine-distributed rays from points spread by area over every triangle's
    front face that meet nothing at any distance (π·E under a white sky of radiance 1 is 1)."""
    if not len(world.triangles) or world.areas().sum() <= 0:
        return 1.0
    _, _, receivers = power_points(world, seed)
    irradiance, _ = sky_irradiance(_WHITE_SKY, 1, receivers, tracer, seed)
    return float(irradiance[:, 0].mean() / np.pi)


def environment(world: World, tracer: Tracer, sources: Sources, escape: str,
                seed: int) -> Environment:
    """What rays that meet nothing count here (see the module's docstring)."""
    if escape == "white":
        return Environment(float("nan"), True, "white, a neutral environment (--escape white)")
    if escape == "scene":
        return Environment(float("nan"), False, "R_ave, the scene's mean albedo (--escape scene)")
    share = escaped_share(world, tracer, seed)
    seen = f"{share:.0%} of rays from its surfaces escape"
    lit = len(sources.lights) > 0 or sources.sky is not None
    if share >= OPEN_SHARE and not lit:
        emitting = " but emission" if sources.emitters is not None else ""
        return Environment(share, True, f"white, a neutral environment: the scene is open ({seen}) "
                                        f"and has no light{emitting} (--escape scene: R_ave)")
    why = (f"enclosed ({seen})" if share < OPEN_SHARE
           else f"open ({seen}) but lit by its lights or sky")
    return Environment(share, False, f"R_ave, the scene's mean albedo: {why} (--escape white: a "
                                     "neutral environment)")
