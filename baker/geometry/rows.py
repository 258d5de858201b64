"""Rows of an integer table that go together: equal rows, found by one sort (which rows are
the same point, the same material and colours, the same key), and keys joined by the rows
that hold them (``joined_roots``: a mesh's UV islands, the seams' independent pieces).

``np.unique(rows, axis=0)`` sorts the rows as structured records, about ten times slower than
``np.lexsort`` over the columns, which is what this does.
"""

from __future__ import annotations

import numpy as np

from baker.jit import jit


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


@jit
def joined_roots(rows: np.ndarray, count: int) -> np.ndarray:
    """(count,) int64: for each key 0 … count − 1, the smallest key joined to it, keys being
    joined when one row of ``rows`` (n, k) int64 holds both (union-find, the larger root
    linked under the smaller, so a set's root is its smallest key)."""
    parent = np.arange(count)
    for r in range(rows.shape[0]):
        for j in range(1, rows.shape[1]):
            a, b = rows[r, 0], rows[r, j]
            while parent[a] != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            while parent[b] != b:
                parent[b] = parent[parent[b]]
                b = parent[b]
            if a != b:
                parent[max(a, b)] = min(a, b)
    for key in range(count):  # roots are smaller than their keys: already resolved
        parent[key] = parent[parent[key]]
    return parent
