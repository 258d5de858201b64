"""The dirty search: which texels a change can reach, and why (``REASONS``, ``Dirty``).

A moved node's own texels, those whose validity probes now find otherwise, those whose
obscurance rays' first hits changed, those whose shadow rays meet it (``moved_reach``); the
texels whose rays meet a recoloured material, and those whose rays meet mirrors or glass
(``dirty_search``). The searches cast the texels' own deterministic rays against the changed
geometry (``changed``, ``near_rays``, ``reach``, ``shadows``) and judge them (``judges``);
the move's cost is weighed on the way (``cost.afford``)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from baker.atlas import validity as validity_module
from baker.atlas.rasterise import Texels
from baker.atlas.validity import Faces, Validity, check_texels
from baker.gltf.scene import Scene
from baker.light.foliage import Foliage
from baker.light.hemisphere import EXACT_RAYS, Surfaces, surfaces_of
from baker.light.inner import translucent
from baker.pipeline.full import Lighting
from baker.pipeline.parts import take
from baker.rays.trace import Tracer
from baker.rebake.changed import Changed, chain_corners, placed_corners, world_before
from baker.rebake.compared import Compared, Stored
from baker.rebake.cost import afford
from baker.rebake.judges import HitsCompared, NotStopped, ProbesCompared
from baker.rebake.reach import mark_seen, near_boxes, probes_meet
from baker.rebake.rows import merge, same_rows
from baker.rebake.shadows import shadow_dirty
from baker.run.stages import timed


REASONS = ("own", "validity", "obscurance", "shadow", "colour", "chain")
PRICE_SAMPLE = 4096  # about this many texels tried first to price a recolour (``_colour_sampled``)


@dataclass(frozen=True)
class Dirty:
    """Which texels the rebake recomputed, and why.

    rows: (d,) int64 texel rows re-integrated (sorted). reason: (N,) int8 index into
    ``REASONS`` of the first reason each texel was found dirty, −1 for clean texels.
    tested_rays: rays cast to find them (validity probes of candidates, test rays against the
    changed geometry). relit: light indices whose shadow rays were recast for every texel.
    """

    rows: np.ndarray
    reason: np.ndarray
    tested_rays: int
    relit: tuple[int, ...]

    def counts(self) -> dict[str, int]:
        """How many texels are dirty for each reason."""
        return {name: int((self.reason == k).sum()) for k, name in enumerate(REASONS)}


@dataclass
class Search:
    """What the dirty search found (``dirty_search``), the one mutable record of a rebake:
    ``reason`` (N,) int8 index into ``REASONS`` per texel (−1: clean), the texels with their
    sample points as the probes leave them now, their validity, the rays cast to find them,
    the judge of which rays a move changed (``HitsCompared``, None without a move) and whether
    dirty texels take only those rays' change (``by_ray``)."""

    reason: np.ndarray
    texels: Texels
    validity: Validity
    surfaces: Surfaces
    by_ray: bool
    judge: "HitsCompared | None" = None
    tested: int = 0
    modelled: float | None = None  # the seconds ``afford`` gave the search and the rays
    priced: bool = True  # ``afford`` may choose a full bake (else it only prices the rebake)


def dirty_search(scene: Scene, start: Compared, lit: Lighting, stored: Stored,
                 times: dict[str, float], foliage: Foliage | None = None,
                 priced: bool = True) -> Search:
    """Which texels the change can reach, and why (``REASONS``). With ``foliage``, obscurance
    rays are judged in the scene without the crowns' leaves, as they were traced; ``priced``:
    an edit (a move, a recolour) whose rebake would cost more than a full bake is a FullBake
    (``cost.afford``)."""
    hidden = None if foliage is None else foliage.hidden()
    world, resolved, change, moved = start.world, start.resolved, start.change, start.moved
    surfaces = surfaces_of(lit.context)
    # Texels whose rays changed take only those rays' change (``incremental._by_ray``) when
    # each ray's part of its texel's terms stands alone and their sums are exact: no chains, no
    # other side, no adaptive rounds, albedos within [0, 1], no directions (their sums are not
    # recovered).
    by_ray = (surfaces.exact_sums and resolved.rays <= EXACT_RAYS and not translucent(world.materials).any
              and resolved.target_error is None and not change.recoloured
              and not resolved.directional_pages)
    raw = stored.raw
    texels = replace(raw, position=stored.texels.positions(raw.position))  # changed in place
    search = Search(np.full(len(raw), -1, np.int8), texels, stored.validity, surfaces, by_ray,
                    priced=priced)
    with timed(times, "dirty"):
        colour = (_colour_search(world, lit, foliage, change.recoloured) if change.recoloured
                  else None)
        dirty, tested = (_colour_sampled(lit.context, colour, search.texels, resolved)
                         if colour else (0, 0))
        if len(moved):
            moved_reach(scene, start, lit, stored, search, hidden, dirty)
        elif colour:
            search.modelled = afford(start.full_bake, dirty, tested - dirty, len(raw),
                                     search.priced)
        if colour:
            search.tested += mark_seen(lit.context, colour.changed, colour.boxes, search.texels,
                                       search.reason, REASONS.index("colour"), resolved,
                                       colour.judge)
        chains = chain_corners(world)
        if (len(moved) or change.recoloured) and len(chains):
            # A ray that meets a mirror or glass goes on where the searches above do not follow:
            # every texel whose rays meet one is recomputed.
            box = [(chains.reshape(-1, 3).min(0), chains.reshape(-1, 3).max(0))]
            search.tested += mark_seen(lit.context, Changed([chains], world.center), box,
                                       search.texels, search.reason, REASONS.index("chain"),
                                       resolved)
    return search


class ColourSearch(NamedTuple):
    """What the search for a recolour casts against (the recoloured materials' triangles),
    the box holding them (none without triangles) and its judge, as ``reach.mark_seen`` takes
    them."""

    changed: Changed
    boxes: list
    judge: NotStopped


def _colour_search(world, lit: Lighting, foliage: Foliage | None, recoloured: list[int]
                   ) -> ColourSearch:
    """The ``ColourSearch`` of the ``recoloured`` materials of ``world``."""
    changed = np.isin(world.tri_material, recoloured)
    a, b, c = world.corners(np.flatnonzero(changed))
    corners = np.stack([a, b, c], axis=1)
    box = ([(corners.reshape(-1, 3).min(0), corners.reshape(-1, 3).max(0))]
           if len(corners) else [])
    return ColourSearch(Changed([corners], world.center), box,
                        NotStopped(_obscurance_tracer(lit, foliage), changed))


def _colour_sampled(context, colour: ColourSearch, texels, resolved) -> tuple[int, int]:
    """How many of ``texels`` the recolour's search would find dirty and how many it would
    test, from the search run on every k-th texel (about ``PRICE_SAMPLE``): what
    ``cost.afford`` prices a recolour by, before the whole search. A recolour of what most
    texels see (a room's walls, every crate) redoes most texels after a search that costs
    about a trace: 2–2.3× a full bake, unpriced."""
    count = len(texels)
    if not count:
        return 0, 0
    rows = np.arange(0, count, max(1, count // PRICE_SAMPLE))
    sample = take(texels, rows)
    reason = np.full(len(rows), -1, np.int8)
    mark_seen(context, colour.changed, colour.boxes, sample, reason, 0, resolved, colour.judge)
    tested = np.count_nonzero(near_boxes(sample, colour.boxes, resolved.d_max))
    scale = count / len(rows)
    return int(round(np.count_nonzero(reason >= 0) * scale)), int(round(tested * scale))


def _obscurance_tracer(lit: Lighting, foliage: Foliage | None) -> Tracer:
    """Embree's scene obscurance rays are traced in: without the crowns' leaves with
    ``foliage`` (``foliage.Foliage.tracer``), else the whole scene."""
    return lit.tracer if foliage is None else foliage.tracer


def moved_reach(scene: Scene, start: Compared, lit: Lighting, stored: Stored,
                search: Search, hidden: np.ndarray | None = None, recoloured: int = 0) -> None:
    """Mark in ``search`` the texels moved nodes can reach: their own, those whose validity
    probes, obscurance rays or shadow rays meet them at their old or new place (obscurance
    rays with the triangles ``hidden`` (T,) bool left out, as --foliage approx traced them).
    ``recoloured``: the texels a recolour in the same edit will redo, priced with the move's
    (``_colour_sampled``)."""
    world, resolved, moved, tracer = start.world, start.resolved, start.moved, lit.tracer
    raw, texels, reason, old_validity = stored.raw, search.texels, search.reason, stored.validity
    own = np.isin(raw.instance(), moved)
    reason[own] = REASONS.index("own")
    instance_world = start.stored.instance_world
    old_corners = [placed_corners(scene, world, i, instance_world[i]) for i in moved]
    new_corners = [placed_corners(scene, world, i, scene.instances[i].world) for i in moved]
    boxes = [(c.reshape(-1, 3).min(0), c.reshape(-1, 3).max(0))
             for c in old_corners + new_corners if len(c)]
    near = near_boxes(raw, boxes, resolved.d_max)
    # Validity: tangent probes reach a few texel sides; hemisphere probes d_max.
    close = own | near_boxes(raw, boxes, 0.0)
    far = np.flatnonzero(near & ~close)
    search.modelled = afford(start.full_bake, int(close.sum()) + recoloured, len(far),
                             len(raw), search.priced)
    small = Changed(old_corners + new_corners, world.center)
    before = world_before(scene, world, moved, instance_world)
    tracer_before, faces = Tracer(before), Faces(scene, world)
    meets, n = probes_meet(small, texels, far, resolved.d_max, resolved.threads,
                           ProbesCompared((tracer, faces),
                                          (tracer_before, Faces(scene, before))))
    search.tested += n
    # Texels touching other geometry: which coincident triangle a probe or ray meets there
    # depends on Embree's BVH, which the move changed (``Validity.touching``). Far texels whose
    # points moved: whether they might was judged by probes from where they were, which the
    # probes compared above (from where they are) do not cover.
    redo = np.union1d(np.union1d(np.flatnonzero(close), far[meets]),
                      np.union1d(np.flatnonzero(old_validity.touching),
                                 far[old_validity.moved_by[far] > 0]))
    checked, fresh = check_texels(scene, world, tracer, take(raw, redo), resolved.d_max,
                                  faces=faces)
    search.tested += len(redo) * (validity_module.HEMISPHERE_RAYS + validity_module.TANGENT_RAYS
                                  * validity_module.TANGENT_ROUNDS)
    # Probes that met the moved object mostly find what they found before: such a texel is
    # dirty only if its rays meet it (below). Touching texels are redone.
    same = (same_rows(old_validity, fresh, redo) & ~old_validity.touching[redo]
            & (texels.position[redo] == checked.position).all(axis=1))
    texels.position[redo] = checked.position
    stored.texels.record(redo, checked.position, raw.position[redo])
    search.validity = merge(old_validity, fresh, redo)
    changed = redo[~same]
    reason[changed[reason[changed] < 0]] = REASONS.index("validity")
    if hidden is not None:
        tracer, tracer_before = Tracer(world, hidden=hidden), Tracer(before, hidden=hidden)
    search.judge = HitsCompared(tracer, tracer_before, resolved.d_max, keep=search.by_ray)
    search.tested += mark_seen(lit.context, small, boxes, texels, reason,
                               REASONS.index("obscurance"), resolved, search.judge)
    rest = np.flatnonzero(reason < 0)
    shadow, n = shadow_dirty(lit.context, small, texels, rest, lit.sources, resolved)
    search.tested += n
    reason[rest[shadow]] = REASONS.index("shadow")
