"""A rebake's traced work, a part at a time, on this machine or on a Ray cluster (``--cluster``).

Once the dirty search has said which texels a change reaches (``dirty.dirty_search``),
a rebake casts rays again for three kinds of rows: the obscurance rays of the dirty texels
whose terms cannot follow from their stored ones, the shadow and sky rays of every dirty
texel, and, for each light placed anew, the shadow rays of every clean texel. Each texel's
values depend only on its key and the scene, so those rows are cut into parts of at most
``parts.PART_TEXELS`` texels and each part is traced by ``_retrace_part``: here one after the
other, or on a cluster's workers through the dispatcher a full bake's parts go through
(``pipeline.cluster.run_parts``). ``retraced`` yields the parts' results in order, and the
rebake writes their rows into the stored terms and direct light: the same bytes wherever and
in whatever order they were traced.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Iterator

import numpy as np

from baker.atlas.rasterise import Texels
from baker.geometry.surface import luminance
from baker.gltf.scene import Scene
from baker.geometry.world import World
from baker.image.compose import effective_r_ave
from baker.light.direct import Direct, aim_of, direct_light, texel_receivers
from baker.light.direct_estimators import mean_and_variance, punctual_samples
from baker.light.hemisphere import Surfaces, Terms, surfaces_of
from baker.light.integrate import integrate
from baker.pipeline import cluster
from baker.pipeline.full import Lighting
from baker.pipeline.parts import part_slices, take, texel_rows
from baker.rays.dimensions import light_dimension
from baker.rays.trace import Tracer
from baker.run.stages import timed
from baker.settings import Resolved


@dataclass(frozen=True)
class Retracing:
    """What every part of a rebake's traced work needs: the scene and its world now, the
    settings as the last bake resolved them, its ``Lighting`` (Embree's scene, sources, I_A),
    the shading of obscurance hits (``hemisphere.surfaces_of``), the lights placed anew
    (``relit``: indices into ``sources.lights``), ``texels``, the texels' per-triangle
    arrays (a ``Texels`` of no rows, which each part's rows complete), and ``obscurance``:
    the Embree scene obscurance rays are traced in when it is not ``lit``'s (--foliage approx:
    without the crowns' leaves; never on a cluster, which refuses that mode)."""

    scene: Scene
    world: World
    settings: Resolved
    lit: Lighting
    surfaces: Surfaces | None
    relit: tuple[int, ...]
    texels: Texels
    obscurance: Tracer | None = None


@dataclass(frozen=True)
class _Rows:
    """One part's input: ``texels``, its k texels' per-texel arrays (``parts.texel_rows``);
    ``obscurance`` (k,) bool, those whose obscurance rays are traced again; ``direct`` (k,)
    bool, the dirty ones, whose direct light is; the others get the ``relit`` lights' shadow
    rays."""

    texels: dict[str, np.ndarray]
    obscurance: np.ndarray
    direct: np.ndarray


@dataclass(frozen=True)
class Retraced:
    """One part's results: ``terms`` of its obscurance rows and ``direct`` light of its direct
    rows (``_Rows``, in order), and for its other rows each relit light's unit irradiance and
    variance, ``relit`` and ``relit_var`` (c, R) for the R lights of ``Retracing.relit``, with
    directional pages their first moments ``relit_aim`` (c, R, 3) and its variance
    ``relit_aim_var`` (c, R) (``direct.Direct.punctual_aim``; else 0 rows)."""

    terms: Terms
    direct: Direct
    relit: np.ndarray
    relit_var: np.ndarray
    relit_aim: np.ndarray
    relit_aim_var: np.ndarray

    @property
    def rays(self) -> int:
        """The obscurance, shadow and sky rays the part cast."""
        return self.terms.rays + self.direct.rays


def retraced(work: Retracing, texels: Texels, rows: np.ndarray, obscurance: np.ndarray,
             direct: np.ndarray, times: dict[str, float]) -> Iterator[tuple[slice, Retraced]]:
    """(the part: a slice of ``rows``, its ``Retraced``) for the texels ``rows`` (n,) int64 of
    ``texels``, in parts of at most ``parts.PART_TEXELS``, in order: their obscurance rays where
    ``obscurance`` (n,) bool, their direct light where ``direct`` (n,) bool, the relit lights'
    shadow rays elsewhere. On the cluster ``work.settings.cluster`` names (``cluster.session``)
    or here; ``times`` gets the stages ("trace", "direct"; on a cluster the driver's, its
    workers' going to the session's account)."""
    slices = [s for s in part_slices(len(rows)) if s.stop > s.start]

    def item(k: int) -> _Rows:
        part = slices[k]
        return _Rows(texel_rows(texels, rows[part]), obscurance[part], direct[part])

    if work.settings.cluster is None:
        made = (_retrace_part(work, item(k), times) for k in range(len(slices)))
    else:
        made = cluster.run_parts(cluster.Work(_shipped(work), _ready, _retrace_part),
                                 [s.stop - s.start for s in slices], item, times,
                                 lambda texels: None)  # a rebake draws no progress bar
    yield from zip(slices, made)


def _shipped(work: Retracing) -> Retracing:
    """What a worker fetches once: ``work`` without Embree's scene and the surfaces, which it
    builds from the scene and world (``_ready``)."""
    return replace(work, lit=work.lit.without_tracer(), surfaces=None)


def _ready(shipped: Retracing) -> Retracing:
    """In a worker: the shipped work with Embree's scene and the surfaces built again, bit for
    bit the driver's, and the task's CPUs (``Settings.threads``, at least 1) as threads."""
    lit = shipped.lit.with_tracer(Tracer(shipped.world))
    return replace(shipped, lit=lit, surfaces=surfaces_of(lit.context),
                   settings=replace(shipped.settings, threads=max(1, shipped.settings.threads)))


def _retrace_part(work: Retracing, rows: _Rows, seconds: dict[str, float]) -> Retraced:
    """Trace one part (``_Rows``) with the same estimators as a full bake; ``seconds`` gets
    "trace" (obscurance) and "direct" (shadow and sky rays)."""
    s, lit = work.settings, work.lit
    texels = replace(work.texels, **rows.texels)
    with timed(seconds, "trace"):
        error_scale = (effective_r_ave(lit.ambient, s.rho),
                       float(luminance(lit.ambient.intensity)))
        context = lit.context.with_settings(s)
        tracer = lit.tracer if work.obscurance is None else work.obscurance
        terms = integrate(context.with_tracer(tracer), texels, None,
                          rows=np.flatnonzero(rows.obscurance), error_scale=error_scale,
                          surfaces=work.surfaces)
    with timed(seconds, "direct"):
        direct = direct_light(context, take(texels, rows.direct), lit.sources)
        clean = np.flatnonzero(~rows.direct) if work.relit else np.zeros(0, np.int64)
        relit = np.zeros((len(clean), len(work.relit)))
        relit_var = np.zeros_like(relit)
        aimed = len(clean) if s.directional_pages else 0
        relit_aim, relit_aim_var = np.zeros((aimed, len(work.relit), 3)), np.zeros((aimed, len(work.relit)))
        for column, light in enumerate(work.relit):
            (relit[:, column], relit_var[:, column], aim, aim_var) = _relight(
                texels, lit.tracer, lit.sources, s, light, clean)
            if aimed:
                relit_aim[:, column], relit_aim_var[:, column] = aim, aim_var
    return Retraced(terms, direct, relit, relit_var, relit_aim, relit_aim_var)


def _relight(texels: Texels, tracer: Tracer, sources, settings, light: int,
             rows: np.ndarray) -> tuple[np.ndarray, ...]:
    """Light ``light``'s unit-intensity irradiance and variance at the texels ``rows``, and
    its first moment (k, 3) and that moment's variance (``direct.aim_of``), with the same
    estimator, samples and chunks as ``direct.direct_light``."""
    value, variance = np.zeros(len(rows)), np.zeros(len(rows))
    aim, aim_var = np.zeros((len(rows), 3)), np.zeros(len(rows))
    step = max(1, settings.chunk_texels)
    for start in range(0, len(rows), step):
        part = rows[start:start + step]
        done = slice(start, start + len(part))
        receivers = texel_receivers(take(texels, part), slice(0, len(part)), tracer.center)
        samples, _, directions = punctual_samples(
            sources.lights[light], float(sources.spread[light]), int(sources.samples[light]),
            receivers, tracer, settings.seed, light_dimension(light))
        value[done], variance[done] = mean_and_variance(samples)
        aim[done], aim_var[done] = aim_of(samples, directions)
    return value, variance, aim, aim_var
