"""What lights the scene directly, resolved against the settings (``light_sources``): its
KHR_lights_punctual lights with their sizes and shadow rays, its emissive triangles as area
lights sampled by power (``Emitters``), and the sky; and a term's light at the baked colours
(``all_sources``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from baker.context import Context
from baker.geometry.surface import emission_means, emission_textured, luminance
from baker.light.sky import Sky, sky_of
from baker.punctual import Light
from baker.rowwise import matmul_rows


def colours_of(terms, light_colours: np.ndarray | None) -> np.ndarray:
    """(L, 3) the light colours × intensities ``light_colours`` as float64, or when None those
    ``terms`` (a ``Direct`` or ``Power``) were baked with."""
    return terms.light_colours if light_colours is None else np.asarray(light_colours, np.float64)


def all_sources(terms, light_colours: np.ndarray | None) -> np.ndarray:
    """punctual × colours + emission + sky of a ``Direct`` or ``Power``: the per-light terms at
    unit intensity times the light colours × intensities (L, 3), by default the baked ones."""
    out = matmul_rows(terms.punctual, colours_of(terms, light_colours))  # a new array: the sums go into it in place
    for term in (terms.emission, terms.sky):  # empty when the scene has no such source
        if len(term):
            out += term
    return out


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

    lights: the scene's punctual lights (order of ``Context.lights``). spread: (L,) float64, a
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

    def exact(self, terms, light_colours: np.ndarray | None = None) -> np.ndarray:
        """(N, 3) the light of a ``Direct``'s texels from the hard lights alone (no spread, one
        shadow ray: no noise, only the shadow's edge), with ``light_colours`` (L, 3) as
        composed, by default the baked ones: what smoothing leaves as it is (``world_filter``)."""
        hard = (self.spread == 0) & (self.samples == 1)
        return matmul_rows(terms.punctual,
                           np.where(hard[:, None], colours_of(terms, light_colours), 0.0))

    def unmeasured(self) -> list[str]:
        """What lights the scene with noise that no error estimate sees: the sources cast with
        one ray a texel (a soft light's single shadow ray, one ray towards the emitters or the
        sky), whose texels have no two halves to measure it by
        (``direct_estimators.mean_and_variance``): a phrase for each."""
        soft = [light for light, spread, samples in zip(self.lights, self.spread, self.samples)
                if spread > 0 and samples == 1]
        out = [f"light {light.index}'s soft shadow, cast with 1 shadow ray" for light in soft]
        if self.emitters is not None and self.emissive_rays == 1:
            out.append("the emitters, cast with 1 emissive ray")
        if self.sky is not None and self.sky_rays == 1:
            out.append("the sky, cast with 1 sky ray")
        return out

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


def find_emitters(context: Context) -> Emitters | None:
    """The triangles that emit (positive mean emission and area), None when there are none."""
    world = context.world
    if len(world.triangles) == 0:
        return None
    mean = emission_means(context.surfaces, world)
    areas = world.areas()
    sides = np.where([c.double_sided for c in context.materials.classes], 2.0,
                     1.0)[world.tri_material]
    weight = areas * np.maximum(luminance(mean), 0.0) * sides
    emitting = np.flatnonzero((weight > 0) & np.isfinite(weight))
    if len(emitting) == 0:
        return None
    w = weight[emitting]
    probability = w / w.sum()
    cdf = np.cumsum(probability)
    cdf[-1] = 1.0
    textured = emission_textured(context.surfaces)
    return Emitters(triangles=emitting, probability=probability, cdf=cdf, areas=areas[emitting],
                    normals=world.geometric_normals(emitting), two_sided=sides[emitting] > 1,
                    power=float(math.pi * w.sum()),
                    corners=world.positions[world.triangles[emitting]],
                    radiance=mean[emitting], textured=textured[world.tri_material[emitting]],
                    area_share=float(areas[emitting].sum() / areas.sum()))


def light_sources(context: Context) -> Sources:
    """The scene's direct-light sources with the settings' fallbacks and ray counts applied."""
    settings = context.settings
    spread, samples = [], []
    for light in context.lights:
        if light.kind == "directional":
            diameter = (light.angular_diameter if light.angular_diameter is not None
                        else math.radians(settings.light_angle))
            size = min(diameter / 2, math.pi / 2 - 1e-6)
        else:
            size = light.radius if light.radius is not None else settings.light_radius
        spread.append(size)
        samples.append(max(settings.shadow_rays if size > 0 else 1, settings.supersample))
    return Sources(lights=context.lights, spread=np.asarray(spread, np.float64).reshape(-1),
                   samples=np.asarray(samples, np.int64).reshape(-1),
                   emitters=find_emitters(context), emissive_rays=settings.emissive_rays,
                   sky=sky_of(settings), sky_rays=settings.sky_rays)
