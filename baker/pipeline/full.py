"""The full bake from a loaded scene to its float lightmaps, as a list of stages (``STAGES``,
docs/design.md §3):

    lights and plan → unwrap → rasterise → parts → foliage fit → texels and rays → post-process

Each stage calls the modules that do its work; ``run.stages.run_stages`` runs them in order,
prints a line for each and times them. Loading before and encoding and writing after are the
API's (``baker.load``, ``baker.encode``, ``baker.write``).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from typing import Callable, Protocol

import numpy as np

from baker.atlas.layout import Atlas
from baker.atlas.rasterise import (
    Coverage,
    Owners,
    Texels,
    cover_and_owners,
    texels_of,
)
from baker.atlas.authored import authored_atlas
from baker.atlas.unwrap import PageTooSmall, baked_instances, frame_area, unwrap
from baker.atlas.validity import (HEMISPHERE_RAYS, TANGENT_RAYS, TANGENT_ROUNDS, Faces, Validity,
                                  check_texels)
from baker.context import Context, context_of
from baker.geometry.surface import luminance
from baker.geometry.world import World, build_world
from baker.gltf.materials import has_normal_maps
from baker.gltf.scene import Scene
from baker.image.compose import (
    Lightmaps,
    blank,
    compose_into,
    directional_pages,
    effective_r_ave,
)
from baker.image.denoise import DenoiseInfo, denoise
from baker.image.errormap import light_variance
from baker.image.world_filter import Smoothed, smooth_pages
from baker.image.postprocess import postprocess
from baker.image.seams import find_seams
from baker.light.adaptive import (
    direct_goes_first,
    first_target,
    obscurance_settings,
    what_is_left,
)
from baker.light.ambient import Ambient, ambient_terms
from baker.light.environment import environment
from baker.light.direct import Direct, adaptive_direct_light, direct_light
from baker.light.power import Power, delivered_power
from baker.light.sources import Sources, light_sources
from baker.light.foliage import (
    FitInputs,
    Foliage,
    integrate_with_foliage,
    prepare_foliage,
    shaded,
)
from baker.light.gi import Indirect, indirect_light, rays_per_path
from baker.light.hemisphere import Surfaces, Terms, surfaces_of, texel_errors
from baker.light.integrate import integrate
from baker.pipeline import cluster
from baker.pipeline.parts import PerTexel, Tally, TexelPoints, part_slices
from baker.pipeline.plan import Plan, make_plan
from baker.rays.trace import Tracer
from baker.run.progress import Meter, StageLines, Steps, bar, wanted
from baker.run.spill import Spill
from baker.run.stages import Stage, run_stages, timed
from baker.errors import SettingsError
from baker.settings import Resolved, Settings, resolve


def bounds_of_baked(world, scene) -> tuple[float, float]:
    """Area and world bounds diagonal of the baked instances (for default settings).

    The area is summed in each instance's rigid-free frame (``unwrap.frame_area``), so a rigid
    move of a node leaves the derived texel density bit-identical (incremental rebake)."""
    tris = np.concatenate([world.instance_triangles(i) for i in baked_instances(scene)] or
                          [np.zeros(0, np.int64)])
    if len(tris) == 0:
        return 0.0, 0.0
    corner = np.zeros(len(world.positions), bool)
    corner[world.triangles[tris]] = True  # each vertex once: the bounds are those of the corners
    points = world.positions[corner]
    return frame_area(scene, world), float(np.linalg.norm(points.max(0) - points.min(0)))


@dataclass(frozen=True)
class Computed:
    """Everything a bake computed before encoding, for the report, tests and benchmarks.

    ``per_texel`` holds the texels and their results, in memory or on disk (``parts.py``);
    ``texels``, ``validity``, ``terms`` and ``direct`` load them whole on first use. ``tally``
    has what the report needs of them without loading them.
    """

    scene: Scene
    world: World
    settings: Resolved
    ambient: Ambient
    plan: Plan
    atlas: Atlas
    per_texel: PerTexel
    tally: Tally
    lightmaps: Lightmaps
    stage_seconds: dict[str, float]
    sources: Sources | None = None  # what lights the scene directly (sources.py)
    power: Power | None = None  # what each source lays on the surfaces, for I_A
    denoised: DenoiseInfo | None = None  # what --denoise did (denoise.py); None: not denoised
    foliage: Foliage | None = None  # --foliage approx: the crowns and their fit (foliage.py)
    indirect_variance: np.ndarray | None = None  # --method gi: (N,) gi.Indirect.variance
    smoothed: Smoothed | None = None  # what --smooth did (world_filter.py); None: not asked

    @property
    def texels(self) -> Texels:
        return self.per_texel.texels

    @property
    def coverage(self) -> Coverage:
        """The texels' keys and owning triangles (``PerTexel.coverage``)."""
        return self.per_texel.coverage

    def context(self, settings: Resolved | None = None) -> Context:
        """What every estimator needs of this bake (its ``Context``), Embree's scene made anew,
        with its settings or ``settings``: for studies and tests that trace its texels again."""
        return context_of(self.scene, self.world, Tracer(self.world),
                          self.settings if settings is None else settings)

    @property
    def validity(self) -> Validity:
        """Which sample points were moved or flagged (validity.py)."""
        return self.per_texel.validity

    @property
    def terms(self) -> Terms:
        """The terms the texels' light was composed from (with --foliage approx, the traced
        texels shaded by the crowns: ``foliage.shaded``; the state keeps them unshaded)."""
        if self.foliage is None:
            return self.per_texel.terms
        return shaded(self.foliage, self.texels, self.per_texel.terms, self.settings.d_max)

    @property
    def direct(self) -> Direct | None:
        """The texels' direct light, per source."""
        return self.per_texel.direct

    def obscurance_rmse(self) -> float:
        """RMSE of the luminance of I_A·W estimated from the rays (``Terms.rmse``)."""
        return self.tally.obscurance_rmse() * float(
            luminance(self.ambient.intensity))

    def rmse_estimate(self) -> float:
        """RMSE of the lightmap's luminance estimated from the rays: D's, and I_A·W's (its
        rays', and I_A's own: ``Ambient.relative_variance`` × the mean square of I_A·W) or,
        with ``--method gi``, the path-traced indirect light's (``gi.Indirect.variance``)."""
        if not self.tally.texels:
            return 0.0
        direct = self.tally.direct_variance / self.tally.texels
        shared = 0.0
        if self.settings.method != "gi":
            shared = self.ambient.relative_variance * self.tally.ambient_squares / self.tally.texels
        if self.smoothed is not None and self.smoothed.width > 0:  # the smoothed light's
            return float(np.sqrt(self.smoothed.error ** 2 + shared))
        if self.settings.method == "gi":
            return float(np.sqrt(direct + self.tally.indirect_variance / self.tally.texels))
        return float(np.sqrt(self.obscurance_rmse() ** 2 + shared + direct))


@dataclass(frozen=True)
class Lighting:
    """What a bake and a rebake both need before any texel (``lighting``): what every
    estimator needs (``context.Context``: the world, its materials, Embree's scene, the lights,
    the settings), the light sources, the power they deliver, I_A and R_ave, and the plan."""

    context: Context
    sources: Sources
    power: Power
    ambient: Ambient
    plan: Plan

    @property
    def tracer(self) -> Tracer:
        return self.context.tracer

    def without_tracer(self) -> Lighting:
        """This ``Lighting`` without Embree's scene, to be sent to another process (which
        makes its own: ``with_tracer``)."""
        return replace(self, context=self.context.with_tracer(None))

    def with_tracer(self, tracer: Tracer) -> Lighting:
        """This ``Lighting`` tracing with ``tracer``."""
        return replace(self, context=self.context.with_tracer(tracer))


def lighting(scene: Scene, world: World, resolved: Resolved, times: dict[str, float]
             ) -> Lighting:
    """The scene's ``Lighting``, its ``Context`` made here once; adds the stages "lights" and
    "plan" to ``times``."""
    with timed(times, "lights"):
        context = context_of(scene, world, Tracer(world), resolved)
        sources = light_sources(context)
        power = delivered_power(context, sources)
    with timed(times, "plan"):
        surround = environment(world, context.tracer, sources, resolved.escape, resolved.seed)
        ambient = ambient_terms(context, power, surround.neutral)
        plan = make_plan(scene, world.materials, ambient, resolved.rho, sources, surround,
                         resolved.directional)
    return Lighting(context, sources, power, ambient, plan)


@dataclass(frozen=True)
class Baking:
    """What every part of a bake needs (``compute``)."""

    scene: Scene
    world: World
    settings: Resolved
    lit: Lighting
    atlas: Atlas
    coverage: Coverage | None = None  # which triangle owns each texel (rasterise.cover)
    owned: Owners | None = None  # what the texels take from their triangles (rasterise.owners)
    faces: Faces | None = None  # back faces, for the validity probes
    surfaces: Surfaces | None = None  # shading of obscurance hits (integrate.surfaces_of)
    foliage: Foliage | None = None  # --foliage approx: crowns in closed form (foliage.py)

    @property
    def tracer(self) -> Tracer:
        return self.lit.tracer

    @property
    def context(self) -> Context:
        """What every estimator needs, with the settings as the unwrap left them."""
        return self.lit.context.with_settings(self.settings)

    @property
    def sources(self) -> Sources:
        return self.lit.sources

    @property
    def ambient(self) -> Ambient:
        return self.lit.ambient


@dataclass(frozen=True)
class BakedPart:
    """One part's texels and what was computed for them (``_bake_part``): the texels with their
    sample points moved by the probes, what the state keeps of them, validity, obscurance terms,
    direct light, and the full-GI indirect light (``gi.Indirect``) with ``--method gi``, else None."""

    texels: Texels
    points: TexelPoints
    validity: Validity
    terms: Terms
    direct: Direct
    indirect: Indirect | None = None

    def held(self) -> PerTexel:
        """The part's results as a bake's ``PerTexel`` (a bake of one part)."""
        return PerTexel.held(self.texels, self.points, self.validity, self.terms, self.direct)


class StateSink(Protocol):
    """Where a bake's state goes once its texels are final (``rebake.staging.StateStaging``):
    ``start`` is called with what every part needed and the texels' results, before the pages
    are post-processed, so that the state can be written beside that work."""

    def start(self, baking: Baking, per_texel: PerTexel, fingerprint: dict | None = None
              ) -> None: ...


@dataclass(frozen=True)
class Underway:
    """A full bake between two of its ``STAGES``: what was asked (the scene, the settings, how
    to run), the seconds of each ``stage_seconds`` key so far, and what the stages before made
    (None until made)."""

    scene: Scene
    asked: Settings
    quiet: bool
    spill_folder: str | os.PathLike | None
    staging: StateSink | None
    prepared: tuple[World, Lighting] | None
    times: dict[str, float]
    world: World | None = None
    settings: Resolved | None = None  # ``asked`` resolved for the scene; the unwrap's density
    lit: Lighting | None = None
    atlas: Atlas | None = None
    coverage: Coverage | None = None
    owned: Owners | None = None
    baking: Baking | None = None  # what every part needs (``parts``)
    slices: tuple[slice, ...] = ()  # the coverage rows of each part
    spill: Spill | None = None  # where the parts' rows go, with more than one part
    pages: _Pages | None = None
    per_texel: PerTexel | None = None
    computed: Computed | None = None

    def abandon(self) -> None:
        """A stage failed (an error, Ctrl-C): no spilled rows left behind."""
        if self.spill is not None:
            self.spill.close()


def _lights_and_plan(w: Underway) -> Underway:
    """The world (timed as "load"), the settings resolved for its bounds, and its ``Lighting``
    (``lighting``), or the world and ``Lighting`` a rebake ``prepared``."""
    scene = w.scene
    with timed(w.times, "load"):
        world = build_world(scene) if w.prepared is None else w.prepared[0]
    area, diagonal = bounds_of_baked(world, scene)
    resolved = resolve(w.asked, area, diagonal, normal_maps=has_normal_maps(scene),
                       lights_needed=scene.lights_needed())
    lit = lighting(scene, world, resolved, w.times) if w.prepared is None else w.prepared[1]
    return replace(w, world=world, settings=resolved, lit=lit)


def _unwrap(w: Underway, steps: Steps) -> Underway:
    """The atlas: the artist's lightmap UVs (``settings.uv``), else the unwrap's
    (``_unwrapped``), with the density it used in the settings."""
    if w.asked.uv is not None:  # the artist's lightmap UVs: no unwrap
        return replace(w, atlas=authored_atlas(w.scene, w.world, w.settings))
    atlas, resolved = _unwrapped(w.scene, w.world, w.asked, w.settings, steps)
    return replace(w, atlas=atlas, settings=resolved)


def _rasterise(w: Underway) -> Underway:
    """Which triangle owns each texel and what the texels take from it (``rasterise``)."""
    coverage, owned = cover_and_owners(w.atlas, w.world)
    return replace(w, coverage=coverage, owned=owned)


def _parts(w: Underway) -> Underway:
    """What every part needs (``Baking``), the ray budget checked (``check_ray_budget``), the
    texels cut into parts and, for more than one, the folder their rows go to."""
    scene, world, resolved = w.scene, w.world, w.settings
    count = len(w.coverage.key)
    slices = part_slices(count, cluster.part_texels(count) if resolved.cluster is not None
                         else None)
    baking = Baking(scene, world, resolved, w.lit, w.atlas, w.coverage, w.owned,
                    Faces(scene, world), surfaces_of(w.lit.context))
    check_ray_budget(baking, count)
    check_light_terms(baking, count)
    spill = Spill(w.spill_folder) if len(slices) > 1 else None
    return replace(w, baking=baking, slices=tuple(slices), spill=spill)


def _fit_foliage(w: Underway) -> Underway:
    """--foliage approx: the crowns fitted to the leaves they stand for (``foliage.py``)."""
    baking, lit = w.baking, w.lit
    return replace(w, baking=replace(baking, foliage=prepare_foliage(
        baking.context, FitInputs(
            w.atlas, w.coverage, w.owned, baking.faces, baking.surfaces,
            effective_r_ave(lit.ambient, w.settings.rho)))))


def _texels_and_rays(w: Underway) -> Underway:
    """Every part's texels made, probed, traced, lit and composed (``_bake_parts``); their
    results, held or spilled (``PerTexel``)."""
    pages, last = _bake_parts(w.baking, list(w.slices), w.spill, w.times, w.quiet)
    per_texel = (PerTexel.spilled(w.spill, w.atlas, w.world) if w.spill is not None
                 else last.held())
    return replace(w, pages=pages, per_texel=per_texel)


def _post_process(w: Underway, steps: Steps) -> Underway:
    """The bake state started, the pages denoised and post-processed (``_finish_pages``)."""
    return replace(w, computed=_finish_pages(w.baking, w.per_texel, w.pages, w.times,
                                             w.staging, steps=steps))


STAGES: tuple[Stage[Underway], ...] = (
    Stage("lights and plan", _lights_and_plan),
    Stage("unwrap", _unwrap, "unwrap", "triangles"),
    Stage("rasterise", _rasterise, "rasterise"),
    Stage("parts", _parts, shown=False),
    Stage("foliage fit", _fit_foliage, "foliage fit",
          when=lambda w: w.settings.foliage == "approx"),
    Stage("texels and rays", _texels_and_rays,
          detail=lambda w: f"{len(w.baking.coverage.key):,} texels"),
    Stage("post-process", _post_process, unit="texels"),
)
"""The full bake, stage by stage, from the loaded scene to the post-processed float lightmaps:
each stage's name is the line a bake prints as it ends, its second field the function that
does it, its third the key of ``stage_seconds`` its time goes to (none: it times its own
keys) and its fourth what its progress counts (``run.stages.Stage``)."""


def compute(scene: Scene, settings: Settings, quiet: bool = True,
            spill_folder: str | os.PathLike | None = None,
            staging: StateSink | None = None,
            prepared: tuple[World, Lighting] | None = None) -> Computed:
    """Run every stage (``STAGES``) from the loaded scene up to the post-processed float
    lightmaps; ``quiet=False`` prints a line per stage with its time, and the rays' bar.

    The texels are made, traced and composed a part at a time (``parts.py``); when there are
    several parts, each part's results go to a temporary folder in ``spill_folder`` (None: the
    system's) until the bake state is written (``Computed.per_texel``). ``staging``: where the
    bake state starts to be written once the texels are done. ``prepared``: the scene's world
    and ``Lighting`` with these settings, already made (by a rebake that fell back to this
    bake, ``rebake.fallback.FullBake``): the same objects this bake would make.
    """
    scene.check_not_a_bake()
    underway = Underway(scene, settings, quiet, spill_folder, staging, prepared, times={})
    return run_stages(STAGES, underway, StageLines(not quiet)).computed


def _unwrapped(scene: Scene, world: World, settings: Settings, resolved: Resolved,
               steps: Steps) -> tuple[Atlas, Resolved]:
    """The atlas and the settings with the density it used: a derived density is
    lowered to fit a page (``unwrap.py``); the user's is kept or refused with what fits.
    ``steps``: the triangles charted, as they are."""
    derived = settings.texel_density is None
    elsewhere = cluster.chart_on_workers if resolved.cluster is not None else None
    try:
        atlas = unwrap(scene, world, resolved, fit_one_page=derived, steps=steps,
                       chart_elsewhere=elsewhere)
    except PageTooSmall as error:
        if not derived:  # the user's density: say what fits
            raise
        resolved = replace(resolved, texel_density=error.texel_density)  # derived: shrink it
        atlas = unwrap(scene, world, resolved, fit_one_page=True, steps=steps,
                       chart_elsewhere=elsewhere)
    return atlas, replace(resolved, texel_density=atlas.texel_density)


def rays_per_texel(baking: Baking) -> tuple[float, float | None, float | None]:
    """The first estimates of rays a texel casts in each ray stage: obscurance (``rays``),
    direct light (shadow and sky rays; None without a source) and GI paths' rays (None
    without ``--method gi``); the progress bar's starting figures and the ray budget's."""
    s, sources = baking.settings, baking.sources
    direct = sources.rays_per_texel() if sources.any() else None
    gi = s.rays * rays_per_path(sources, baking.ambient.r_ave) if s.method == "gi" else None
    return s.rays, direct, gi


PROBE_RAYS = HEMISPHERE_RAYS + TANGENT_RAYS * TANGENT_ROUNDS
"""The most validity probes a texel casts (``atlas.validity``)."""


def check_ray_budget(baking: Baking, texels: int) -> None:
    """SettingsError, before any ray is cast, when ``texels`` × the rays each casts (obscurance,
    direct light, GI — their most with ``target_error`` —, validity probes) exceeds
    ``max_total_rays``: the message gives the figures and what makes them (the lights, for a
    scene of many), the fix the setting that would allow it and what makes fewer."""
    s, sources = baking.settings, baking.sources
    obscurance, direct, gi = rays_per_texel(baking)
    if s.target_error is not None:
        obscurance = max(obscurance, s.max_rays)
        direct = sources.most_rays_per_texel(s.max_rays) if direct is not None else None
        gi = gi * max(s.max_rays, s.rays) / s.rays if gi is not None else None
    parts = {"obscurance": obscurance, "direct light": direct or 0, "GI paths": gi or 0,
             "validity probes": PROBE_RAYS}
    per_texel = sum(parts.values())
    total = texels * per_texel
    if total <= s.max_total_rays:
        return
    shown = ", ".join(f"{name} {value:,.0f}" for name, value in parts.items() if value)
    lights = (f"; the scene's {len(sources.lights):,} lights cast {int(sources.samples.sum()):,}"
              if len(sources.lights) else "")
    raise SettingsError(
        f"this bake would cast about {total:.3g} rays, more than max_total_rays "
        f"{s.max_total_rays:.3g}: {texels:,} texels × {per_texel:,.0f} rays each ({shown}"
        f"{lights})", fix=f"use --max-total-rays {math.ceil(total):d} if the time is yours to "
                          "spend, or fewer --rays, a lower --texel-density or fewer lights")


LIGHT_TERM_BYTES = 1 << 31
"""Most bytes of per-light terms a bake keeps (2 GiB): each punctual light's irradiance and
its variance at every texel, 16 bytes (48 with --directional's aims), held for composing and
relighting and written to the bake state: 134 lights over 1,000,000 texels. A 520 kB file of
5,000 point lights over a 1024² page's texels asked for 28 GB and hours."""


def check_light_terms(baking: Baking, texels: int) -> None:
    """SettingsError, before any ray is cast, when the scene's punctual lights' terms at
    ``texels`` would take more than ``LIGHT_TERM_BYTES``; the message gives the figures and
    how many lights these texels allow."""
    lights = len(baking.sources.lights)
    per_pair = 48 if baking.settings.directional_pages else 16
    if texels * lights * per_pair <= LIGHT_TERM_BYTES:
        return
    raise SettingsError(
        f"the scene's {lights:,} punctual lights at {texels:,} texels would keep "
        f"{texels * lights * per_pair / 2 ** 30:.1f} GiB of terms (each light's irradiance at "
        f"each texel, for relighting), more than baker keeps ({LIGHT_TERM_BYTES >> 30} GiB: "
        f"{LIGHT_TERM_BYTES // (per_pair * max(texels, 1)):,} lights at these texels)",
        fix="merge small lights into fewer, or bake at a lower --texel-density or a smaller "
            "--page-size")


@dataclass(frozen=True)
class _RayStages:
    """The progress reports ``(texels, rays)`` of a bake's ray-casting stages, registered on
    one ``run.progress.Meter`` with their first estimates of rays per texel: obscurance rays,
    direct light's shadow and sky rays, GI's paths (``gi.rays_per_path``)."""

    meter: Meter
    obscurance: Callable[[int, int], None]
    direct: Callable[[int, int], None] | None
    gi: Callable[[int, int], None] | None
    estimates: tuple[float, ...]  # the first rays per texel of each stage there is, in order

    @classmethod
    def of(cls, meter: Meter, baking: Baking, count: int) -> "_RayStages":
        estimates = rays_per_texel(baking)
        stages = [None if per is None else meter.stage(count, per) for per in estimates]
        return cls(meter, *stages, estimates=tuple(per for per in estimates if per is not None))

    def whole_parts(self) -> Callable[[int], None]:
        """For parts made elsewhere (``cluster.parts``), which say only their texels when done:
        every stage advanced by them, at its first estimate of rays per texel."""
        reports = [r for r in (self.obscurance, self.direct, self.gi) if r is not None]

        def advance(texels: int) -> None:
            self.meter.start()
            for report, per_texel in zip(reports, self.estimates):
                report(texels, round(texels * per_texel))

        return advance


def _bake_parts(baking: Baking, slices: list[slice], spill: Spill | None,
                times: dict[str, float], quiet: bool) -> tuple["_Pages", BakedPart]:
    """Bake the texels a part (``slices``) at a time, each composed into the pages as it is
    done and, with a ``spill``, its rows appended to it. Returns the composed ``_Pages``, and
    the last ``BakedPart`` — all the texels' when there is one part."""
    count = len(baking.coverage.key)
    pages = _Pages.blank(baking)
    with bar("baking", wanted(quiet)) as meter:
        stages = _RayStages.of(meter, baking, count)
        made = (cluster.parts(_bake_part, baking, slices, times, stages.whole_parts())
                if baking.settings.cluster is not None else
                (_bake_part(baking, rows, times, stages) for rows in slices))
        for part in made:
            with timed(times, "compose"):
                pages.add(baking, part.texels, part.validity, part.terms, part.direct,
                          part.indirect)
            if spill is not None:
                with timed(times, "spill"):
                    for name, group in (("texels", part.points), ("validity", part.validity),
                                        ("terms", part.terms), ("direct", part.direct)):
                        spill.append(name, group)
    return pages, part


def _bake_part(baking: Baking, rows: slice, times: dict[str, float],
               stages: "_RayStages | None") -> BakedPart:
    """Make, probe, trace and light the texels ``rows``, reporting to ``stages`` (None: to no
    bar, as on a cluster's worker)."""
    stages = stages or _RayStages.of(Meter(), baking, 0)
    s, ambient, scene, world, tracer = (baking.settings, baking.ambient, baking.scene,
                                        baking.world, baking.tracer)
    with timed(times, "rasterise"):
        made = texels_of(baking.atlas, world, baking.coverage, rows, baking.owned)
    with timed(times, "validity"):  # sample points inside/behind geometry: moved or flagged
        texels, validity = check_texels(scene, world, tracer, made, s.d_max, faces=baking.faces)
        points = TexelPoints.of(texels, made.position)
    stages.meter.start()
    indirect, direct, targets = None, None, None
    if s.target_error is not None:  # the first term's share of the target (adaptive.py)
        targets = np.full(len(texels), first_target(s, baking.sources.noisy()))
        if direct_goes_first(s):
            direct, targets = _adaptive_direct(baking, texels, targets, times, stages)
    if s.method == "gi":  # the full-GI reference instead of I_A·W (gi.py); first, as it is
        with timed(times, "gi"):  # most of the work: the bar's rate is then its rate
            indirect = indirect_light(baking.context, baking.sources, texels, s.rays,
                                      progress=stages.gi, targets=targets)
    with timed(times, "trace"):
        error_scale = (effective_r_ave(ambient, s.rho), float(luminance(ambient.intensity)))
        traced = baking.context.with_settings(obscurance_settings(s))
        if baking.foliage is None:
            terms = integrate(traced, texels, stages.obscurance, error_scale=error_scale,
                              surfaces=baking.surfaces, targets=targets)
        else:
            terms = integrate_with_foliage(baking.foliage, traced, texels, stages.obscurance,
                                           error_scale, baking.surfaces, targets)
    if direct is None and s.target_error is not None:
        error = texel_errors(terms, error_scale, texels, np.arange(len(texels)))
        left = what_is_left(s.target_error, error)
        direct, _ = _adaptive_direct(baking, texels, left, times, stages)
    elif direct is None:
        with timed(times, "direct"):
            direct = direct_light(baking.context, texels, baking.sources, stages.direct)
    return BakedPart(texels, points, validity, terms, direct, indirect)


def _adaptive_direct(baking: Baking, texels: Texels, targets: np.ndarray,
                     times: dict[str, float], stages: "_RayStages") -> tuple[Direct, np.ndarray]:
    """The direct light in adaptive rounds to ``targets`` (N,), and what it leaves of the
    target to the other term (``adaptive.what_is_left``)."""
    with timed(times, "direct"):
        direct, error = adaptive_direct_light(baking.context, texels, baking.sources, targets,
                                              stages.direct)
    return direct, what_is_left(baking.settings.target_error, error)


def finish(scene: Scene, world: World, resolved: Resolved, lit: Lighting, atlas: Atlas,
           per_texel: PerTexel, times: dict[str, float], staging: StateSink | None = None,
           fingerprint: dict | None = None, foliage: Foliage | None = None) -> Computed:
    """From the texels' results, all held in memory (``PerTexel.held``), to the post-processed
    float lightmaps: an incremental rebake (``rebake.incremental``) ends as a full bake does, so
    both give the same bytes (``staging`` and the scene's ``fingerprint``: the bake state, as in
    ``compute``; ``foliage``: the crowns that shade the traced texels, with --foliage approx).
    """
    baking = Baking(scene, world, resolved, lit, atlas, foliage=foliage)
    with timed(times, "compose"):
        pages = _Pages.blank(baking)
        pages.add(baking, per_texel.texels, per_texel.validity, per_texel.terms,
                  per_texel.direct)
    return _finish_pages(baking, per_texel, pages, times, staging, fingerprint)


@dataclass
class _Pages:
    """What the texels are composed into, part by part: the lightmaps, the validity's page
    masks (invalid, enclosed) and the report's ``Tally``."""

    lightmaps: Lightmaps
    masks: tuple[np.ndarray, np.ndarray]
    tally: Tally
    indirect_variance: list[np.ndarray]  # --method gi: each part's gi.Indirect.variance
    variance: list[np.ndarray]  # --smooth: each part's errormap.light_variance, unfloored
    exact: list[np.ndarray]  # --smooth: each part's light from hard lights (Sources.exact)

    @classmethod
    def blank(cls, baking: Baking) -> "_Pages":
        """Nothing composed yet (pages of the visibility only for the occlusion texture)."""
        lightmaps = blank(baking.atlas, visibility=writes_occlusion(baking.settings),
                          directional=baking.settings.directional_pages)
        return cls(lightmaps, (np.zeros_like(lightmaps.covered),
                               np.zeros_like(lightmaps.covered)), Tally(), [], [], [])

    def add(self, baking: Baking, texels: Texels, validity: Validity, terms: Terms,
            direct: Direct, indirect: Indirect | None = None) -> None:
        """Compose the texels' light, mark their validity and count them. With baked lights
        "indirect" the punctual lights' direct light is left out (the viewer's lights give
        it); their power still sets I_A."""
        rho, ambient = baking.settings.rho, baking.ambient
        if baking.foliage is not None:
            terms = shaded(baking.foliage, texels, terms, baking.settings.d_max)
        colours = (np.zeros_like(direct.light_colours)
                   if baking.settings.baked_lights == "indirect" else None)
        compose_into(self.lightmaps, texels, terms, ambient, rho, direct, colours,
                     None if indirect is None else indirect.irradiance,
                     None if indirect is None or not len(indirect.aim) else indirect.aim)
        validity.mark(texels, *self.masks)
        r_ave = effective_r_ave(ambient, rho)
        self.tally.add(terms, direct, validity, r_ave, indirect, ambient.intensity)
        if indirect is not None:
            self.indirect_variance.append(indirect.variance)
        if baking.settings.smooth:  # what the world-space filter weighs its risk by, and
            # what it leaves as it is
            self.variance.append(light_variance(
                terms, r_ave, ambient.intensity, direct, colours,
                None if indirect is None else indirect.variance, floor=False))
            self.exact.append(baking.sources.exact(direct, colours))


def writes_occlusion(settings: Resolved) -> bool:
    """Whether the output has an occlusion texture: the occlusion carrier, or occlusion 'also'."""
    return settings.carrier == "occlusion" or settings.occlusion == "also"


def _finish_pages(baking: Baking, per_texel: PerTexel, pages: _Pages, times: dict[str, float],
                  staging: StateSink | None = None, fingerprint: dict | None = None,
                  steps: Steps | None = None) -> Computed:
    """Start writing the bake state (``staging``, if any: the texels are final), then smooth or
    denoise (if asked) and post-process the composed pages; ``steps``: a pass over the pages'
    texels for the smoothing or the denoiser, one for the seams, and the post-process's own,
    counted as done."""
    if staging is not None:
        staging.start(baking, per_texel, fingerprint)
    resolved, lightmaps, masks = baking.settings, pages.lightmaps, pages.masks
    with timed(times, "compose"):
        lightmaps = directional_pages(lightmaps)
    steps = steps or Steps()
    texels = lightmaps.covered.size
    steps.expect(texels * (2 if resolved.denoise or resolved.smooth else 1))
    smoothed = None
    if resolved.smooth:  # in world space, before the fill of invalid texels (world_filter.py)
        with timed(times, "smooth"):
            lightmaps, smoothed = smooth_pages(lightmaps, per_texel.texels,
                                               np.concatenate(pages.variance),
                                               np.concatenate(pages.exact), *masks)
        steps.advance(texels)
    denoised = None
    if resolved.denoise:  # per chart, before the fill of invalid texels and dilation (denoise.py)
        with timed(times, "denoise"):
            lightmaps, denoised = denoise(lightmaps, per_texel.texels, *masks,
                                          threads=resolved.threads,
                                          visibility=writes_occlusion(resolved))
        steps.advance(texels)
    with timed(times, "compose"):
        seams = find_seams(baking.atlas, baking.world)
        steps.advance(texels)
        lightmaps = postprocess(lightmaps, resolved.padding, *masks, seams=seams, steps=steps)
    return Computed(scene=baking.scene, world=baking.world, settings=resolved,
                    ambient=baking.ambient, plan=baking.lit.plan, atlas=baking.atlas,
                    per_texel=per_texel, tally=pages.tally, lightmaps=lightmaps,
                    stage_seconds=times, sources=baking.sources, power=baking.lit.power,
                    denoised=denoised, smoothed=smoothed, foliage=baking.foliage,
                    indirect_variance=(np.concatenate(pages.indirect_variance)
                                       if pages.indirect_variance else None))


