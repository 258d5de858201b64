"""Clean-up of the composed pages before encoding: invalid texels, dilation into the padding.

Texels whose sample point lay inside geometry (``validity.py``) are fixed first: those shut
inside a solid are set dark (no light reaches them), the other invalid ones take the mean of
their valid neighbours, never their own rays' values.

Bilinear filtering (and mipmapping) reads texels around a chart's border that no triangle
covers; left black they show as dark seams. Dilation fills each empty texel with the mean of its
filled 8-neighbours, ring after ring. Last, the texels along smooth UV seams are re-solved so
that both sides of each seam look the same (``seams.py``).
"""

from __future__ import annotations

import numpy as np

from .compose import Lightmaps
from .sampling import jit
from .seams import Seams, stitch

_NEIGHBOURS = np.array([(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)],
                       np.int64)
_FILL_RINGS = 8  # how far (texels) valid values reach into a patch of invalid texels


@jit
def _grow_ring(values: np.ndarray, filled: np.ndarray, into: np.ndarray,
               out: np.ndarray, grown: np.ndarray) -> bool:
    """One ring of dilation: every texel of ``into`` not ``filled`` (P, H, W) with filled
    8-neighbours gets their mean (neighbours summed in ``_NEIGHBOURS`` order) in ``out``
    (P, H, W, C) and is marked in ``grown``; False when no texel grew. Reads only ``values`` and
    ``filled`` as they were before the ring, so the result does not depend on the scan order."""
    pages, height, width, channels = values.shape
    total = np.zeros(channels)
    any_grown = False
    for p in range(pages):
        for y in range(height):
            for x in range(width):
                if filled[p, y, x] or not into[p, y, x]:
                    continue
                count = 0.0
                total[:] = 0.0
                for k in range(len(_NEIGHBOURS)):
                    v, u = y + _NEIGHBOURS[k, 0], x + _NEIGHBOURS[k, 1]
                    if 0 <= v < height and 0 <= u < width and filled[p, v, u]:
                        total += values[p, v, u]
                        count += 1.0
                if count > 0:
                    out[p, y, x] = total / count
                    grown[p, y, x] = True
                    any_grown = True
    return any_grown


def dilate(values: np.ndarray, filled: np.ndarray, rings: int,
           into: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Grow ``values`` (P, H, W, C) from ``filled`` (P, H, W) texels by ``rings`` texels.

    ``into`` (P, H, W) bool, when given, limits the growth to those texels (e.g. the invalid
    texels inside charts, so that the fill never crosses the padding to another chart).
    """
    values = np.ascontiguousarray(values, np.float64).copy()
    filled = filled.copy()
    into = np.ones(filled.shape, bool) if into is None else np.ascontiguousarray(into)
    for _ in range(rings):
        grown = np.zeros(filled.shape, bool)
        if not _grow_ring(values.copy(), filled, into, values, grown):
            break
        filled |= grown
    return values, filled


def fill_invalid(values: np.ndarray, covered: np.ndarray, invalid: np.ndarray,
                 rings: int = _FILL_RINGS) -> np.ndarray:
    """``values`` (P, H, W, C) with each invalid texel (P, H, W) given the mean of its valid
    8-neighbours, ring after ring inwards (up to ``rings``); invalid texels no valid texel
    reaches keep their own value."""
    filled, _ = dilate(values, covered & ~invalid, rings, into=invalid & covered)
    return filled


def postprocess(lightmaps: Lightmaps, padding: int, invalid: np.ndarray | None = None,
                enclosed: np.ndarray | None = None, seams: Seams | None = None) -> Lightmaps:
    """Clean the composed pages: enclosed texels dark, invalid ones from valid neighbours,
    dilation past the padding (at least 4 texels, for bilinear + 1 mip), then both sides of
    every smooth UV seam made to agree (``seams.stitch``).

    invalid, enclosed: (P, H, W) bool masks from ``validity.Validity.page_masks`` (None: none).
    seams: from ``seams.find_seams`` (None: no stitching).
    """
    light, obscurance = lightmaps.light, lightmaps.obscurance
    if enclosed is not None and enclosed.any():
        light, obscurance = light.copy(), obscurance.copy()
        light[enclosed] = 0.0  # shut inside a solid: no light reaches it
        obscurance[enclosed] = 0.0
    if invalid is not None and invalid.any():
        light = fill_invalid(light, lightmaps.covered, invalid)
        obscurance = fill_invalid(obscurance, lightmaps.covered, invalid)
    rings = max(2 * padding, 4)
    light, filled = dilate(light, lightmaps.covered, rings)
    obscurance, _ = dilate(obscurance, lightmaps.covered, rings)
    if seams is not None and len(seams):
        light = stitch(light, lightmaps.covered, seams)
        obscurance = stitch(obscurance, lightmaps.covered, seams)
    return Lightmaps(light=light, obscurance=obscurance, covered=lightmaps.covered)
