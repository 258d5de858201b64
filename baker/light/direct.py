"""Direct light D(P): punctual lights, emissive surfaces and the sky, with shadow rays.

The lightmap holds what arrives at a surface, ``L(P) = D(P) + I_A · W(P)`` (docs/design.md §2), as
irradiance: the shader multiplies by albedo / π (three.js, Blender). D is estimated per texel and
kept apart per source so that changing a light's colour or intensity is a recomposition, with no
ray cast:

- KHR_lights_punctual lights, each at unit intensity and white colour: a directional light of
  1 lux gives cosθ, a point light of 1 candela at distance r gives cosθ / r², times the spot cone
  and range window the extension recommends, times visibility (one shadow ray; several for a
  light with a size). ``Direct.light_colours`` (L, 3) holds colour × intensity as baked.
- Emissive triangles (emissiveFactor × emissiveTexture × KHR_materials_emissive_strength, taken
  as emitted radiance) as area lights, sampled in proportion to their power.
- The sky (``sky.Sky``): a uniform or two-colour gradient, through cosine-distributed rays that
  escape the scene, or an environment image, importance-sampled by the image and the cosine.

Soft shadows: a point/spot light with radius R is a sphere of uniform radiance I / (πR²); it is
sampled by directions uniform in the cone it subtends, so an unoccluded receiver facing it gets
exactly I·cosθ/r², as from the point. A directional light with angular diameter 2α is a disc of
uniform radiance E / (π sin²α); its directions are sampled uniformly in the cone of half-angle α.

The emissive surfaces' own texels: the lightmap holds only the light arriving at them (from other
emitters, lights, sky and the ambient term), never their own emission, which stays in the
material (emissiveFactor) where every viewer adds it: nothing is counted twice. An emitter does
not light itself (a flat triangle's points see it at cosθ = 0).

Supersampling (``settings.supersample`` = S > 1, ``supersample.py``): each texel's shadow, emissive
and sky rays start from S sub-positions spread over its square, ray s from sub-position s mod S,
so a shadow edge crossing a texel gives it a partial value; a hard light then casts S rays.

Shadow terminator: texels on smooth-shaded curved facets are raised towards the smooth surface
(``Texels.terminator``, applied by ``validity.check_texels``); from there rays may leave
a little below their own facet's plane (above the shading normal's), so the light fades smoothly
across the facets instead of stopping at each facet's edge.

Randomness is a pure function of (seed, texel key, sample, dimension) through
``sampling.split_samples`` (two independent halves, which make each estimate's error
measurable: ``mean_and_variance``); each source has dimensions of its own
(``baker/rays/dimensions.py``, the one table of them). Chunks of texels
run on a thread pool and write only their own rows, so the result does not depend on chunking.

``delivered_power`` estimates, for I_A, how much power each source lays on the scene's surfaces
(docs/direct_light.md): the same estimators at points spread over every triangle by area.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from baker.atlas.rasterise import Texels
from baker.atlas.supersample import sub_positions
from baker.geometry.surface import LUMINANCE, emission, triangle_means
from baker.geometry.world import World
from baker.gltf.scene import Light, Scene
from baker.jit import jit
from baker.light.adaptive import WITHIN, neighbour_mean, pooled_gain
from baker.light.sky import Sky, sky_of
from baker.rays.dimensions import EMISSIVE, POWER, POWER_TRACED, SKY, light_dimension
from baker.rays.sampling import (
    cosine_hemisphere,
    folded,
    hemisphere_normals,
    sample_2d,
    split_samples,
    tangent_frames,
)
from baker.rays.trace import Tracer, ray_lift
from baker.run.parallel import run_chunks, texels_per_chunk
from baker.settings import DEFAULT_RAYS, Resolved

# Samples of each source's power for I_A at ``DEFAULT_RAYS`` rays a texel (``power_samples``).
POWER_POINTS = 16384
# Keys of the power-estimate points, apart from texel keys ((page·h + y)·w + x, far below 2^62),
# and of the sources whose power is traced from them (``TRACED_GROUPS`` keys each, above every
# point's): each key's rays are an independent net, so their means' spread is the estimate's.
_POWER_KEY_BASE = np.uint64(1 << 62)
_TRACED_KEY_BASE = np.uint64(3 << 61)
TRACED_GROUPS = 16

# Shadow rays stop this fraction short of the point they aim at (a light sample on a surface).
SHADOW_SHORTEN = 1e-3



# ------------------------------------------------------------------------------------------------
# The scene's sources, resolved against the settings


@dataclass(frozen=True)
class Emitters:
    """The emissive triangles, E of them, and how they are sampled.

    triangles: (E,) int64 world triangles. probability: (E,) float64 chance of picking each one,
    in proportion to its power (area × luminance of its mean emission × sides). cdf: (E,) float64
    running sum of ``probability`` (last 1). areas: (E,) float64 world areas. normals: (E, 3)
    float64 unit front-face normals. two_sided: (E,) bool, emits from both faces (doubleSided).
    power: the emitted luminous power Σ sides·π·A·lum(e), scene units² × radiance.
    corners: (E, 3, 3) float64 world corners. radiance: (E, 3) float64 emitted radiance of the
    triangles whose material has no emissive texture (constant over them); textured: (E,) bool,
    the others, whose radiance is looked up at each sample point.
    """

    triangles: np.ndarray
    probability: np.ndarray
    cdf: np.ndarray
    areas: np.ndarray
    normals: np.ndarray
    two_sided: np.ndarray
    power: float
    corners: np.ndarray
    radiance: np.ndarray
    textured: np.ndarray
    area_share: float = 1.0  # the emitting triangles' share of the scene's surface area


@dataclass(frozen=True)
class Sources:
    """What lights the scene directly, as this bake treats it.

    lights: the scene's punctual lights (order of ``Scene.lights``). spread: (L,) float64, a
    point/spot light's sphere radius (scene units) or a directional light's cone half-angle
    (radians), 0 for a hard light. samples: (L,) int64 shadow rays per texel (1 when hard, or
    the supersample count when that is more: one ray from each sub-position).
    emitters: the emissive triangles, None when nothing emits. emissive_rays: rays per texel
    towards them. sky: what the sky sends (``sky.Sky``), None for no sky. sky_rays.
    """

    lights: tuple[Light, ...]
    spread: np.ndarray
    samples: np.ndarray
    emitters: Emitters | None
    emissive_rays: int
    sky: Sky | None
    sky_rays: int

    def light_colours(self) -> np.ndarray:
        """(L, 3) colour × intensity of every light (lux or candela, linear RGB)."""
        if not self.lights:
            return np.zeros((0, 3))
        return np.array([light.colour * light.intensity for light in self.lights], np.float64)

    def counts(self, samples: int | None = None, scale: int = 1) -> np.ndarray:
        """(L + 2,) int64 rays a receiver casts towards each light, the emitters and the sky
        (0 for an absent source): each source's own, or ``samples`` for every source, with
        the noisy ones' (``noisy``) times ``scale`` (an adaptive round)."""
        own = np.concatenate([self.samples, [self.emissive_rays if self.emitters is not None
                                             else 0, self.sky_rays if self.sky is not None else 0]])
        present = np.concatenate([np.ones(len(self.lights), bool),
                                  [self.emitters is not None, self.sky is not None]])
        own = np.where(present, own if samples is None else samples, 0).astype(np.int64)
        return np.where(self._noisy_sources(), own * scale, own)

    def _noisy_sources(self) -> np.ndarray:
        """(L + 2,) bool: which sources' estimates have noise — a light cast with several rays
        (a soft one, or supersampled), the emitters and the sky when there are some."""
        return np.concatenate([self.samples > 1, [self.emitters is not None,
                                                  self.sky is not None]])

    def noisy(self) -> bool:
        """Whether any source's estimate has noise (``counts``): adaptive rounds can reduce it."""
        return bool(self._noisy_sources().any())

    def scales(self, max_rays: int) -> list[int]:
        """The ray scales of the adaptive rounds (``counts``): 1, then doubling while the noisy
        sources' rays stay within ``max_rays``; only 1 when no source is noisy."""
        scales = [1]
        while self.noisy() and self.counts(None, 2 * scales[-1]).max() <= max_rays:
            scales.append(2 * scales[-1])
        return scales

    def most_rays_per_texel(self, max_rays: int) -> int:
        """The shadow and sky rays a texel casts at most in all adaptive rounds (each round
        estimates afresh: ``direct_light``)."""
        return sum(self.rays_per_texel(self.counts(None, scale)) for scale in self.scales(max_rays))

    def rays_per_texel(self, counts: np.ndarray | None = None) -> int:
        """Shadow and sky rays every texel casts (at ``counts``, by default its own)."""
        return int((self.counts() if counts is None else counts).sum())

    def any(self) -> bool:
        """Whether anything lights the scene directly."""
        return bool(self.lights) or self.emitters is not None or self.sky is not None


def find_emitters(scene: Scene, world: World) -> Emitters | None:
    """The triangles that emit (positive mean emission and area), None when there are none."""
    if len(world.triangles) == 0:
        return None
    mean = triangle_means(scene, world, emission, lambda m: m.emissive_texture)
    areas = world.areas()
    sides = np.where([m.double_sided for m in scene.materials], 2.0, 1.0)[world.tri_material]
    weight = areas * np.maximum(mean @ LUMINANCE, 0.0) * sides
    emitting = np.flatnonzero((weight > 0) & np.isfinite(weight))
    if len(emitting) == 0:
        return None
    w = weight[emitting]
    probability = w / w.sum()
    cdf = np.cumsum(probability)
    cdf[-1] = 1.0
    textured = np.array([m.emissive_texture is not None for m in scene.materials], bool)
    return Emitters(triangles=emitting, probability=probability, cdf=cdf, areas=areas[emitting],
                    normals=world.geometric_normals(emitting), two_sided=sides[emitting] > 1,
                    power=float(math.pi * w.sum()),
                    corners=world.positions[world.triangles[emitting]],
                    radiance=mean[emitting], textured=textured[world.tri_material[emitting]],
                    area_share=float(areas[emitting].sum() / areas.sum()))


def light_sources(scene: Scene, world: World, settings: Resolved) -> Sources:
    """The scene's direct-light sources with the settings' fallbacks and ray counts applied."""
    spread, samples = [], []
    for light in scene.lights:
        if light.kind == "directional":
            diameter = (light.angular_diameter if light.angular_diameter is not None
                        else math.radians(settings.light_angle))
            size = min(diameter / 2, math.pi / 2 - 1e-6)
        else:
            size = light.radius if light.radius is not None else settings.light_radius
        spread.append(size)
        samples.append(max(settings.shadow_rays if size > 0 else 1, settings.supersample))
    return Sources(lights=tuple(scene.lights), spread=np.asarray(spread, np.float64).reshape(-1),
                   samples=np.asarray(samples, np.int64).reshape(-1),
                   emitters=find_emitters(scene, world), emissive_rays=settings.emissive_rays,
                   sky=sky_of(settings), sky_rays=settings.sky_rays)


# ------------------------------------------------------------------------------------------------
# Estimators at a batch of receiving points


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


def _cone_directions(axis: np.ndarray, cos_max: np.ndarray, u: np.ndarray) -> np.ndarray:
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
    cd = to_receiver @ light.direction
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
            directions = _cone_directions(axis, cos_max, u)
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
            directions = _cone_directions(axis.reshape(-1, 3), cos_max.reshape(-1),
                                          u.reshape(-1, 1, 2)).reshape(k, n, 3)
            # Radiance I / (πR²) times the cone's solid angle 2π(1 − cos α).
            scale = factor * 2.0 * (1.0 - cos_max) / (spread * spread)
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


def emissive_irradiance(scene: Scene, world: World, emitters: Emitters, n: int,
                        receivers: Receivers, tracer: Tracer, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Irradiance (k, 3) from the emissive triangles, and the variance (k,) of its luminance.

    Each of ``n`` samples picks a triangle in proportion to its power and a uniform point q on
    it; the estimate is Le(q)·cosθ_p·cosθ_q / d² · V / (P_t / A_t), unbiased for the irradiance
    of every emitter (a triangle whose mean emission is 0 at the fixed points is never picked).
    """
    value, _, _ = emissive_samples(scene, world, emitters, n, receivers, tracer, seed)
    return _rgb_mean_and_variance(value)


def emissive_samples(scene: Scene, world: World, emitters: Emitters, n: int,
                     receivers: Receivers, tracer: Tracer, seed: int
                     ) -> tuple[np.ndarray, np.ndarray]:
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
        visible = ~tracer.occluded(origins[live], directions[live],
                                   distance[live] * (1.0 - SHADOW_SHORTEN))
        radiance = emitter_radiance(scene, world, emitters, chosen[live], bary[live])
        unoccluded[live] = (radiance @ LUMINANCE) * weight[live]
        value[live] = radiance * (weight[live] * visible)[:, None]
    return value.reshape(k, n, 3), unoccluded.reshape(k, n), directions.reshape(k, n, 3)


def emitter_radiance(scene: Scene, world: World, emitters: Emitters, picked: np.ndarray,
                     bary: np.ndarray) -> np.ndarray:
    """Emitted radiance (k, 3) at points ``bary`` (k, 3) of the emitter triangles ``picked``
    (k,): each triangle's constant radiance, or its emissive texture's where it has one."""
    radiance = emitters.radiance[picked]
    textured = emitters.textured[picked]
    if textured.any():
        radiance[textured] = emission(scene, world, emitters.triangles[picked[textured]],
                                      bary[textured])
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
    return _rgb_mean_and_variance(value)


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
            (unoccluded @ LUMINANCE).reshape(k, n), directions.reshape(k, n, 3))


# ------------------------------------------------------------------------------------------------
# Per texel


def _all_sources(terms, light_colours: np.ndarray | None) -> np.ndarray:
    """punctual @ colours + emission + sky of a ``Direct`` or ``Power``: the per-light terms at
    unit intensity times the light colours × intensities (L, 3), by default the baked ones."""
    colours = terms.light_colours if light_colours is None else np.asarray(light_colours, np.float64)
    out = terms.punctual @ colours  # a new array: the sums go into it in place
    for term in (terms.emission, terms.sky):  # empty when the scene has no such source
        if len(term):
            out += term
    return out


@dataclass(frozen=True)
class Direct:
    """Direct irradiance at N texels (rows in ``Texels`` order), kept apart per source.

    punctual: (N, L) float64 irradiance from each light at unit intensity and white colour (lux
    per lux, or per candela); punctual_var: (N, L) variance of those estimates (0 for hard lights).
    light_colours: (L, 3) colour × intensity of each light as baked. emission: (N, 3) irradiance
    from emissive surfaces; sky: (N, 3) from the sky; emission_var, sky_var: (N,) variances of
    their luminance estimates — each empty (0 rows) when the scene has no such source (32 bytes
    a texel not held: 270 MB on a 4096² page). rays_per_texel: shadow and sky rays cast from
    each texel (``rays`` in all); texel_rays: (N,) int64 the rays each texel cast in all of
    its adaptive rounds (``direct_light``), empty (0 rows) without them.
    punctual_aim (N, L, 3), emission_aim (N, 3), sky_aim (N, 3): each source's first moment of
    its irradiance's luminance along the light's world directions (``light.directional``), at
    unit intensity and white for the lights; punctual_aim_var (N, L), emission_aim_var (N,),
    sky_aim_var (N,): their estimates' variances (summed over the components). Empty (0 rows)
    without ``Resolved.directional_pages`` (or the source).
    """

    punctual: np.ndarray
    punctual_var: np.ndarray
    light_colours: np.ndarray
    emission: np.ndarray
    emission_var: np.ndarray
    sky: np.ndarray
    sky_var: np.ndarray
    rays_per_texel: int
    texel_rays: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    punctual_aim: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 3)))
    punctual_aim_var: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    emission_aim: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    emission_aim_var: np.ndarray = field(default_factory=lambda: np.zeros(0))
    sky_aim: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    sky_aim_var: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def aim(self, light_colours: np.ndarray | None = None) -> np.ndarray:
        """(N, 3) the first moment of D's luminance along the light's directions, for the
        lights' colour × intensity (L, 3), by default the baked ones; (0, 3) when not kept."""
        if not len(self.punctual_aim):
            return np.zeros((0, 3))
        colours = self.light_colours if light_colours is None else np.asarray(light_colours, np.float64)
        out = np.einsum("nlc,l->nc", self.punctual_aim, colours @ LUMINANCE)
        for term in (self.emission_aim, self.sky_aim):
            if len(term):
                out += term
        return out

    def aim_variance(self, light_colours: np.ndarray | None = None) -> np.ndarray:
        """(N,) the variance of ``aim``'s estimate (the sources' are independent)."""
        if not len(self.punctual_aim):
            return np.zeros(0)
        colours = self.light_colours if light_colours is None else np.asarray(light_colours, np.float64)
        out = self.punctual_aim_var @ (colours @ LUMINANCE) ** 2
        for term in (self.emission_aim_var, self.sky_aim_var):
            if len(term):
                out += term
        return out

    @property
    def rays(self) -> int:
        """Shadow and sky rays cast in all."""
        if len(self.texel_rays):
            return int(self.texel_rays.sum())
        return len(self.punctual) * self.rays_per_texel

    def irradiance(self, light_colours: np.ndarray | None = None) -> np.ndarray:
        """D (N, 3) for the given light colour × intensity (L, 3), by default the baked ones."""
        return _all_sources(self, light_colours)

    def variance(self, light_colours: np.ndarray | None = None) -> np.ndarray:
        """(N,) variance of the luminance of D's estimate (the sources' estimates are independent)."""
        colours = self.light_colours if light_colours is None else np.asarray(light_colours, np.float64)
        out = self.punctual_var @ (colours @ LUMINANCE) ** 2  # a new array, summed in place
        for term in (self.emission_var, self.sky_var):
            if len(term):
                out += term
        return out


def _source_terms(count: int, present: bool) -> tuple[np.ndarray, np.ndarray]:
    """Zeroed (count, 3) irradiance and (count,) variance of a source kind, or empty ones (0
    rows) when the scene has no such source."""
    rows = count if present else 0
    return np.zeros((rows, 3)), np.zeros(rows)


def no_direct(count: int) -> Direct:
    """The direct term of ``count`` texels in a scene with no source: zeros, no ray."""
    none = _source_terms(count, False)
    return Direct(np.zeros((count, 0)), np.zeros((count, 0)), np.zeros((0, 3)), *none, *none, 0)


def texel_receivers(texels: Texels, rows: slice | np.ndarray, center: np.ndarray,
                     tracer: Tracer | None = None, supersample: int = 1,
                     seed: int = 0) -> Receivers:
    """The texels ``rows`` as Receivers: their (moved, raised) sample points and, when
    ``supersample`` > 1, their sub-positions (``supersample.sub_positions``, which need the
    ``tracer`` and the ``seed``)."""
    sub = None
    if supersample > 1:
        if tracer is None:
            raise ValueError("supersampling needs the tracer (sub-positions are checked by rays)")
        sub = sub_positions(tracer, texels, rows, supersample, seed)
    return Receivers(position=texels.position[rows], normal=texels.normal[rows],
                     geometric=texels.geometric_normal(rows),
                     lift=ray_lift(texels.position[rows], texels.size(rows), center),
                     key=texels.key[rows], sub=sub,
                     raised=np.any(texels.terminator(rows) != 0.0, axis=1))


def direct_at(scene: Scene, world: World, tracer: Tracer, sources: Sources,
              receivers: Receivers, seed: int, samples: int | None = None) -> Direct:
    """Direct irradiance at ``receivers`` from every source, kept apart per source.

    ``samples``: shadow/sky rays per receiver for every source (None: each source's own count,
    as a bake uses them; the full-GI reference takes 1 at each bounce).
    """
    return _direct_rows(scene, world, tracer, sources, receivers, seed, samples)[0]


@dataclass(frozen=True)
class _Noise:
    """What adaptive rounds need to predict the error of k receivers' D, in luminance at the
    baked colours, summed over the sources: iid (k,), the variance of the mean were the
    samples independent (sample variance / n); floor (k,), the square of the error that a
    source whose samples were all unoccluded, or all occluded, cannot rule out: the rule of
    succession's p ≲ 1/(n + 2) of its unoccluded light (as ``hemisphere.binomial_floor``);
    partial (k,) bool, some source's samples were occluded in part (a penumbra seen).

    ``_predicted`` takes the floor only beside a texel that saw a penumbra: without it, a
    floor beside a box under the sky, whose few rays all missed the box, stops at the first
    round (75 % of the sky scene's texels within E where 95 % should be); with it everywhere,
    a texel lit by a soft light with no occluder about spends rays on one that is not there
    (9× the rays uniform sampling needs on the penumbra scene)."""

    iid: np.ndarray
    floor: np.ndarray
    partial: np.ndarray


def _noise_of(values: np.ndarray, unoccluded: np.ndarray, scale: float) -> tuple[np.ndarray, ...]:
    """(iid, floor, partial) of one source's luminance samples ``values`` (k, n) (what each
    would give unoccluded: (k, n)) at luminance per unit ``scale`` (``_Noise``)."""
    n = values.shape[1]
    if n < 2:
        return np.zeros(len(values)), np.zeros(len(values)), np.zeros(len(values), bool)
    iid = values.var(axis=1, ddof=1) / n * scale * scale
    seen = (values == unoccluded) | (unoccluded <= 0)  # unoccluded, or giving nothing anyway
    hidden = (values <= 0) | (unoccluded <= 0)
    alike = seen.all(axis=1) | hidden.all(axis=1)
    floor = np.where(alike, unoccluded.mean(axis=1) * scale / (n + 2), 0.0)
    return iid, floor * floor, ~alike


def _direct_rows(scene: Scene, world: World, tracer: Tracer, sources: Sources,
                 receivers: Receivers, seed: int, samples: int | None = None,
                 scale: int = 1, aims: bool = False) -> tuple[Direct, _Noise]:
    """``direct_at``, with each noisy source's rays × ``scale`` (an adaptive round:
    ``Sources.counts``), and its ``_Noise``; ``aims``: keep each source's ``Direct.aim``."""
    k = len(receivers.position)
    lights = len(sources.lights)
    punctual, punctual_var = np.zeros((k, lights)), np.zeros((k, lights))
    emitted, emitted_var = _source_terms(k, sources.emitters is not None)
    sky, sky_var = _source_terms(k, sources.sky is not None)
    aim = _Aims.blank(k if aims else 0, lights, sources)
    noise = _Noise(np.zeros(k), np.zeros(k), np.zeros(k, bool))
    counts = sources.counts(samples, scale)
    colours = sources.light_colours() @ LUMINANCE
    for l, light in enumerate(sources.lights):
        values, unoccluded, directions = punctual_samples(
            light, float(sources.spread[l]), int(counts[l]), receivers, tracer, seed,
            light_dimension(l))
        punctual[:, l], punctual_var[:, l] = mean_and_variance(values)
        _add(noise, _noise_of(values, unoccluded, float(colours[l])))
        if aims:
            aim.punctual[:, l], aim.punctual_var[:, l] = aim_of(values, directions)
    if sources.emitters is not None:
        values, unoccluded, directions = emissive_samples(
            scene, world, sources.emitters, int(counts[-2]), receivers, tracer, seed)
        emitted, emitted_var = _rgb_mean_and_variance(values)
        _add(noise, _noise_of(values @ LUMINANCE, unoccluded, 1.0))
        if aims:
            aim.emission[:], aim.emission_var[:] = aim_of(values @ LUMINANCE, directions)
    if sources.sky is not None:
        values, unoccluded, directions = sky_samples(sources.sky, int(counts[-1]), receivers,
                                                     tracer, seed)
        sky, sky_var = _rgb_mean_and_variance(values)
        _add(noise, _noise_of(values @ LUMINANCE, unoccluded, 1.0))
        if aims:
            aim.sky[:], aim.sky_var[:] = aim_of(values @ LUMINANCE, directions)
    rays = sources.rays_per_texel(counts)
    return (Direct(punctual=punctual, punctual_var=punctual_var,
                   light_colours=sources.light_colours(), emission=emitted,
                   emission_var=emitted_var, sky=sky, sky_var=sky_var, rays_per_texel=rays,
                   **aim.fields()),
            noise)


def aim_of(values: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The first moment (k, 3) of luminance samples ``values`` (k, n) along their unit
    directions (k, n, 3) (``light.directional``: the mean of value × direction) and its
    variance (k,), the three components' ``mean_and_variance`` summed."""
    moment = values[..., None] * directions
    aim, variance = np.empty((len(values), 3)), np.zeros(len(values))
    for c in range(3):
        aim[:, c], part = mean_and_variance(moment[..., c])
        variance += part
    return aim, variance


@dataclass(frozen=True)
class _Aims:
    """The ``Direct`` aim fields of k receivers (0 rows: not kept), filled source by source."""

    punctual: np.ndarray
    punctual_var: np.ndarray
    emission: np.ndarray
    emission_var: np.ndarray
    sky: np.ndarray
    sky_var: np.ndarray

    @classmethod
    def blank(cls, k: int, lights: int, sources: Sources) -> "_Aims":
        emission, sky = (k if sources.emitters is not None else 0), (
            k if sources.sky is not None else 0)
        return cls(np.zeros((k, lights, 3)), np.zeros((k, lights)), np.zeros((emission, 3)),
                   np.zeros(emission), np.zeros((sky, 3)), np.zeros(sky))

    def fields(self) -> dict[str, np.ndarray]:
        """The ``Direct`` fields, by name."""
        return {"punctual_aim": self.punctual, "punctual_aim_var": self.punctual_var,
                "emission_aim": self.emission, "emission_aim_var": self.emission_var,
                "sky_aim": self.sky, "sky_aim_var": self.sky_var}


def _add(noise: _Noise, source: tuple[np.ndarray, ...]) -> None:
    """Add one source's (iid, floor, partial) to ``noise``, in place (independent sources)."""
    noise.iid[:] += source[0]
    noise.floor[:] += source[1]
    noise.partial[:] |= source[2]


def _rgb_mean_and_variance(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean (k, 3) of RGB samples (k, n, 3) and the variance (k,) of its luminance
    (``mean_and_variance``)."""
    _, variance = mean_and_variance(values @ LUMINANCE)
    return values.mean(axis=1), variance


def direct_light(scene: Scene, world: World, tracer: Tracer, texels: Texels, sources: Sources,
                 settings: Resolved, progress: Callable[[int, int], None] | None = None) -> Direct:
    """Estimate every texel's direct irradiance from every source (no ray when there is none);
    ``progress(texels, rays)`` after each chunk (its shadow and sky rays)."""
    return _rounds(scene, world, tracer, texels, sources, settings, progress, None)[0]


def adaptive_direct_light(scene: Scene, world: World, tracer: Tracer, texels: Texels,
                          sources: Sources, settings: Resolved, targets: np.ndarray,
                          progress: Callable[[int, int], None] | None = None
                          ) -> tuple[Direct, np.ndarray]:
    """``direct_light`` in adaptive rounds, and each texel's predicted error σ (N,) after them.

    A texel whose predicted error (``_predicted``) times ``adaptive.WITHIN`` is above its
    target (``targets`` (N,)) is estimated again with twice the rays of every noisy source
    (``Sources.counts``), from the start, until it is within or the rays would pass
    ``settings.max_rays``: a texel with m times the rays holds what a bake with m times the
    rays would give it, byte for byte. The rounds depend on the texels asked for (the error
    model is pooled over them), not on the chunks.
    """
    return _rounds(scene, world, tracer, texels, sources, settings, progress, targets)


def _rounds(scene: Scene, world: World, tracer: Tracer, texels: Texels, sources: Sources,
            settings: Resolved, progress: Callable[[int, int], None] | None,
            targets: np.ndarray | None) -> tuple[Direct, np.ndarray | None]:
    """``adaptive_direct_light`` (one round when ``targets`` is None: no σ then)."""
    count = len(texels)
    if not sources.any():
        return no_direct(count), (None if targets is None else np.zeros(count))
    lights = len(sources.lights)
    aims = settings.directional_pages
    out = Direct(np.zeros((count, lights)), np.zeros((count, lights)), sources.light_colours(),
                 *_source_terms(count, sources.emitters is not None),
                 *_source_terms(count, sources.sky is not None), sources.rays_per_texel(),
                 **_Aims.blank(count if aims else 0, lights, sources).fields())
    noise = _Noise(np.zeros(count), np.zeros(count), np.zeros(count, bool))
    texel_rays = np.zeros(count, np.int64)
    scales = np.ones(count)  # each texel's last round's ray scale
    active = np.arange(count)
    for scale in sources.scales(settings.max_rays) if targets is not None else [1]:
        if scale > 1:
            error = _predicted(out, noise, texels, active, scales)
            active = active[WITHIN * error > targets[active]]
            if not len(active):
                break
            if progress is not None:  # the round's rays, for the bar
                progress(0, 0, len(active) * sources.rays_per_texel(sources.counts(None, scale)))

        def work(rows: np.ndarray, scale=scale) -> None:
            receivers = texel_receivers(texels, rows, tracer.center, tracer, settings.supersample,
                                         settings.seed)
            part, part_noise = _direct_rows(scene, world, tracer, sources, receivers,
                                            settings.seed, scale=scale, aims=aims)
            _store(out, noise, rows, part, part_noise)
            texel_rays[rows] += part.rays_per_texel
            if progress is not None:
                progress(len(rows) if scale == 1 else 0, len(rows) * part.rays_per_texel)

        step = texels_per_chunk(settings.chunk_texels, int(sources.counts(None, scale).max()))
        run_chunks(work, [active[start:start + step] for start in range(0, len(active), step)],
                   settings.threads)
        scales[active] = scale
    if targets is None:
        return out, None
    return (replace(out, texel_rays=texel_rays),
            _predicted(out, noise, texels, np.arange(count), scales) if sources.noisy()
            else np.zeros(count))


def _store(out: Direct, noise: _Noise, rows: np.ndarray, part: Direct, part_noise: _Noise) -> None:
    """Write one chunk's estimates into the rows ``rows`` of ``out`` and ``noise``, in place."""
    out.punctual[rows], out.punctual_var[rows] = part.punctual, part.punctual_var
    if len(out.emission):
        out.emission[rows], out.emission_var[rows] = part.emission, part.emission_var
    if len(out.sky):
        out.sky[rows], out.sky_var[rows] = part.sky, part.sky_var
    if len(out.punctual_aim):
        out.punctual_aim[rows], out.punctual_aim_var[rows] = part.punctual_aim, part.punctual_aim_var
    if len(out.emission_aim):
        out.emission_aim[rows], out.emission_aim_var[rows] = part.emission_aim, part.emission_aim_var
    if len(out.sky_aim):
        out.sky_aim[rows], out.sky_aim_var[rows] = part.sky_aim, part.sky_aim_var
    noise.iid[rows], noise.floor[rows] = part_noise.iid, part_noise.floor
    noise.partial[rows] = part_noise.partial


def _predicted(direct: Direct, noise: _Noise, texels: Texels, rows: np.ndarray,
               scales: np.ndarray) -> np.ndarray:
    """(k,) the predicted error σ of D's luminance at the texels ``rows``, from their
    neighbours' samples, not their own (``neighbour_mean``): the neighbours' iid variance,
    per sample (× their rounds' ray ``scales`` (N,)) over the texel's own samples (÷ its
    scale: a neighbour that stopped has fewer), times the nets' gain pooled over these texels
    (``adaptive.pooled_gain``, the splits ``Direct.variance`` against the iid variances), plus
    the texel's floor where a neighbour saw a penumbra (``_Noise``).

    A texel stopped by its own samples is biased: an emitter's estimate is heavy-tailed (1/d²
    beside it), a texel whose samples missed the rare bright ones has a low mean and a low
    variance together, and it is the one that stops (a glowing closed room's D came out 13 %
    lower than uniform sampling's); one stopped by its neighbours' is not, its rounds being
    independent of its own samples."""
    iid = neighbour_mean(texels, noise.iid * scales, rows) / scales[rows]
    gain = pooled_gain(noise.iid[rows], direct.variance()[rows], noise.iid[rows] > 0, iid)
    near = neighbour_mean(texels, noise.partial.astype(np.float64), rows) > 0
    return np.sqrt(gain * iid + np.where(near, noise.floor[rows], 0.0))


# ------------------------------------------------------------------------------------------------
# Power laid on the scene's surfaces, for the ambient intensity I_A


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
        return _all_sources(self, light_colours)

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


def power_samples(settings: Resolved) -> int:
    """How many samples estimate each source's power for I_A: ``POWER_POINTS`` at
    ``DEFAULT_RAYS`` rays a texel and in proportion above (``--rays``, or with
    ``--target-error`` the most a texel may get), so that I_A's error falls with the work asked
    as every texel's does."""
    rays = settings.max_rays if settings.target_error is not None else settings.rays
    return POWER_POINTS * max(1, -(-int(rays) // DEFAULT_RAYS))


def delivered_power(scene: Scene, world: World, tracer: Tracer, sources: Sources,
                    settings: Resolved) -> Power:
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
            luminance = float(colours[l] @ LUMINANCE)
            traced = None
            if light.kind != "directional":
                traced = _traced_light_power(light, world, tracer, count, settings.seed,
                                             _traced_keys(l))
            punctual[l], spread = _kept(area * mean, traced)
            if spread is None:
                seen += mean * luminance
            else:
                variance += spread * luminance ** 2
        if sources.emitters is not None:
            mean, _ = emissive_irradiance(scene, world, sources.emitters, 1, receivers, tracer,
                                          settings.seed)
            traced = _traced_emitter_power(scene, world, sources.emitters, tracer, count,
                                           settings.seed, _traced_keys(lights))
            emitted, spread = _kept(area * mean, traced)
            if spread is None:
                seen += mean @ LUMINANCE
            else:
                variance += spread
        if sources.sky is not None:
            mean, _ = sky_irradiance(sources.sky, 1, receivers, tracer, settings.seed)
            sky = area * mean.mean(axis=0)
            seen += mean @ LUMINANCE
        variance += area * area * _strata_variance(seen)
    power = Power(punctual=punctual, light_colours=colours, emission=emitted, sky=sky,
                  area=area)
    level = float(power.total() @ LUMINANCE)
    return replace(power, relative_variance=variance / level ** 2 if level > 0 else 0.0)


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
    luminance = (lambda v: v @ LUMINANCE) if traced.ndim == 3 else (lambda v: v)
    groups = luminance(traced).mean(axis=1)
    spread = float(np.var(groups, ddof=1)) / len(groups)
    if spread <= _strata_variance(luminance(pointed)):
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
    directions = _cone_directions(axis[None], np.array([cos_max]), u)[0]
    origins = np.broadcast_to(np.asarray(light.position, np.float64), directions.shape)
    front, distance = _front_hits(world, tracer, origins, directions, light.range)
    weight = 2.0 * np.pi * (1.0 - cos_max) * range_window(light, np.where(front, distance, 0.0))
    if light.kind == "spot":
        weight = weight * spot_attenuation(light, directions)
    return np.where(front, weight, 0.0).reshape(len(keys), -1)


def _traced_emitter_power(scene: Scene, world: World, emitters: Emitters, tracer: Tracer,
                          count: int, seed: int, keys: np.ndarray) -> np.ndarray:
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
    lift = ray_lift(point, np.sqrt(emitters.areas[picked]), world.center)
    front, _ = _front_hits(world, tracer, point + lift[:, None] * normal, directions, np.inf)
    weight = (np.pi * emitters.areas[picked] * np.where(two, 2.0, 1.0)
              / emitters.probability[picked])
    radiance = emitter_radiance(scene, world, emitters, picked, bary)
    return (radiance * np.where(front, weight, 0.0)[:, None]).reshape(len(keys), -1, 3)
