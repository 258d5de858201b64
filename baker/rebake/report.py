"""What the API keeps of a bake or rebake beyond its output: the rebake's account in the report
(``summary``), the dirty texels for ``BakeResult.rebake`` (``details``), and the timing record
beside the state that the next rebakes price their work by (``record_full_bake``)."""

from __future__ import annotations

import numpy as np

from baker.rebake import state as state_file
from baker.rebake.cost import rebake_measured
from baker.rebake.dirty import REASONS
from baker.rebake.incremental import Rebaked


def record_full_bake(path, rebaked, seconds: float, write,
                     stages: dict[str, float] | None = None) -> None:
    """After a full bake, record beside its state at ``path`` the ``seconds`` it took without
    numba's compile and its ``stages``' seconds (``state.timing_path``), which the rebakes that
    follow compare with and price their work by (``cost.afford``); after a rebake, keep that
    record with what its search and rays took against the model (``cost.rebake_measured``) and
    what it took besides them (``cost.worth_reading``); ``write(path, bytes)`` writes it
    (``run.atomic.Outputs.stage``)."""
    if not isinstance(rebaked, Rebaked):
        state_file.save_full_bake_seconds(path, seconds, write, stages)
        return
    last = state_file.last_full_bake(path)
    if last is None:
        return
    stages = stages or {}
    scaling = sum(stages.get(name, 0.0) for name in ("dirty", "trace", "direct"))
    state_file.save_full_bake_seconds(
        path, last["full_bake_seconds"], write, last["stage_seconds"],
        rebake_measured(rebaked.modelled, stages) or last.get("rebake_correction"),
        max(seconds - scaling, 0.0))


def summary(rebaked, state_path, incremental: bool, seconds: float | None = None,
            compile_seconds: float = 0.0) -> dict:
    """The JSON-able account of the rebake for the report: full or incremental, why, what
    changed, how many texels were dirty for which reason, rays cast, and its ``seconds``
    (``compile_seconds`` of them numba's compile, ``run.compile_clock``) against the last full
    bake's without its compile (``last_full_bake_seconds``, None when not recorded)."""
    out: dict = {"incremental": isinstance(rebaked, Rebaked),
                 "state": None if state_path is None else str(state_path)}
    if isinstance(rebaked, str):
        out["full_bake_reason"] = rebaked
    elif not incremental:
        out["full_bake_reason"] = "full bake asked for"
    if isinstance(rebaked, Rebaked):
        count = len(rebaked.dirty.reason)
        out.update({
            "changes": list(rebaked.diff.changes) or ["nothing changed"],
            "texels": count, "dirty_texels": int(len(rebaked.dirty.rows)),
            "dirty_fraction": float(len(rebaked.dirty.rows) / count) if count else 0.0,
            "dirty_by_reason": rebaked.dirty.counts(),
            "relit_lights": list(rebaked.dirty.relit),
            "moved_nodes": sorted({rebaked.fingerprints["instances"][i]["name"]
                                   for i in rebaked.diff.moved}),
            "rays": int(rebaked.rays), "test_rays": int(rebaked.dirty.tested_rays),
            "modelled_seconds": rebaked.modelled,  # its search and rays, by the cost model
            "seconds": seconds, "compile_seconds": compile_seconds,
            "last_full_bake_seconds": state_file.last_full_bake_seconds(state_path)})
    return out


def details(report: dict, rebaked) -> dict:
    """``summary`` plus, for a rebake, the arrays naming the dirty texels: ``dirty_keys`` (d,)
    uint64 texel keys and ``dirty_reasons`` (d,) names from REASONS (for ``BakeResult.rebake``)."""
    out = dict(report)
    if isinstance(rebaked, Rebaked):
        rows = rebaked.dirty.rows
        out["dirty_keys"] = rebaked.computed.texels.key[rows]
        out["dirty_reasons"] = np.asarray(REASONS)[rebaked.dirty.reason[rows]]
    return out
