"""The stored per-texel rows a rebake replaces with fresh ones, in place (``merge``), and which
rows of fresh results equal the stored ones (``same_rows``)."""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from baker.rebake.fallback import FullBake


def _absent(value) -> bool:
    """Whether an optional per-texel term is missing (None or an empty array)."""
    return value is None or (isinstance(value, np.ndarray) and not len(value))


def merge(stored, fresh, rows: np.ndarray, **overrides):
    """``stored`` (a dataclass of per-texel arrays) with rows ``rows`` replaced by ``fresh``'s
    rows (same fields, k rows); fields in ``overrides`` are taken as given (global values).
    ``stored``'s arrays are changed in place: they were read from the bake state for this
    rebake alone, and copies of a 4096² bake's terms would add 1 GB to its peak."""
    values = {}
    for f in fields(stored):
        if f.name in overrides:
            values[f.name] = overrides[f.name]
            continue
        old = getattr(stored, f.name)
        new = getattr(fresh, f.name)
        if _absent(old) or _absent(new):
            if _absent(old) != _absent(new) and len(rows):  # an optional term (e.g. §4's)
                raise FullBake(f"the bake state's term {f.name} does not fit the scene now")
            values[f.name] = old
        elif isinstance(old, np.ndarray):
            old[rows] = new
            values[f.name] = old
        else:
            values[f.name] = old
    return type(stored)(**values)


def same_rows(stored, fresh, rows: np.ndarray) -> np.ndarray:
    """(k,) bool: whether rows ``rows`` of ``stored`` equal, in every per-texel array field,
    the k rows of ``fresh`` (a dataclass of the same type)."""
    same = np.ones(len(rows), bool)
    for f in fields(stored):
        old, new = getattr(stored, f.name), getattr(fresh, f.name)
        if isinstance(old, np.ndarray) and isinstance(new, np.ndarray):
            same &= (old[rows] == new).reshape(len(rows), int(np.prod(new.shape[1:]))).all(axis=1)
    return same
