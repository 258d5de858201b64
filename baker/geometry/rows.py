"""Equal rows of an integer table, found by one sort: which rows are the same point, the same
material and colours, the same key.

``np.unique(rows, axis=0)`` sorts the rows as structured records, about ten times slower than
``np.lexsort`` over the columns, which is what this does.
"""

from __future__ import annotations

import numpy as np


def row_groups(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of ``rows`` (n, k) int64, in lexicographic order: (g,) the index of
    each one's first occurrence, and (n,) each row's rank among them — ``np.unique(rows,
    axis=0, return_index=True, return_inverse=True)[1:]``."""
    if not len(rows):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = np.lexsort(rows.T[::-1])  # stable: equal rows keep their order
    ordered = rows[order]
    new = np.r_[True, (ordered[1:] != ordered[:-1]).any(axis=1)]
    ranks = np.empty(len(rows), np.int64)
    ranks[order] = np.cumsum(new) - 1
    return order[new], ranks
