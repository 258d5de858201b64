"""Which texels' validity probes and obscurance rays reach the changed geometry: those near its
boxes (``near_boxes``), then, among them, those whose own rays (``rays_meet``) or probes
(``probes_meet``) meet it, as a bake casts them, judged changed where a judge is given
(``judges``); ``mark_seen`` marks them dirty, rays from a texel's other side included."""

from __future__ import annotations

from typing import Callable

import numpy as np

from baker.atlas import validity as validity_module
from baker.atlas.rasterise import Texels
from baker.context import Context
from baker.jit import jit
from baker.light.hemisphere import world_rays
from baker.light.inner import other_side_rays, translucent
from baker.pipeline.parts import take
from baker.rays.sampling import tangent_frames
from baker.rays.trace import RayCaster
from baker.rebake.changed import Changed
from baker.rebake.judges import ProbesCompared
from baker.rebake.near_rays import drawn_near_rays, fixed_may_meet, ray_starts
from baker.run.parallel import cores, even_slices, run_chunks
from baker.settings import TECHNIQUES


# Extra reach (in texel sides of each texel) beyond d_max: the validity probes move a sample
# point by up to rounds × (probe radius + push) sides, then probe a radius further; plus one.
_REACH_TEXELS = (validity_module.TANGENT_ROUNDS
                 * (validity_module.PROBE_RADIUS + validity_module.PUSH)
                 + validity_module.PROBE_RADIUS + 1.0)


# Rays per batch when testing candidates against the changed geometry (bounds memory).
_TEST_RAYS = 1 << 19


@jit
def _within(points: np.ndarray, size: np.ndarray, d_max: float, texels_reach: float,
            middle: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """(n,) bool: whether each point (n, 3) lies within its reach of some box [low[b], high[b]]
    (b, 3) (Euclidean distance to the box, 0 inside). The reach: d_max (+ 1e-9 of it),
    ``texels_reach`` texel sides ``size`` (n,), and 1e-4 of the point's distance from
    ``middle`` (3,) (the float32 spacing part of the rays' lift, ``trace.ray_lift``)."""
    out = np.zeros(len(points), np.bool_)
    for i in range(len(points)):
        spread = 0.0
        for c in range(3):
            spread = max(spread, abs(points[i, c] - middle[c]))
        reach = d_max * (1 + 1e-9) + texels_reach * size[i] + 1e-4 * spread
        for b in range(len(low)):
            squared = 0.0
            for c in range(3):
                gap = max(low[b, c] - points[i, c], points[i, c] - high[b, c], 0.0)
                squared += gap * gap
            if np.sqrt(squared) <= reach:
                out[i] = True
                break
    return out


def near_boxes(texels: Texels, boxes: list[tuple[np.ndarray, np.ndarray]], d_max: float
               ) -> np.ndarray:
    """(N,) bool: texels whose sample point lies within reach (d_max + a few texel sides) of any
    box — a conservative bound on where their validity probes and obscurance rays can go."""
    if not boxes:
        return np.zeros(len(texels), bool)
    middle = (boxes[0][0] + boxes[0][1]) / 2
    low, high = np.array([b[0] for b in boxes]), np.array([b[1] for b in boxes])
    near = np.zeros(len(texels), bool)

    def work(rows: slice) -> None:  # on every core: a bake has millions of texels
        near[rows] = _within(texels.position[rows], texels.size(rows), float(d_max),
                             float(_REACH_TEXELS), middle, low, high)

    run_chunks(work, even_slices(len(texels), 1 << 16))
    return near


def rays_meet(changed: Changed, texels: Texels, rows: np.ndarray, settings,
              judge: Callable | None = None) -> tuple[np.ndarray, int]:
    """(k,) bool: whether any of each texel's own obscurance rays meets the ``changed``
    triangles within d_max — and, with a ``judge`` (``NotStopped``, ``HitsCompared``), is
    judged to have changed; and the number of rays drawn. A bake's ray let through alpha
    cut-outs goes on along its own line (``trace.pass_alpha``): its straight line is its path."""
    n = settings.rays
    meets = np.zeros(len(rows), bool)

    def work(part: slice) -> None:
        chosen = rows[part]
        normal, frame = texels.geometric_normal(chosen), texels.hemisphere_normal(chosen)
        starts, radii = ray_starts(changed, texels.position[chosen], normal, texels.size(chosen),
                                   settings.d_max)
        texel, sample, x, y, z = drawn_near_rays(
            TECHNIQUES.index(settings.sampling), np.uint64(settings.seed), texels.key[chosen],
            n, starts, *tangent_frames(frame), frame, normal, changed.sphere_centres, radii,
            settings.d_max, True)
        if not len(texel):
            return
        # Each drawn ray from its texel's sample point: the bits of that ray in a bake.
        origins, directions = world_rays(texels, chosen, texel, x, y, z, changed.center)
        met = changed.cast_local(origins, directions,
                                 np.full(len(origins), settings.d_max, np.float32))
        hit = np.flatnonzero(met.triangle >= 0)
        if judge is not None and len(hit):
            hit = hit[judge(chosen[texel[hit]], sample[hit], origins[hit], directions[hit],
                            met.distance[hit])]
        found = meets[part]
        found[texel[hit]] = True
        meets[part] = found

    run_chunks(work, even_slices(len(rows), max(1, _TEST_RAYS // n), 2 * cores()),
               settings.threads)
    return meets, len(rows) * n


def probes_meet(tracer: RayCaster, texels: Texels, rows: np.ndarray, d_max: float,
                threads: int = 0, judge: "ProbesCompared | None" = None
                ) -> tuple[np.ndarray, int]:
    """(k,) bool: whether any of the validity module's fixed hemisphere probes from each texel's
    (probed) sample point meets ``tracer``'s triangles within d_max — and, with a ``judge``,
    is judged to have changed; and the rays cast."""
    meets = np.zeros(len(rows), bool)
    m = validity_module.HEMISPHERE_RAYS
    x, y, z = np.ascontiguousarray(validity_module.hemisphere_directions(m).T)

    def work(part: slice) -> None:
        chosen = rows[part]
        normal = texels.geometric_normal(chosen)
        starts, radii = ray_starts(tracer, texels.position[chosen], normal, texels.size(chosen),
                                   d_max)
        some = np.flatnonzero(fixed_may_meet(x, y, z, starts, *validity_module.probe_frames(normal),
                                             normal, tracer.sphere_centres, radii, d_max))
        if not len(some):
            return
        origins, directions = validity_module.hemisphere_probes(
            texels.position[chosen[some]], normal[some], texels.size(chosen[some]),
            tracer.center)
        met = tracer.cast(origins, directions, d_max).triangle >= 0
        if judge is not None and met.any():
            met[met] = judge(origins[met], directions[met], d_max)
        found = meets[part]
        found[some] = met.reshape(len(some), -1).any(axis=1)
        meets[part] = found

    run_chunks(work, even_slices(len(rows), max(1, _TEST_RAYS // validity_module.HEMISPHERE_RAYS),
                                 2 * cores()), threads)
    return meets, len(rows) * validity_module.HEMISPHERE_RAYS


def mark_seen(context: Context, changed: Changed, boxes: list, texels: Texels,
              reason: np.ndarray, mark: int, settings, judge: Callable | None = None) -> int:
    """Mark with ``mark`` (in ``reason`` (N,), in place: an index into ``dirty.REASONS``) the
    texels not yet dirty whose
    obscurance rays — their own (within d_max of ``boxes``, above their plane) and those from
    their other side (leaves' back faces, translucent insides: ``inner.other_side_rays``) —
    meet the ``changed`` geometry (held in ``boxes``, (low, high) pairs); return the rays cast.
    ``judge``: their own rays count only if it judges them changed (``rays_meet``)."""
    test = np.flatnonzero(near_boxes(texels, boxes, settings.d_max) & (reason < 0))
    meets, tested = rays_meet(changed, texels, test, settings, judge)
    reason[test[meets]] = mark
    world = context.world
    table = translucent(world.materials)
    if not table.any:
        return tested
    rest = np.flatnonzero(reason < 0)
    material = world.tri_material[texels.triangle[rest]]
    rest = rest[table.leaf[material] | table.inner[material]]  # texels with another side
    for part in even_slices(len(rest), max(1, _TEST_RAYS // settings.rays)):
        rows = rest[part]
        which, origins, directions, lengths = other_side_rays(
            context.with_settings(settings), take(texels, rows), np.arange(len(rows)),
            changed.center)
        if not len(which):
            continue
        hit = changed.cast_local(origins, directions, lengths.copy()).triangle >= 0
        reason[rows[which[hit.reshape(len(which), -1).any(axis=1)]]] = mark
        tested += len(origins)
    return tested
