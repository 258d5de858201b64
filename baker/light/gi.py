"""Full diffuse global illumination: the reference obscurances are measured against.

The obscurance model approximates the light that has bounced at least once by I_A·W(P). This
module computes it without the approximation, by path tracing on the same texels, with the same
lights, albedos and direct-light estimators (direct.py): the indirect irradiance

    E_ind(P) = ∫ L(Q → P) cosθ dω,   L(Q) = R(Q)/π · (D(Q) + E_ind(Q)),

with Le the emitted radiance, estimated with cosine-distributed directions (pdf cosθ/π) as the
mean over paths of Σ_b T_b·(R(Q_b)·D'(Q_b) + π·Le(Q_{b+1})·[b ≥ 1]), where Q_1, Q_2, … are the
path's vertices and T_b the product of the albedos met before Q_b. D' is the direct light of
punctual lights and sky by next-event estimation (one shadow ray per source). Emissive
triangles are reached both ways, combined by multiple importance sampling (Veach's power
heuristic): at each vertex one next-event sample picks an emitter point as direct.py does
(in proportion to power, pdf p_l in solid angle), and the path's next direction (pdf
cosθ/π = p_b) may meet an emitter too (counted from b ≥ 1: the light of emitters seen from P
is in D(P) already); each counts with weight p²/(p_l² + p_b²) of its own pdf. A small lamp,
which cosine paths seldom meet, is then found by every vertex, and the next-event estimate's
peaks near an emitter's edges (p_l ≫ p_b there) are weighted down to the paths' bounded one.
Paths end by Russian roulette from the second vertex on: a path goes on with probability
s = min(1, max channel of its throughput) and its throughput is divided by s, so the estimate
is unbiased and a surviving path's throughput never exceeds 1 (its variance stays finite even
at albedo 0.99, where a cap on s, such as 0.95, lets weights grow as (a/0.95)^b). The only
bias left is the cap of ``MAX_BOUNCES`` vertices, for scenes whose paths would never end
(albedo 1 everywhere and nothing escaping): a path that survives to it carries throughput
≤ a_max^(B−1) (a_max the largest albedo met), so the light it loses is that fraction of what
a path from there gathers; ``Indirect.capped`` counts such paths and the report prints them.
The lightmap is then L(P) = D(P) + E_ind(P), what ``--method gi`` bakes and what
``baker study`` compares obscurances with.

The error estimate: the first directions of a texel's paths are two independently scrambled
Sobol nets, half the paths each (as the obscurance's rays: ``sampling.net_points``), which
makes the paths better than independent: their sample variance over the path count overstated
the error of the Cornell room's GI 1.2–1.3×. So the variance of a texel's mean is that, times
a gain measured on the texels: the split of each texel's mean between its two nets, pooled
over texels of like variance (``_predicted_variance``, ``Indirect.variance``).

Randomness is a pure function of (seed, texel key, path, bounce): the first direction of each
path comes from the texel's Owen-scrambled Sobol points, later ones from per-vertex keys.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from baker.atlas.rasterise import Texels
from baker.context import Context
from baker.geometry.surface import albedo, emission, luminance
from baker.geometry.world import World
from baker.light.adaptive import WITHIN, neighbour_mean, pooled_gain
from baker.light.direct import direct_at
from baker.light.direct_estimators import (
    Receivers,
    SHADOW_SHORTEN,
    emitter_radiance,
    emitter_samples,
)
from baker.light.sources import Emitters, Sources
from baker.rays.dimensions import GI_BOUNCE, GI_EMITTER, GI_FIRST, GI_ROULETTE
from baker.rays.sampling import (
    cosine_hemisphere,
    folded,
    hash_u32,
    net_points,
    sample_2d,
    tangent_frames,
)
from baker.rays.trace import ray_lift
from baker.run.parallel import run_chunks

_FAR = 1e30  # "no length limit" for Embree's float32 tfar
MAX_BOUNCES = 1024  # a path cut here at albedo 0.99 has throughput 0.99^1023 = 3.4e-5


@dataclass(frozen=True)
class Indirect:
    """E_ind (N, 3) at N texels; the predicted variance (N,) of each texel's E_ind luminance
    (of the mean of its paths: ``_predicted_variance``); the rays the paths cast (bounce and
    shadow rays); the paths cut at ``MAX_BOUNCES`` (0 unless paths could not end by
    themselves); the paths traced, over all texels (adaptive rounds give texels different
    counts). aim: (N, 3) the first moment of E_ind's luminance along each path's first world
    direction (``light.directional``), aim_variance (N,) its estimate's variance (its paths'
    sample variance over their count, summed over the components), both empty (0 rows)
    without ``Resolved.directional_pages``."""

    irradiance: np.ndarray
    variance: np.ndarray
    rays: int
    capped: int = 0
    paths: int = 0
    aim: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    aim_variance: np.ndarray = field(default_factory=lambda: np.zeros(0))


def _path_keys(keys: np.ndarray, paths: int, first: int = 0) -> np.ndarray:
    """(k·paths,) uint64 keys, one per (texel, path ``first`` … ``first + paths − 1``): a hash
    of both, texel-major."""
    numbers = np.tile(np.arange(first, first + paths), len(keys))
    high = hash_u32(np.repeat(keys, paths), numbers, 1)
    low = hash_u32(np.repeat(keys, paths), numbers, 2)
    return (high.astype(np.uint64) << np.uint64(32)) | low.astype(np.uint64)


def _bounce_keys(path_keys: np.ndarray, bounce: int) -> np.ndarray:
    """Keys (m,) of the paths' vertices at ``bounce``: each vertex takes sample 0 of its own key.

    Successive samples of one key are stratified against each other (a (0, 2)-sequence), so a
    path that survived roulette on a low number would meet a high one next: drawing every
    bounce from one key biases the paths (measured: a furnace lost 15 % of its light).
    """
    return path_keys ^ np.uint64((bounce + 1) * 0x9E3779B97F4A7C15 % 2 ** 64)


def _cosine_directions(normals: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(m, 3) cosine-distributed directions about unit ``normals`` (m, 3) from points (m, 2)."""
    local = cosine_hemisphere(points)
    t1, t2 = tangent_frames(normals)
    return local[:, :1] * t1 + local[:, 1:2] * t2 + local[:, 2:] * normals


@dataclass(frozen=True)
class _Paths:
    """What k texels' paths ``first`` … ``first + count − 1`` gave: the mean (k, 3) of their
    E_ind, the mean (k,) of its luminance and m2 (k,), the sum of that luminance's squared
    deviations from its mean (so that rounds of paths combine exactly: ``_combined``); the
    rays they cast and the paths cut at ``MAX_BOUNCES``; net_sum (k,), the luminance summed over
    the paths of the first of the texel's two nets (the first ⌊count/2⌋: ``_chunk``); aim
    (k, 3) the mean of luminance × first direction and aim_square (k,) the mean of its squared
    length, or (0, 3) and (0,) when not kept."""

    mean: np.ndarray
    luminance: np.ndarray
    m2: np.ndarray
    count: int
    rays: int
    capped: int
    net_sum: np.ndarray
    aim: np.ndarray
    aim_square: np.ndarray


def _chunk(context: Context, sources: Sources, texels: Texels, rows: slice | np.ndarray,
           paths: int, max_bounces: int, first: int = 0, start: int = 0) -> _Paths:
    """Paths ``first`` … ``first + paths − 1`` of the texels ``rows`` (k of them). Their first
    directions are two independent nets (``sampling.net_points``; ``start``: the first round's
    paths, when this is a later one), the first ⌊paths/2⌋ paths from the first net."""
    world, tracer, settings, scene = (context.world, context.tracer, context.settings,
                                      context.surfaces)
    keys = texels.key[rows]
    k = len(keys)
    path_keys = _path_keys(keys, paths, first)
    position = np.repeat(texels.position[rows], paths, axis=0)
    normal = np.repeat(texels.geometric_normal(rows), paths, axis=0)
    frame = np.repeat(texels.hemisphere_normal(rows), paths, axis=0)  # the first rays'
    size = np.repeat(texels.size(rows), paths)
    points = np.column_stack(net_points(settings.seed, keys, first, paths, GI_FIRST,
                                        start=start))
    throughput = np.ones((k * paths, 3))
    total = np.zeros((k * paths, 3))
    others = replace(sources, emitters=None)  # punctual lights and sky: next-event estimation
    lit, emitters = others.any(), sources.emitters
    emitter_of = _emitter_index(world, emitters)
    two_sided = np.array([c.double_sided for c in context.materials.classes], bool)
    alive = np.arange(k * paths)
    rays = 0
    first_directions = np.zeros((0, 3))
    for bounce in range(max_bounces):
        if not len(alive):
            break
        if bounce:  # a path vertex: about its face's normal
            points = sample_2d(settings.seed, _bounce_keys(path_keys[alive], bounce), 0,
                               GI_BOUNCE)
            directions = _cosine_directions(normal, points)
            cos_out = np.einsum("ij,ij->i", directions, normal)  # the direction's pdf × π
        else:  # the texel: about its hemisphere normal, folded above its front face
            directions = folded(_cosine_directions(frame, points), frame, normal)
            cos_out = np.einsum("ij,ij->i", directions, frame)
            if settings.directional_pages:
                first_directions = directions
        origins = position + ray_lift(position, size, tracer.center)[:, None] * normal
        hits = tracer.cast(origins, directions, _FAR)
        rays += len(alive)
        hit = hits.triangle >= 0
        alive, directions, hits = alive[hit], directions[hit], _select(hits, hit)
        size, cos_out = size[hit], cos_out[hit]
        if not len(alive):
            break
        tris = hits.triangle
        bary = hits.barycentric()
        position = origins[hit] + directions * hits.distance[:, None]
        facing = world.geometric_normals(tris)
        back = np.einsum("ij,ij->i", facing, directions) > 0
        normal = np.where(back[:, None], -facing, facing)
        throughput = throughput[hit]
        if bounce and emitters is not None:  # single-sided emitters emit from the front only
            front = ~back | two_sided[world.tri_material[tris]]
            cos_in = np.abs(np.einsum("ij,ij->i", facing, directions))
            mis = _power_heuristic(cos_out / np.pi,
                                   _light_pdf(emitters, emitter_of[tris], hits.distance, cos_in))
            total[alive] += (throughput * np.pi * emission(scene, world, tris, bary)
                             * (front * mis)[:, None])
        reflectance = albedo(scene, world, tris, bary)
        if emitters is not None:
            light, cast = _emitter_light(context, emitters, position, normal,
                                         ray_lift(position, size, tracer.center),
                                         _bounce_keys(path_keys[alive], bounce), settings.seed)
            rays += cast
            total[alive] += throughput * reflectance * light
        if lit:
            receivers = Receivers(position=position, normal=normal, geometric=normal,
                                  lift=ray_lift(position, size, tracer.center),
                                  key=_bounce_keys(path_keys[alive], bounce))
            direct = direct_at(context, others, receivers, settings.seed, samples=1)
            rays += direct.rays
            total[alive] += throughput * reflectance * direct.irradiance()
        throughput = throughput * reflectance
        if bounce >= 1:  # Russian roulette: survive with the throughput's largest channel
            survive = np.minimum(throughput.max(axis=1), 1.0)
            u = sample_2d(settings.seed, _bounce_keys(path_keys[alive], bounce), 0,
                          GI_ROULETTE)[:, 0]
            keep = u < survive
            throughput = throughput[keep] / survive[keep, None]
            alive, position, normal, size = alive[keep], position[keep], normal[keep], size[keep]
    per_path = total.reshape(k, paths, 3)
    lum = luminance(per_path)
    mean = lum.mean(axis=1)
    deviation = lum - mean[:, None]
    moment = (lum.reshape(-1)[:len(first_directions), None]
              * first_directions).reshape(-1, paths, 3)
    return _Paths(per_path.mean(axis=1), mean, np.add.reduce(deviation * deviation, axis=1),
                  paths, rays, len(alive), lum[:, :paths // 2].sum(axis=1),
                  moment.mean(axis=1), (moment * moment).sum(axis=2).mean(axis=1))


def _combined(a: _Paths, b: _Paths) -> _Paths:
    """Two rounds of paths of the same texels as one (Chan et al.'s pairwise update of m2)."""
    n = a.count + b.count
    gap = b.luminance - a.luminance
    return _Paths((a.count * a.mean + b.count * b.mean) / n,
                  (a.count * a.luminance + b.count * b.luminance) / n,
                  a.m2 + b.m2 + gap * gap * (a.count * b.count / n), n,
                  a.rays + b.rays, a.capped + b.capped, a.net_sum + b.net_sum,
                  (a.count * a.aim + b.count * b.aim) / n,
                  (a.count * a.aim_square + b.count * b.aim_square) / n)


def _variance(m2: np.ndarray, count: np.ndarray) -> np.ndarray:
    """(k,) the variance of a mean of ``count`` (k,) paths whose luminance has ``m2`` (k,),
    were the paths independent."""
    count = np.asarray(count, np.float64)
    return np.where(count > 1, m2 / np.maximum(count - 1, 1) / np.maximum(count, 1), 0.0)


def _predicted_variance(state: _Paths, counts: np.ndarray, texels: Texels) -> np.ndarray:
    """(N,) the predicted variance of each texel's mean luminance over its ``counts`` (N,)
    paths, at every texel of ``texels``: their sample variance over the count (``_variance``)
    times the first directions' nets' gain, pooled over texels of like variance, by their
    neighbours' (``adaptive.pooled_gain``), from the split
    of each texel's mean between its two nets (an unbiased measure of its variance, of one
    degree of freedom): (m_a − m_b)² · n_a·n_b / n²."""
    n = np.maximum(counts, 1).astype(np.float64)
    first = counts // 2  # the first net's paths: ⌊paths/2⌋ of every round
    m_a = state.net_sum / np.maximum(first, 1)
    m_b = (state.luminance * n - state.net_sum) / np.maximum(counts - first, 1)
    split = np.where(first > 0, (m_a - m_b) ** 2 * first * (counts - first) / (n * n), 0.0)
    iid = _variance(state.m2, counts)
    like = neighbour_mean(texels, iid, np.arange(len(iid)))
    return pooled_gain(iid, split, iid > 0, like) * iid


def _emitter_index(world: World, emitters: Emitters | None) -> np.ndarray:
    """(T,) int64: each world triangle's row in ``emitters`` (−1: not an emitter)."""
    index = np.full(len(world.triangles), -1, np.int64)
    if emitters is not None:
        index[emitters.triangles] = np.arange(len(emitters.triangles))
    return index


def _light_pdf(emitters: Emitters, row: np.ndarray, distance: np.ndarray,
               cos_emitter: np.ndarray) -> np.ndarray:
    """(m,) solid-angle pdf with which the next-event sample picks a point of emitter ``row``
    (−1: none, pdf 0) seen at ``distance`` under cosθ ``cos_emitter``: (P_e / A_e)·d²/cosθ."""
    pdf = np.zeros(len(row))
    ok = (row >= 0) & (cos_emitter > 0)
    e = row[ok]
    pdf[ok] = emitters.probability[e] / emitters.areas[e] * distance[ok] ** 2 / cos_emitter[ok]
    return pdf


def _power_heuristic(mine: np.ndarray, other: np.ndarray) -> np.ndarray:
    """Veach's power-heuristic weight of a sample drawn with pdf ``mine`` against ``other``."""
    total = mine * mine + other * other
    return np.where(total > 0, mine * mine / np.where(total > 0, total, 1.0), 0.0)


def _emitter_light(context: Context, emitters: Emitters, position: np.ndarray,
                   normal: np.ndarray, lift: np.ndarray, keys: np.ndarray,
                   seed: int) -> tuple[np.ndarray, int]:
    """One next-event sample of the emitters' irradiance (m, 3) at each vertex (position,
    normal (m, 3), ``lift`` (m,) off the surface), sampled as
    ``direct_estimators.emissive_irradiance`` does and weighted against the cosine-sampled direction
    that may meet the same point; and the shadow rays cast."""
    m = len(position)
    origins = position + lift[:, None] * normal
    chosen, bary, directions, distance, weight = emitter_samples(
        sample_2d(seed, keys, 0, GI_EMITTER), 1, emitters.cdf, emitters.probability,
        emitters.corners, emitters.normals, emitters.two_sided, emitters.areas, origins, lift,
        normal, normal, np.zeros(m, bool))
    light = np.zeros((m, 3))
    live = np.flatnonzero(weight > 0)
    if not len(live):
        return light, 0
    visible = ~context.tracer.occluded(origins[live], directions[live],
                                       distance[live] * (1.0 - SHADOW_SHORTEN))
    live = live[visible]
    picked = chosen[live]
    radiance = emitter_radiance(context, emitters, picked, bary[live])
    cos_p = np.einsum("ij,ij->i", directions[live], normal[live])
    cos_q = np.abs(np.einsum("ij,ij->i", directions[live], emitters.normals[picked]))
    mis = _power_heuristic(_light_pdf(emitters, picked, distance[live], cos_q), cos_p / np.pi)
    light[live] = radiance * (weight[live] * mis)[:, None]
    return light, int(len(visible))


def _select(hits, mask):
    """The rows ``mask`` of a ``trace.Hits``."""
    return type(hits)(hits.triangle[mask], hits.distance[mask], hits.u[mask], hits.v[mask])


def rays_per_path(sources: Sources, r_ave: np.ndarray) -> float:
    """About how many rays a path casts, for a progress bar's first estimate (``_chunk``
    measures the truth): a bounce ray at each vertex, two vertices before Russian roulette and
    then, as a surviving throughput is divided back to a largest channel of 1, one more with
    probability a ≈ max(R_ave) each: 2 + a²/(1 − a) in all (assuming every ray hits), and
    a next-event ray per source kind at each vertex (emitters, each light, the sky)."""
    a = min(float(np.max(r_ave)), 0.99)
    vertices = 2.0 + a * a / (1.0 - a)
    next_event = (sources.emitters is not None) + len(sources.lights) + (sources.sky is not None)
    return vertices * (1 + next_event)


def indirect_light(context: Context, sources: Sources, texels: Texels, paths: int,
                   max_bounces: int = MAX_BOUNCES,
                   progress: Callable[[int, int], None] | None = None,
                   targets: np.ndarray | None = None) -> Indirect:
    """E_ind at every texel from ``paths`` paths each (see the module's docstring);
    ``progress(texels, rays)`` after each chunk, with the rays its paths cast.

    ``targets`` (N,) (``adaptive.what_is_left``; None: one round): adaptive rounds. A texel
    whose neighbours' σ (``adaptive.neighbour_mean`` of ``Indirect.variance`` per path, over
    the texel's own paths) times ``adaptive.WITHIN`` is above its target gets as many paths
    again — the next ones, paths n … 2n − 1 — while it would stay within
    ``max_rays`` paths (the context's settings). The rounds do not depend on the chunks.
    """
    settings = context.settings
    count = len(texels)
    kept = count if settings.directional_pages else 0
    state = _Paths(np.zeros((count, 3)), np.zeros(count), np.zeros(count), 0, 0, 0,
                   np.zeros(count), np.zeros((kept, 3)), np.zeros(kept))
    counts = np.zeros(count, np.int64)
    active, rays, capped, first = np.arange(count), 0, 0, 0
    while len(active):
        batch = paths if first == 0 else first
        step = max(1, settings.chunk_texels // max(1, batch // 16))
        chunks = [active[start:start + step] for start in range(0, len(active), step)]
        found: list[_Paths | None] = [None] * len(chunks)

        def work(item: tuple[int, np.ndarray], batch=batch, first=first) -> None:
            i, rows = item
            found[i] = part = _chunk(context, sources, texels, rows, batch, max_bounces, first,
                                     paths if first else 0)
            if progress is not None:
                progress(len(rows) if first == 0 else 0, part.rays)

        run_chunks(work, list(enumerate(chunks)), settings.threads)
        for rows, part in zip(chunks, found):
            old = _Paths(state.mean[rows], state.luminance[rows], state.m2[rows], first, 0, 0,
                         state.net_sum[rows], state.aim[rows] if kept else state.aim,
                         state.aim_square[rows] if kept else state.aim_square)
            new = part if first == 0 else _combined(old, part)
            state.mean[rows], state.luminance[rows] = new.mean, new.luminance
            state.m2[rows], state.net_sum[rows] = new.m2, new.net_sum
            if kept:
                state.aim[rows], state.aim_square[rows] = new.aim, new.aim_square
            rays, capped = rays + part.rays, capped + part.capped
        counts[active] += batch
        first += batch
        if targets is None or 2 * first > settings.max_rays:
            break
        # By the neighbours' variance: a texel whose paths missed the rare bright ones has
        # a low mean and a low variance together, and stopped by its own it stays too dark.
        # Per path, over the texel's own paths: a neighbour that stopped has fewer.
        per_path = neighbour_mean(texels, _predicted_variance(state, counts, texels) * counts,
                                  active)
        active = active[WITHIN * np.sqrt(per_path / counts[active]) > targets[active]]
        if progress is not None and len(active):  # the round's rays at the paths' mean so far
            progress(0, 0, round(len(active) * first * rays / max(1, int(counts.sum()))))
    n = np.maximum(counts[:kept], 1).astype(np.float64)
    spread = state.aim_square - np.einsum("kc,kc->k", state.aim, state.aim)
    aim_variance = np.maximum(spread, 0.0) / np.maximum(n - 1, 1) if kept else np.zeros(0)
    return Indirect(irradiance=state.mean, variance=_predicted_variance(state, counts, texels),
                    rays=rays, capped=capped, paths=int(counts.sum()), aim=state.aim,
                    aim_variance=aim_variance)
