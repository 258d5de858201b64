"""The rebake's cost model: what a rebake of a move would cost against a full bake from the same
point, priced by the last full bake's stage times (``rebake_cost``), corrected by what the last
rebake of the state measured (``rebake_measured``); a FullBake when the rebake would cost more
(``afford``), or could never pay (``worth_reading``). docs/bake_state.md describes the record."""

from __future__ import annotations

import numpy as np

from baker.rebake import state as state_file
from baker.rebake.fallback import FullBake


REDO_COST, SEARCH_COST = 2.3, 1.25
"""What a rebake of a move costs per texel, in units of a full bake's: ``REDO_COST`` × its
validity, trace and direct light for a texel of the moved nodes (or touching them: probed,
traced and lit anew, and the larger a node, the more the search meets it at both places, in
every texel's rays and shadows); ``SEARCH_COST`` × its validity probes for another texel within
reach (its probes, and its rays that may meet the node, cast in the scene now and as it was).
Fitted (least squares of the relative error) to what the search and rays of nine rebakes took
at default settings on 2 shared cores (bench_rebake_cost.py: 1 to 60 of 60 crates moved, 1 or
4 of 9 big boxes, a tree or the box beside it, a flower of GlassVaseFlowers, 0.3–70 % of the
texels redone whole): the model 0.64–1.40 of the time taken over two runs (3.5 and 1.0
before: 0.77–2.0, the vase's flower priced at twice its time). A recolour's texels found dirty
by a sample of its search count as redone (``dirty._colour_sampled``): 1.28 and 1.73 of the
time taken there. A rebake of a state measures what its own search and
rays took against this model and records it (``rebake_measured``): the next rebake of that
state scales the model by it (``afford``)."""


CORRECTION_RANGE = (0.25, 8.0)
"""The least and most a measured correction scales the model by (``afford``): one rebake's
time, on a shared machine, is a noisy measure."""


def rebake_cost(stages: dict[str, float], redone: float, reached: float
                ) -> tuple[float, float, float]:
    """(a rebake's search and rays, its composing and writing, and a full bake's work from the
    same point), as fractions of the last full bake, whose ``stages`` (name → seconds) price
    the work: ``redone`` (fraction of the texels: the moved nodes' own and those touching
    them) at ``REDO_COST`` × a full bake's validity, trace and direct light per texel,
    ``reached`` (fraction: the others within reach) at ``SEARCH_COST`` × its validity per
    texel; compose and write as a full bake's. A full bake from there does all but what the
    rebake has done before it prices: loading the scene, its lights and plan (the rebake hands
    over what it made of them, ``FullBake.prepared``). Those stages hold a process's first
    calls (numba's start, Embree's device): counted as a full bake's work they made a rebake of
    nearly every texel look cheaper than one, on a small scene's first bake or one slowed
    there by the machine."""
    total = sum(stages.values())
    share = {name: stages.get(name, 0.0) / total for name in
             ("load", "lights", "plan", "validity", "trace", "direct", "compose", "spill",
              "write")}
    per_texel = share["validity"] + share["trace"] + share["direct"]
    tail = share["compose"] + share["spill"] + share["write"]
    return (redone * REDO_COST * per_texel + reached * SEARCH_COST * share["validity"], tail,
            1.0 - share["load"] - share["lights"] - share["plan"])


def afford(full_bake: dict | None, redone: int, reached: int, texels: int,
           priced: bool = True) -> float | None:
    """FullBake when a rebake of an edit (``redone``, ``reached``: texel counts, as
    ``rebake_cost`` takes their fractions of ``texels``) would cost more than a full bake
    from here, by the last full bake's stage times (no record of them: the rebake goes on),
    its search and rays scaled by what the last rebake of this state measured of them against
    this model (``rebake_measured``); never when not ``priced`` (a rebake asked for whatever it
    costs). Returns the seconds the model gives the search and the rays, unscaled (None
    without a record), for that measure. A full bake's bytes are the rebake's."""
    if not full_bake or not texels or sum(full_bake["stage_seconds"].values()) <= 0:
        return None
    seconds = full_bake["full_bake_seconds"]
    scaling, tail, full = rebake_cost(full_bake["stage_seconds"], redone / texels,
                                      reached / texels)
    correction = float(np.clip(full_bake.get("rebake_correction", 1.0), *CORRECTION_RANGE))
    cost = correction * scaling + tail
    if priced and cost > full:
        measured = (f", × {correction:.2f} as the last rebake of this state measured"
                    if "rebake_correction" in full_bake else "")
        raise FullBake(
            f"a rebake would cost more than a full bake: the edit reaches "
            f"{(redone + reached) / texels:.0%} of the texels ({redone / texels:.0%} redone "
            f"whole), about {cost * seconds:.2f} s by the last full bake's stages"
            f"{measured}, against {full * seconds:.2f} s for a full one (the last took "
            f"{seconds:.2f} s)")
    return scaling * seconds


def worth_reading(path) -> None:
    """FullBake, before the state at ``path`` is read, when the last rebake of it took longer
    besides its search and rays (reading the state, the scene's world and lights, composing,
    writing: ``rebake_overhead``, measured) than the whole last full bake: no edit can make a
    rebake of it pay (a small scene, whose every bake is mostly such fixed work)."""
    record = state_file.last_full_bake(path)
    if record is None or "rebake_overhead" not in record:
        return
    overhead, full = record["rebake_overhead"], record["full_bake_seconds"]
    if overhead >= full:
        raise FullBake(f"a rebake would cost more than a full bake: the last rebake of this "
                       f"state took {overhead:.2f} s besides its search and rays, the last "
                       f"full bake {full:.2f} s in all")


def rebake_measured(modelled: float | None, stages: dict[str, float]) -> float | None:
    """What a rebake's search and rays (its "dirty", "trace" and "direct" ``stages``, seconds)
    took over what the model gave them (``modelled`` seconds: ``incremental.Rebaked.modelled``),
    for the record beside the state (``state.save_rebake_correction``); None when
    unmodelled."""
    if not modelled:
        return None
    spent = sum(stages.get(name, 0.0) for name in ("dirty", "trace", "direct"))
    return spent / modelled
