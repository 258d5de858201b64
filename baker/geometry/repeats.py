"""Triangles that repeat another exactly: one surface placed twice at one place.

A node copied onto itself, or GPU instances whose translations are missing (every instance at
the origin), put many copies of the same triangles at the same place. Embree cannot tell them
apart: a ray that reaches such a surface tests every copy, so 100,000 coincident copies of a
floor made a 4 kB file bake for hours. The copies are the same surface for every ray (the
same distance, the same point, the same side), so the tracer keeps the first and leaves the
others out (``rays.trace.embree_mesh``): the world, its texels and its lightmaps keep them all.

Found by one sort of a hash of each triangle's corners, then checked corner by corner: a copy
is a triangle whose three corners are bit for bit those of a lower-numbered one, in the same
cyclic order (the same winding: the same front face). A triangle the alpha test may let rays
through is never taken for a copy, nor one without area.
"""

from __future__ import annotations

import numpy as np

_MIX = np.uint64(0x9E3779B97F4A7C15)  # odd multipliers of a multiply-xorshift hash
_MIX2 = np.uint64(0xBF58476D1CE4E5B9)
_SHIFT = np.uint64(31)


def _mixed(h: np.ndarray, word: np.ndarray) -> np.ndarray:
    """(n,) uint64: ``word`` (n,) uint64 folded into the hashes ``h`` (n,) uint64."""
    h = (h ^ word) * _MIX
    return (h ^ (h >> _SHIFT)) * _MIX2


def repeated_triangles(positions: np.ndarray, triangles: np.ndarray,
                       eligible: np.ndarray) -> np.ndarray:
    """(T,) bool: the ``eligible`` (T,) bool triangles (``triangles`` (T, 3) rows into
    ``positions`` (V, 3) float64) whose corners, in the same cyclic order, are bit for bit
    those of a lower-numbered eligible triangle."""
    out = np.zeros(len(triangles), bool)
    rows = np.flatnonzero(eligible)
    if len(rows) < 2:
        return out
    bits = np.ascontiguousarray(positions, np.float64).view(np.uint64)
    vertex = _mixed(_mixed(_mixed(np.zeros(len(bits), np.uint64), bits[:, 0]), bits[:, 1]),
                    bits[:, 2])
    corners = triangles[rows]
    start = vertex[corners].argmin(axis=1)  # each triangle read from its least-hashed corner
    turned = np.take_along_axis(corners, (start[:, None] + np.arange(3)) % 3, axis=1)
    hashes = vertex[turned]
    key = _mixed(_mixed(_mixed(np.zeros(len(rows), np.uint64), hashes[:, 0]), hashes[:, 1]),
                 hashes[:, 2])
    ordered = np.sort(key)  # a sort without its order first: most scenes have no copy
    if not (ordered[1:] == ordered[:-1]).any():
        return out
    order = np.argsort(key, kind="stable")  # equal keys keep the triangles' order
    ordered = key[order]
    follows = np.flatnonzero(ordered[1:] == ordered[:-1]) + 1
    first = np.maximum.accumulate(np.where(np.r_[True, ordered[1:] != ordered[:-1]],
                                           np.arange(len(order)), 0))[follows]
    same = (positions[turned[order[follows]]] == positions[turned[order[first]]]).all(axis=(1, 2))
    out[rows[order[follows[same]]]] = True
    return out
