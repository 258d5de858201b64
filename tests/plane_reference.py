"""An independent reference for the tests: rays against rectangles in numpy.

It shares no code with baker: a rectangle is a dict (``centre`` (3,), unit ``normal`` (3,), two
unit in-plane ``axes`` and their ``half`` extents, as ``assets.artifact_scenes.panels_on_floor``
describes its panels), and the directions are a fixed stratified grid, not baker's sampler.
"""

from __future__ import annotations

import numpy as np


def cosine_directions(rings: int = 64, spokes: int = 512) -> np.ndarray:
    """(rings·spokes, 3) stratified cosine-distributed directions about +y (cell centres; fine
    in azimuth: a panel seen edge-on covers a wedge of a few degrees)."""
    u, v = np.meshgrid((np.arange(rings) + 0.5) / rings, (np.arange(spokes) + 0.5) / spokes)
    r, phi = np.sqrt(u.ravel()), 2 * np.pi * v.ravel()
    return np.stack([r * np.cos(phi), np.sqrt(1 - r * r), r * np.sin(phi)], axis=1)


DIRECTIONS = cosine_directions()
"""The cosine-distributed directions about +y that ``blocked`` casts."""


def blocked(point: np.ndarray, rectangles, length: float) -> np.ndarray:
    """(len(DIRECTIONS),) bool: which of the ``DIRECTIONS`` from ``point`` (3,) meet one of
    the ``rectangles`` (either face) within ``length``."""
    out = np.zeros(len(DIRECTIONS), bool)
    for rectangle in rectangles:
        normal = np.asarray(rectangle["normal"])
        offset = np.asarray(rectangle["centre"]) - point
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (offset @ normal) / (DIRECTIONS @ normal)
        hit = (t > 1e-9) & (t < length)
        for axis, half in zip(rectangle["axes"], rectangle["half"]):
            axis = np.asarray(axis)
            hit &= np.abs(t * (DIRECTIONS @ axis) - offset @ axis) <= half
        out |= hit
    return out


def segment_meets(start: np.ndarray, end: np.ndarray, rectangle) -> tuple[bool, bool]:
    """(whether the segment from ``start`` to ``end`` (3,) crosses the rectangle, whether it
    crosses its plane less than 5 mm from its edge: a hit there depends on rounding)."""
    normal = np.asarray(rectangle["normal"])
    offset = np.asarray(rectangle["centre"]) - start
    along = (end - start) @ normal
    if along == 0:
        return False, False
    t = (offset @ normal) / along
    if not 0 < t < 1:
        return False, False
    point = start + t * (end - start) - np.asarray(rectangle["centre"])
    margin = min(half - abs(point @ np.asarray(axis))
                 for axis, half in zip(rectangle["axes"], rectangle["half"]))
    return margin >= 0, abs(margin) < 5e-3
