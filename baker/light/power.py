"""The power each source lays on the scene's surfaces, for the ambient intensity I_A
(``delivered_power``, docs/direct_light.md): the estimators of ``direct_estimators`` at points
spread over every triangle by area (``power_points``), or traced from the sources where few
points see them."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from baker.context import Context
from baker.geometry.surface import luminance
from baker.geometry.world import World
from baker.light.direct_estimators import (
    Receivers,
    cone_directions,
    emissive_irradiance,
    emitter_radiance,
    punctual_irradiance,
    range_window,
    sky_irradiance,
    spot_attenuation,
)
from baker.light.sources import Emitters, Sources, all_sources
from baker.punctual import Light
from baker.rays.dimensions import POWER, POWER_TRACED, light_dimension
from baker.rays.sampling import cosine_hemisphere, sample_2d, split_samples, tangent_frames
from baker.rays.trace import Tracer, ray_lift
from baker.settings import DEFAULT_RAYS, Resolved


# Samples of each source's power for I_A at ``DEFAULT_RAYS`` rays a texel (``power_samples``).
POWER_POINTS = 16384


# Keys of the power-estimate points, apart from texel keys ((page·h + y)·w + x, far below 2^62),
# and of the sources whose power is traced from them (``TRACED_GROUPS`` keys each, above every
# point's): each key's rays are an independent net, so their means' spread is the estimate's.
_POWER_KEY_BASE = np.uint64(1 << 62)


_TRACED_KEY_BASE = np.uint64(3 << 61)


TRACED_GROUPS = 16


@dataclass(frozen=True)
class Power:
    """The power each source lays on the scene's surfaces (irradiance integrated over area).

    punctual: (L,) float64 per light at unit intensity and white colour; light_colours: (L, 3)
    colour × intensity as baked; emission: (3,) from emissive surfaces; sky: (3,) from the sky.
    area: A_T, the scene's total triangle area. Units: irradiance × scene units².
    relative_variance: the variance of the estimate of the total's luminance over its square,
    which I_A inherits (``ambient.Ambient``): the points fall one in each of equal strata of
    the surface (``power_points``), so, taking neighbouring strata two by two as one stratum
    of two points, Σ (D_a − D_b)² / P² over the pairs (E[(D_a − D_b)²] = σ_a² + σ_b², the
    variance of the pair's sum; D the points' luminance at the baked colours). Their sample
    variance over P, which treats them as independent, was 1.5–3× too high (the Cornell room,
    the sky over a box: 40 seeds).
    """

    punctual: np.ndarray
    light_colours: np.ndarray
    emission: np.ndarray
    sky: np.ndarray
    area: float
    relative_variance: float = 0.0

    def total(self, light_colours: np.ndarray | None = None) -> np.ndarray:
        """(3,) power from every source, with light colours × intensities (L, 3) if given."""
        return all_sources(self, light_colours)

    def sources(self) -> tuple[str, ...]:
        """Which kinds of source the scene has: of "lights", "emission", "sky"."""
        names = []
        if len(self.punctual):
            names.append("lights")
        if np.any(self.emission > 0):
            names.append("emission")
        if np.any(self.sky > 0):
            names.append("sky")
        return tuple(names)


def power_points(world: World, seed: int,
                 count: int | None = None) -> tuple[np.ndarray, np.ndarray, Receivers]:
    """``count`` points (None: ``POWER_POINTS``, as it is when called) spread over every
    triangle by area (systematic sampling): their triangles (count,), barycentrics (count, 3)
    and the Receivers they make."""
    count = POWER_POINTS if count is None else count
    areas = world.areas()
    total = areas.sum()
    keys = _POWER_KEY_BASE + np.arange(count, dtype=np.uint64)
    u = sample_2d(seed, keys, 0, POWER[0])
    target = (np.arange(count) + u[:, 0]) / count * total
    tris = np.minimum(np.searchsorted(np.cumsum(areas), target, side="right"), len(areas) - 1)
    v = sample_2d(seed, keys, 0, POWER[1])
    root = np.sqrt(v[:, 0])
    bary = np.stack([1.0 - root, v[:, 1] * root, (1.0 - v[:, 1]) * root], axis=1)
    a, b, c = world.corners(tris)
    position = bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c
    normal = world.geometric_normals(tris)
    size = np.sqrt(areas[tris])
    return tris, bary, Receivers(position=position, normal=normal, geometric=normal,
                                 lift=ray_lift(position, size, world.center), key=keys)


_MOST_POWER_BLOCKS = 64
"""``power_samples`` grows with the rays up to 64 × ``POWER_POINTS`` (1,048,576 points, at
4,096 rays a texel): 16.7 M points (65,536 rays) took 4.5 GB and 15 s; past it I_A's error,
which the estimate reports (``Power.relative_variance``), stays as at 4,096 rays."""


def power_samples(settings: Resolved) -> int:
    """How many samples estimate each source's power for I_A: ``POWER_POINTS`` at
    ``DEFAULT_RAYS`` rays a texel and in proportion above (``--rays``, or with
    ``--target-error`` the most a texel may get), so that I_A's error falls with the work asked
    as every texel's does, up to ``_MOST_POWER_BLOCKS`` times."""
    rays = settings.max_rays if settings.target_error is not None else settings.rays
    return POWER_POINTS * min(max(1, -(-int(rays) // DEFAULT_RAYS)), _MOST_POWER_BLOCKS)


def delivered_power(context: Context, sources: Sources) -> Power:
    """Estimate the power each source lays on all the scene's surfaces (baked or not).

    Φ = ∫ D dA over every triangle's front face, with ``power_samples`` samples a source, two
    ways: A_T × the mean of D at points spread by area (``power_points``, one sample of each
    source at each), and for point and spot lights and the emitters also by rays of their own
    (``_traced_light_power``, ``_traced_emitter_power``): the power they send towards the front
    faces their rays meet first. Each such source keeps the estimate of the two with the
    smaller estimated variance: in a closed room the traced one, exact (every ray meets a
    front face) where the points beside a lamp have a 1/r² tail (3 % of I_A at 16,384 points
    in a lamp-lit room); around a small lit patch in the open, the points (most traced rays
    miss it). Directional lights and the sky light every open surface evenly: points. Every
    sample is deterministic (sampler keys of their own), so I_A is too; its relative variance
    comes from the two halves of each traced source's rays (two independent nets) and from
    the points' neighbouring strata taken two by two (``Power``).
    """
    world, tracer, settings = context.world, context.tracer, context.settings
    lights = len(sources.lights)
    area = float(world.areas().sum()) if len(world.triangles) else 0.0
    punctual, emitted, sky = np.zeros(lights), np.zeros(3), np.zeros(3)
    colours = sources.light_colours()
    variance = 0.0  # of the total's luminance
    if area > 0 and sources.any():
        count = power_samples(settings)
        _, _, receivers = power_points(world, settings.seed, count)
        seen = np.zeros(count)  # each point's luminance of D from the sources points estimate
        for l, light in enumerate(sources.lights):
            mean, _ = punctual_irradiance(light, float(sources.spread[l]), 1, receivers, tracer,
                                          settings.seed, light_dimension(l))
            lum = float(luminance(colours[l]))
            traced = None
            if light.kind != "directional":
                traced = _traced_light_power(light, world, tracer, count, settings.seed,
                                             _traced_keys(l))
            punctual[l], spread = _kept(area * mean, traced)
            if spread is None:
                seen += mean * lum
            else:
                variance += spread * lum ** 2
        if sources.emitters is not None:
            mean, _ = emissive_irradiance(context, sources.emitters, 1, receivers, settings.seed)
            traced = _traced_emitter_power(context, sources.emitters, count, settings.seed,
                                           _traced_keys(lights))
            emitted, spread = _kept(area * mean, traced)
            if spread is None:
                seen += luminance(mean)
            else:
                variance += spread
        if sources.sky is not None:
            mean, _ = sky_irradiance(sources.sky, 1, receivers, tracer, settings.seed)
            sky = area * mean.mean(axis=0)
            seen += luminance(mean)
        variance += area * area * _strata_variance(seen)
    power = Power(punctual=punctual, light_colours=colours, emission=emitted, sky=sky,
                  area=area)
    square = float(luminance(power.total())) ** 2  # 0 below 1.5e-154 too: its error is ~0
    return replace(power, relative_variance=variance / square if square > 0 else 0.0)


def _strata_variance(values: np.ndarray) -> float:
    """The variance of the mean of ``values`` (P,), one point in each of P equal strata:
    neighbouring strata taken two by two as one, Σ (v_a − v_b)² / P²."""
    gaps = values[0:len(values) - 1:2] - values[1::2]
    return float(np.sum(gaps * gaps)) / len(values) ** 2


def _traced_keys(source: int) -> np.ndarray:
    """(TRACED_GROUPS,) the sampler keys of source ``source``'s traced rays, one a group."""
    return (_TRACED_KEY_BASE + np.uint64(source * TRACED_GROUPS)
            + np.arange(TRACED_GROUPS, dtype=np.uint64))


def _kept(pointed: np.ndarray, traced: np.ndarray | None) -> tuple[np.ndarray | float, float | None]:
    """(power, its luminance's variance or None) of one source from its samples at the power
    points (``pointed`` (P,) or (P, 3): A_T × D) and, when it has them, from its own rays
    (``traced`` (G, m) or (G, m, 3): ``TRACED_GROUPS`` independent groups): the one of smaller
    estimated variance (the points', None then: their variance is taken with the other pointed
    sources', whose errors share the points; the traced one's is the spread of its groups'
    means, with G − 1 degrees of freedom)."""
    mean = pointed.mean(axis=0)
    if traced is None:
        return mean, None
    of = luminance if traced.ndim == 3 else (lambda v: v)
    groups = of(traced).mean(axis=1)
    spread = float(np.var(groups, ddof=1)) / len(groups)
    if spread <= _strata_variance(of(pointed)):
        return traced.mean(axis=(0, 1)), spread
    return mean, None


def _front_hits(world: World, tracer: Tracer, origins: np.ndarray, directions: np.ndarray,
                length: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """((n,) bool, (n,) distance): whether each ray's first hit within ``length`` is the front
    face of a triangle (``World.geometric_normals``), and how far it is (inf for misses)."""
    hits = tracer.cast(origins, directions, length)
    hit = hits.triangle >= 0
    normals = world.geometric_normals(hits.triangle[hit])
    front = np.zeros(len(origins), bool)
    front[hit] = (normals * directions[hit]).sum(axis=1) < 0
    return front, hits.distance


def _traced_light_power(light: Light, world: World, tracer: Tracer, count: int, seed: int,
                        keys: np.ndarray) -> np.ndarray:
    """(G, count/G) samples of the power a point or spot ``light`` of unit intensity lays on
    front faces, a group per key of ``keys`` (G,): rays from its centre uniform in the solid
    angle Ω it shines into (the sphere, or the spot's outer cone), each worth Ω × the cone's
    falloff × the range window at its first hit, where that is a front face (a sphere light
    of radius R lights what lies beyond R as its centre does)."""
    cos_max = math.cos(light.outer_cone) if light.kind == "spot" else -1.0
    axis = np.asarray(light.direction if light.kind == "spot" else (0.0, 0.0, 1.0), np.float64)
    u = split_samples(seed, keys, count // len(keys), POWER_TRACED[1]).reshape(1, -1, 2)
    directions = cone_directions(axis[None], np.array([cos_max]), u)[0]
    origins = np.broadcast_to(np.asarray(light.position, np.float64), directions.shape)
    front, distance = _front_hits(world, tracer, origins, directions, light.range)
    weight = 2.0 * np.pi * (1.0 - cos_max) * range_window(light, np.where(front, distance, 0.0))
    if light.kind == "spot":
        weight = weight * spot_attenuation(light, directions)
    return np.where(front, weight, 0.0).reshape(len(keys), -1)


def _traced_emitter_power(context: Context, emitters: Emitters, count: int, seed: int,
                          keys: np.ndarray) -> np.ndarray:
    """(G, count/G, 3) samples of the power the emissive triangles lay on front faces, a group
    per key of ``keys`` (G,): each picks a triangle in proportion to its power and a uniform
    point q on it (as ``emitter_samples`` does), a side (either, for a two-sided one) and a
    cosine-distributed direction from it, worth π·Le(q)·A·sides / p where its first hit is a
    front face."""
    u = split_samples(seed, keys, count // len(keys), POWER_TRACED[0]).reshape(-1, 2)
    v = split_samples(seed, keys, count // len(keys), POWER_TRACED[1]).reshape(-1, 2)
    picked = np.minimum(np.searchsorted(emitters.cdf, u[:, 0], side="right"),
                        len(emitters.cdf) - 1)
    start = emitters.cdf[picked] - emitters.probability[picked]
    root = np.sqrt(np.clip((u[:, 0] - start) / emitters.probability[picked], 0.0, 1.0))
    bary = np.stack([1.0 - root, u[:, 1] * root, (1.0 - u[:, 1]) * root], axis=1)
    corners = emitters.corners[picked]  # (count, 3, 3)
    point = (bary[:, 0:1] * corners[:, 0] + bary[:, 1:2] * corners[:, 1]
             + bary[:, 2:3] * corners[:, 2])
    two = emitters.two_sided[picked]
    back = two & (v[:, 0] >= 0.5)  # a two-sided emitter's back side, with half the samples
    v = np.stack([np.where(two, (2.0 * v[:, 0]) % 1.0, v[:, 0]), v[:, 1]], axis=1)
    normal = emitters.normals[picked] * np.where(back, -1.0, 1.0)[:, None]
    local = cosine_hemisphere(v)
    t1, t2 = tangent_frames(normal)
    directions = local[:, :1] * t1 + local[:, 1:2] * t2 + local[:, 2:] * normal
    world = context.world
    lift = ray_lift(point, np.sqrt(emitters.areas[picked]), world.center)
    front, _ = _front_hits(world, context.tracer, point + lift[:, None] * normal, directions,
                           np.inf)
    weight = (np.pi * emitters.areas[picked] * np.where(two, 2.0, 1.0)
              / emitters.probability[picked])
    radiance = emitter_radiance(context, emitters, picked, bary)
    return (radiance * np.where(front, weight, 0.0)[:, None]).reshape(len(keys), -1, 3)
