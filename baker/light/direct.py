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

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from baker.atlas.rasterise import Texels
from baker.atlas.supersample import sub_positions
from baker.context import Context
from baker.geometry.surface import luminance
from baker.light.adaptive import WITHIN, neighbour_mean, pooled_gain
from baker.light.direct_estimators import (
    Receivers,
    emissive_samples,
    mean_and_variance,
    punctual_samples,
    rgb_mean_and_variance,
    sky_samples,
)
from baker.light.sources import Sources, all_sources, colours_of
from baker.rays.dimensions import light_dimension
from baker.rays.trace import Tracer, ray_lift
from baker.rowwise import dot_rows
from baker.run.parallel import run_chunks, texels_per_chunk


def _source_terms(count: int, present: bool) -> tuple[np.ndarray, np.ndarray]:
    """Zeroed (count, 3) irradiance and (count,) variance of a source kind, or empty ones (0
    rows) when the scene has no such source."""
    rows = count if present else 0
    return np.zeros((rows, 3)), np.zeros(rows)


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
        colours = colours_of(self, light_colours)
        out = np.einsum("nlc,l->nc", self.punctual_aim, luminance(colours))
        for term in (self.emission_aim, self.sky_aim):
            if len(term):
                out += term
        return out

    def aim_variance(self, light_colours: np.ndarray | None = None) -> np.ndarray:
        """(N,) the variance of ``aim``'s estimate (the sources' are independent)."""
        if not len(self.punctual_aim):
            return np.zeros(0)
        colours = colours_of(self, light_colours)
        out = dot_rows(self.punctual_aim_var, luminance(colours) ** 2)
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
        return all_sources(self, light_colours)

    def variance(self, light_colours: np.ndarray | None = None) -> np.ndarray:
        """(N,) variance of the luminance of D's estimate (the sources' estimates are independent)."""
        colours = colours_of(self, light_colours)
        out = dot_rows(self.punctual_var, luminance(colours) ** 2)  # a new array, summed in place
        for term in (self.emission_var, self.sky_var):
            if len(term):
                out += term
        return out


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


def direct_at(context: Context, sources: Sources, receivers: Receivers, seed: int,
              samples: int | None = None) -> Direct:
    """Direct irradiance at ``receivers`` from every source, kept apart per source.

    ``samples``: shadow/sky rays per receiver for every source (None: each source's own count,
    as a bake uses them; the full-GI reference takes 1 at each bounce).
    """
    return _direct_rows(context, sources, receivers, seed, samples)[0]


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


def _direct_rows(context: Context, sources: Sources, receivers: Receivers, seed: int,
                 samples: int | None = None, scale: int = 1, aims: bool = False
                 ) -> tuple[Direct, _Noise]:
    """``direct_at``, with each noisy source's rays × ``scale`` (an adaptive round:
    ``Sources.counts``), and its ``_Noise``; ``aims``: keep each source's ``Direct.aim``."""
    tracer = context.tracer
    k = len(receivers.position)
    lights = len(sources.lights)
    punctual, punctual_var = np.zeros((k, lights)), np.zeros((k, lights))
    emitted, emitted_var = _source_terms(k, sources.emitters is not None)
    sky, sky_var = _source_terms(k, sources.sky is not None)
    aim = _Aims.blank(k if aims else 0, lights, sources)
    noise = _Noise(np.zeros(k), np.zeros(k), np.zeros(k, bool))
    counts = sources.counts(samples, scale)
    colours = luminance(sources.light_colours())
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
            context, sources.emitters, int(counts[-2]), receivers, seed)
        emitted, emitted_var = rgb_mean_and_variance(values)
        _add(noise, _noise_of(luminance(values), unoccluded, 1.0))
        if aims:
            aim.emission[:], aim.emission_var[:] = aim_of(luminance(values), directions)
    if sources.sky is not None:
        values, unoccluded, directions = sky_samples(sources.sky, int(counts[-1]), receivers,
                                                     tracer, seed)
        sky, sky_var = rgb_mean_and_variance(values)
        _add(noise, _noise_of(luminance(values), unoccluded, 1.0))
        if aims:
            aim.sky[:], aim.sky_var[:] = aim_of(luminance(values), directions)
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


def direct_light(context: Context, texels: Texels, sources: Sources,
                 progress: Callable[[int, int], None] | None = None) -> Direct:
    """Estimate every texel's direct irradiance from every source (no ray when there is none);
    ``progress(texels, rays)`` after each chunk (its shadow and sky rays)."""
    return _rounds(context, texels, sources, progress, None)[0]


def adaptive_direct_light(context: Context, texels: Texels, sources: Sources,
                          targets: np.ndarray,
                          progress: Callable[[int, int], None] | None = None
                          ) -> tuple[Direct, np.ndarray]:
    """``direct_light`` in adaptive rounds, and each texel's predicted error σ (N,) after them.

    A texel whose predicted error (``_predicted``) times ``adaptive.WITHIN`` is above its
    target (``targets`` (N,)) is estimated again with twice the rays of every noisy source
    (``Sources.counts``), from the start, until it is within or the rays would pass
    ``max_rays`` (the context's settings): a texel with m times the rays holds what a bake with m times the
    rays would give it, byte for byte. The rounds depend on the texels asked for (the error
    model is pooled over them), not on the chunks.
    """
    return _rounds(context, texels, sources, progress, targets)


def _rounds(context: Context, texels: Texels, sources: Sources,
            progress: Callable[[int, int], None] | None,
            targets: np.ndarray | None) -> tuple[Direct, np.ndarray | None]:
    """``adaptive_direct_light`` (one round when ``targets`` is None: no σ then)."""
    tracer, settings = context.tracer, context.settings
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
            part, part_noise = _direct_rows(context, sources, receivers, settings.seed,
                                            scale=scale, aims=aims)
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
