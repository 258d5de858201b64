"""Each source's direct light at a batch of receiving points (``Receivers``), with shadow rays:
punctual lights (``punctual_irradiance``: spot cone and range window, soft lights sampled in the
cone they subtend), emissive triangles (``emissive_irradiance``) and the sky
(``sky_irradiance``), each estimate with its variance from two independent halves of its
samples (``mean_and_variance``). The texels' direct light (``direct``), the power for I_A
(``power``) and the GI paths' next-event estimates (``gi``) all call them."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from baker.context import Context
from baker.geometry.surface import emission, luminance
from baker.jit import jit
from baker.light.sky import Sky
from baker.light.sources import Emitters
from baker.punctual import Light
from baker.rays.dimensions import EMISSIVE, SKY
from baker.rays.sampling import (
    cosine_hemisphere,
    folded,
    hemisphere_normals,
    split_samples,
    tangent_frames,
)
from baker.rays.trace import Tracer
from baker.rowwise import dot_rows


# Shadow rays stop this fraction short of the point they aim at (a light sample on a surface).
SHADOW_SHORTEN = 1e-3


@dataclass(frozen=True)
class Receivers:
    """k surface points that receive light.

    position: (k, 3) float64 world. normal: (k, 3) unit shading normal (for cosθ).
    geometric: (k, 3) unit front-face normal (rays leave on this side). lift: (k,) float64 world
    offset of ray origins along ``geometric``. key: (k,) uint64 sampler key.
    sub: None, or (k, S, 3) float64 world sub-positions (supersampling): ray s of a point starts
    from its sub-position s mod S instead of ``position``. raised: None, or (k,) bool, the
    point has a shadow-terminator push (``Texels.terminator``): its rays may leave below its
    facet's plane (only the shading normal's hemisphere counts). Where the push was blocked
    (validity.py) such rays meet the object itself, as they would anyway.
    """

    position: np.ndarray
    normal: np.ndarray
    geometric: np.ndarray
    lift: np.ndarray
    key: np.ndarray
    sub: np.ndarray | None = None
    raised: np.ndarray | None = None

    def starts(self, n: int) -> np.ndarray:
        """(k, n, 3) where each point's rays 0 … n − 1 start on the surface (before the lift):
        the point itself, or sub-position s mod S."""
        if self.sub is None:
            return np.broadcast_to(self.position[:, None, :], (len(self.position), n, 3))
        return self.sub[:, np.arange(n) % self.sub.shape[1]]

    def origins(self, n: int) -> np.ndarray:
        """(k·n, 3) ray origins, lifted off the surface, point-major (ray s of point i at row
        i·n + s)."""
        if self.sub is None:
            return np.repeat(self.position + self.lift[:, None] * self.geometric, n, axis=0)
        return (self.starts(n) + (self.lift[:, None] * self.geometric)[:, None]).reshape(-1, 3)


def cone_directions(axis: np.ndarray, cos_max: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Directions (k, n, 3) uniform in solid angle within the cones around unit ``axis`` (k, 3)
    of half-angle acos(``cos_max``) (k,), from points ``u`` (k, n, 2) of [0, 1)²."""
    cos_t = 1.0 - u[..., 0] * (1.0 - cos_max[:, None])
    sin_t = np.sqrt(np.clip(1.0 - cos_t * cos_t, 0.0, 1.0))
    phi = 2.0 * np.pi * u[..., 1]
    t1, t2 = tangent_frames(axis)
    return ((sin_t * np.cos(phi))[..., None] * t1[:, None] + (sin_t * np.sin(phi))[..., None] * t2[:, None]
            + cos_t[..., None] * axis[:, None])


def mean_and_variance(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean over the last axis of (k, n) samples drawn as ``sampling.split_samples`` draws
    them, and an unbiased estimate of that mean's variance (0 when n = 1).

    The samples' variance over n would assume independent samples; scrambled Sobol points
    are better than that, and it overstated the error of soft shadows, emitters and the sky
    2–4× (``benchmarks/bench_calibration.py``). The two halves (a = ⌊n/2⌋ and b = n − a
    samples) are independent estimates, so with m₁, m₂ their means, E[(m₁ − m₂)²] = V₁ + V₂
    and the whole mean's variance (a²V₁ + b²V₂)/n² is ab/n²·(m₁ − m₂)² when V ∝ 1/size, and
    exactly (m₁ − m₂)²/4 for a = b whatever the points' convergence. One texel's estimate has
    one degree of freedom: the error map pools it over neighbouring texels
    (``errormap.texel_errors``), the report over all of them."""
    n = values.shape[1]
    mean = values.mean(axis=1)
    if n < 2:
        return mean, np.zeros_like(mean)
    a = n // 2
    gap = values[:, :a].mean(axis=1) - values[:, a:].mean(axis=1)
    return mean, a * (n - a) / (n * n) * gap * gap


def rgb_mean_and_variance(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean (k, 3) of RGB samples (k, n, 3) and the variance (k,) of its luminance
    (``mean_and_variance``)."""
    _, variance = mean_and_variance(luminance(values))
    return values.mean(axis=1), variance


def _facing(receivers: Receivers, directions: np.ndarray) -> np.ndarray:
    """cosθ (k, n) of directions (k, n, 3) against the shading normal, 0 where the direction is
    below either the shading or the geometric surface (the ray could not leave there) — except
    that a point raised off its facet (``Receivers.raised``, the shadow-terminator offset)
    may send rays below its facet's plane: they start above the neighbouring facets."""
    cos_n = np.einsum("kc,knc->kn", receivers.normal, directions)
    above = np.einsum("kc,knc->kn", receivers.geometric, directions) > 0
    if receivers.raised is not None:
        above |= receivers.raised[:, None]
    return np.where(above, np.maximum(cos_n, 0.0), 0.0)


def spot_attenuation(light: Light, to_receiver: np.ndarray) -> np.ndarray:
    """KHR_lights_punctual's spot cone falloff for unit directions (k, 3) from the light.

    The extension's reference code: a linear ramp in cos between the outer and inner cone
    angles, squared; 1 inside the inner cone, 0 outside the outer cone.
    """
    cos_outer, cos_inner = math.cos(light.outer_cone), math.cos(light.inner_cone)
    scale = 1.0 / max(0.001, cos_inner - cos_outer)
    cd = dot_rows(to_receiver, light.direction)
    return np.clip(cd * scale - cos_outer * scale, 0.0, 1.0) ** 2


def range_window(light: Light, distance: np.ndarray) -> np.ndarray:
    """The extension's recommended range cutoff, clamp(1 − (d / range)⁴, 0, 1) (1 without range)."""
    if not math.isfinite(light.range):
        return np.ones_like(distance)
    return np.clip(1.0 - (distance / light.range) ** 4, 0.0, 1.0)


def punctual_irradiance(light: Light, spread: float, n: int, receivers: Receivers, tracer: Tracer,
                        seed: int, dimension: int) -> tuple[np.ndarray, np.ndarray]:
    """Irradiance (k,) from ``light`` at unit intensity, white, and the variance of its estimate.

    Directional: cosθ (lux per lux). Point/spot: cosθ / r² × spot cone × range window (lux per
    candela). ``spread`` > 0 makes the light a sphere of that radius (point/spot) or a disc of that
    angular radius (directional), sampled with ``n`` shadow rays per receiver; otherwise one ray.
    """
    values, _, _ = punctual_samples(light, spread, n, receivers, tracer, seed, dimension)
    return mean_and_variance(values)


def punctual_samples(light: Light, spread: float, n: int, receivers: Receivers, tracer: Tracer,
                     seed: int, dimension: int) -> tuple[np.ndarray, np.ndarray]:
    """``punctual_irradiance``'s samples (k, n'), what each would give unoccluded (k, n') and
    their unit directions towards the light (k, n', 3): n' = ``n`` for a soft light or with
    supersampling, else 1."""
    k = len(receivers.position)
    if k == 0:
        return np.zeros((0, 1)), np.zeros((0, 1)), np.zeros((0, 1, 3))
    soft = spread > 0
    n = n if soft or receivers.sub is not None else 1
    u = split_samples(seed, receivers.key, n, dimension)  # (k, n, 2)
    if light.kind == "directional":
        axis = np.broadcast_to(-light.direction, (k, 3)).copy()
        if soft:
            cos_max = np.full(k, math.cos(spread))
            directions = cone_directions(axis, cos_max, u)
            scale = np.full((k, 1), 2.0 / (1.0 + math.cos(spread)))  # normal irradiance of the disc = 1
        else:
            directions = axis[:, None, :]
            scale = np.ones((k, 1))
        lengths = np.full(k * n, np.inf)
    else:  # every ray from where it starts (a sub-position when supersampling): (k, n) values
        offset = light.position - receivers.starts(n)  # (k, n, 3)
        r = np.maximum(np.linalg.norm(offset, axis=2), receivers.lift[:, None])
        axis = offset / r[..., None]
        factor = range_window(light, r)
        if light.kind == "spot":
            factor = factor * spot_attenuation(light, -axis)
        if soft:
            sin_max = np.minimum(spread / r, 1.0)
            cos_max = np.sqrt(1.0 - sin_max * sin_max)
            directions = cone_directions(axis.reshape(-1, 3), cos_max.reshape(-1),
                                         u.reshape(-1, 1, 2)).reshape(k, n, 3)
            # Radiance I / (πR²) times the cone's solid angle 2π(1 − cos α), with 1 − cos α =
            # sin²α / (1 + cos α) and sin α / R = min(1/r, 1/R): no cancellation nor 0/0 for
            # a sphere far smaller than its distance (a radius of 1e-200 is a point light).
            per_radius = np.minimum(1.0 / r, 1.0 / spread)
            scale = factor * 2.0 * per_radius * per_radius / (1.0 + cos_max)
            b = np.einsum("knc,knc->kn", directions, offset)
            to_sphere = b - np.sqrt(np.maximum(b * b - (r * r - spread * spread), 0.0))
            lengths = (np.maximum(to_sphere, 0.0) * (1.0 - SHADOW_SHORTEN)).reshape(-1)
        else:
            directions = axis
            scale = factor / (r * r)
            lengths = (r * (1.0 - SHADOW_SHORTEN)).reshape(-1)
    directions = np.broadcast_to(directions, (k, n, 3))
    cos = _facing(receivers, directions)
    live = (cos > 0) & (scale > 0)
    visible = np.zeros(k * n, bool)
    flat = live.reshape(-1)
    if flat.any():
        origins = receivers.origins(n)[flat]
        rays = directions.reshape(-1, 3)[flat]
        visible[flat] = ~tracer.occluded(origins, rays, lengths[flat])
    unoccluded = np.broadcast_to(cos * scale, (k, n))
    return unoccluded * visible.reshape(k, n), unoccluded, directions


@jit
def emitter_samples(u, n, cdf, probability, corners, normals, two_sided, areas, origins, lift,
                    shading, geometric, raised):
    """The geometry of the k·n emissive samples (``emissive_irradiance``), one compiled pass.

    Sample j of receiver i = j // n: its first coordinate u[j, 0] picks the emitter triangle by
    the power ``cdf`` (E,) (``probability`` (E,) each), then is stretched back to [0, 1)
    within the triangle's slice to place a uniform point with u[j, 1] (one stratified 2D sample
    does both). Returns chosen (k·n,) triangle, bary (k·n, 3) of the point, unit directions
    (k·n, 3) from ``origins`` (k·n, 3) to it, distance (k·n,) (at least the receiver's ``lift``)
    and weight (k·n,) = cosθ_p·cosθ_q / d² · A / p (0 where the point cannot see it: cosθ_p
    as ``_facing`` gives it, with ``raised`` (k,) receivers free to look below their facet;
    cosθ_q only from the front unless ``two_sided``).
    """
    count = len(u)
    chosen = np.empty(count, np.int64)
    bary = np.empty((count, 3))
    directions = np.empty((count, 3))
    distance = np.empty(count)
    weight = np.zeros(count)
    last = len(cdf) - 1
    for j in range(count):
        i = j // n
        e = min(np.searchsorted(cdf, u[j, 0], side="right"), last)
        chosen[j] = e
        start = cdf[e] - probability[e]
        root = np.sqrt(min(max((u[j, 0] - start) / probability[e], 0.0), 1.0))
        b0, b1, b2 = 1.0 - root, u[j, 1] * root, (1.0 - u[j, 1]) * root
        bary[j, 0], bary[j, 1], bary[j, 2] = b0, b1, b2
        ox = b0 * corners[e, 0, 0] + b1 * corners[e, 1, 0] + b2 * corners[e, 2, 0] - origins[j, 0]
        oy = b0 * corners[e, 0, 1] + b1 * corners[e, 1, 1] + b2 * corners[e, 2, 1] - origins[j, 1]
        oz = b0 * corners[e, 0, 2] + b1 * corners[e, 1, 2] + b2 * corners[e, 2, 2] - origins[j, 2]
        d = max(np.sqrt(ox * ox + oy * oy + oz * oz), lift[i])
        dx, dy, dz = ox / d, oy / d, oz / d
        directions[j, 0], directions[j, 1], directions[j, 2] = dx, dy, dz
        distance[j] = d
        above = raised[i] or dx * geometric[i, 0] + dy * geometric[i, 1] + dz * geometric[i, 2] > 0
        cos_p = max(dx * shading[i, 0] + dy * shading[i, 1] + dz * shading[i, 2], 0.0) if above else 0.0
        cos_q = -(normals[e, 0] * dx + normals[e, 1] * dy + normals[e, 2] * dz)
        cos_q = abs(cos_q) if two_sided[e] else max(cos_q, 0.0)
        weight[j] = cos_p * cos_q / (d * d) * areas[e] / probability[e]
    return chosen, bary, directions, distance, weight


def emissive_irradiance(context: Context, emitters: Emitters, n: int, receivers: Receivers,
                        seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Irradiance (k, 3) from the emissive triangles, and the variance (k,) of its luminance.

    Each of ``n`` samples picks a triangle in proportion to its power and a uniform point q on
    it; the estimate is Le(q)·cosθ_p·cosθ_q / d² · V / (P_t / A_t), unbiased for the irradiance
    of every emitter (a triangle whose mean emission is 0 at the fixed points is never picked).
    Shadow rays go through ``context.tracer``.
    """
    value, _, _ = emissive_samples(context, emitters, n, receivers, seed)
    return rgb_mean_and_variance(value)


def emissive_samples(context: Context, emitters: Emitters, n: int, receivers: Receivers,
                     seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``emissive_irradiance``'s samples (k, n, 3), the luminance (k, n) each would give
    unoccluded and their unit directions (k, n, 3)."""
    k = len(receivers.position)
    if k == 0:
        return np.zeros((0, n, 3)), np.zeros((0, n)), np.zeros((0, n, 3))
    u = split_samples(seed, receivers.key, n, EMISSIVE).reshape(-1, 2)
    origins = receivers.origins(n)
    raised = np.zeros(k, bool) if receivers.raised is None else receivers.raised
    chosen, bary, directions, distance, weight = emitter_samples(
        u, n, emitters.cdf, emitters.probability, emitters.corners, emitters.normals,
        emitters.two_sided, emitters.areas, origins, receivers.lift, receivers.normal,
        receivers.geometric, raised)
    live = weight > 0
    value = np.zeros((k * n, 3))
    unoccluded = np.zeros(k * n)
    if live.any():
        visible = ~context.tracer.occluded(origins[live], directions[live],
                                           distance[live] * (1.0 - SHADOW_SHORTEN))
        radiance = emitter_radiance(context, emitters, chosen[live], bary[live])
        unoccluded[live] = luminance(radiance) * weight[live]
        value[live] = radiance * (weight[live] * visible)[:, None]
    return value.reshape(k, n, 3), unoccluded.reshape(k, n), directions.reshape(k, n, 3)


def emitter_radiance(context: Context, emitters: Emitters, picked: np.ndarray,
                     bary: np.ndarray) -> np.ndarray:
    """Emitted radiance (k, 3) at points ``bary`` (k, 3) of the emitter triangles ``picked``
    (k,): each triangle's constant radiance, or its emissive texture's where it has one."""
    radiance = emitters.radiance[picked]
    textured = emitters.textured[picked]
    if textured.any():
        radiance[textured] = emission(context.surfaces, context.world,
                                      emitters.triangles[picked[textured]], bary[textured])
    return radiance


def sky_irradiance(sky: Sky, n: int, receivers: Receivers, tracer: Tracer,
                   seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Irradiance (k, 3) from the sky about the shading normal, and its luminance variance (k,).

    Cosine-distributed rays (pdf cosθ/π) about the receivers' hemisphere normals
    (``sampling.hemisphere_normals``: the shading normal, the front face's on flat surfaces),
    those below the front face folded above it (``sampling.fold``), as the obscurance's; a ray
    that meets nothing at any distance sees the sky, so the estimate is π · mean(L_sky(ω) · V(ω)).
    An image sky draws half of them by the image instead, each weighted by the mixture's
    density (``Sky.draw``).
    """
    value, _, _ = sky_samples(sky, n, receivers, tracer, seed)
    return rgb_mean_and_variance(value)


def sky_samples(sky: Sky, n: int, receivers: Receivers, tracer: Tracer,
                seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``sky_irradiance``'s samples (k, n, 3), the luminance (k, n) each would give
    unoccluded and their unit directions (k, n, 3)."""
    k = len(receivers.position)
    if k == 0:
        return np.zeros((0, n, 3)), np.zeros((0, n)), np.zeros((0, n, 3))
    points = split_samples(seed, receivers.key, n, SKY)
    normal = hemisphere_normals(receivers.normal, receivers.geometric)
    if sky.is_image:
        directions, unoccluded = sky.draw(points.reshape(-1, 2), np.repeat(normal, n, axis=0),
                                          np.repeat(receivers.geometric, n, axis=0))
    else:
        local = cosine_hemisphere(points)
        t1, t2 = tangent_frames(normal)
        directions = folded((local[..., :1] * t1[:, None] + local[..., 1:2] * t2[:, None]
                             + local[..., 2:] * normal[:, None]).reshape(-1, 3),
                            np.repeat(normal, n, axis=0),
                            np.repeat(receivers.geometric, n, axis=0))
        unoccluded = np.pi * sky.radiance(directions)
    live = np.flatnonzero(unoccluded.any(axis=1)) if sky.is_image else slice(None)
    escaped = np.zeros(k * n, bool)
    escaped[live] = ~tracer.occluded(receivers.origins(n)[live], directions[live], np.inf)
    return ((unoccluded * escaped[:, None]).reshape(k, n, 3),
            luminance(unoccluded).reshape(k, n), directions.reshape(k, n, 3))
