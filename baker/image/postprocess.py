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

from baker.image.compose import Lightmaps
from baker.image.seams import Seams, stitch
from baker.jit import jit
from baker.run.progress import Steps

_NEIGHBOURS = np.array([(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)],
                       np.int64)
_FILL_RINGS = 8  # how far (texels) valid values reach into a patch of invalid texels


@jit
def _grow_ring(pages, filled: np.ndarray, into: np.ndarray, frontier: np.ndarray) -> np.ndarray:
    """One ring of dilation, in place, over flat pages: ``pages`` a tuple of value arrays
    (P·H·W, C) grown alike (the light and the W pages share their masks, so the ring is found
    once for both), filled and into (P, H, W) bool. Every texel of ``into`` not ``filled`` next to a
    texel of ``frontier`` (flat indices of the texels filled last ring, or all filled ones at
    first) gets the mean of its filled 8-neighbours (summed in ``_NEIGHBOURS`` order); returns
    the flat indices of the texels grown, and marks them filled only after the ring. It reads
    only texels filled before the ring and writes only unfilled ones, so the result does not
    depend on the order of ``frontier``; the work is proportional to the frontier, not to the
    page (a sparse 8192² page costs what its charts' borders cost)."""
    height, width = filled.shape[1], filled.shape[2]
    flat_filled, flat_into = filled.reshape(-1), into.reshape(-1)
    candidate = np.empty(len(frontier) * 8, np.int64)
    seen = 0
    for f in frontier:
        page, rest = divmod(f, height * width)
        y, x = divmod(rest, width)
        for k in range(len(_NEIGHBOURS)):
            v, u = y + _NEIGHBOURS[k, 0], x + _NEIGHBOURS[k, 1]
            if 0 <= v < height and 0 <= u < width:
                n = (page * height + v) * width + u
                if not flat_filled[n] and flat_into[n]:
                    flat_into[n] = False  # taken once (given back below): no duplicates to sort
                    candidate[seen] = n
                    seen += 1
    candidate = candidate[:seen]
    for n in candidate:
        flat_into[n] = True
    for flat_values in pages:
        channels = flat_values.shape[1]
        total = np.zeros(channels)
        for n in candidate:
            page, rest = divmod(n, height * width)
            y, x = divmod(rest, width)
            count = 0.0
            total[:] = 0.0
            for k in range(len(_NEIGHBOURS)):
                v, u = y + _NEIGHBOURS[k, 0], x + _NEIGHBOURS[k, 1]
                if 0 <= v < height and 0 <= u < width:
                    m = (page * height + v) * width + u
                    if flat_filled[m]:
                        for c in range(channels):
                            total[c] += flat_values[m, c]
                        count += 1.0
            for c in range(channels):
                flat_values[n, c] = total[c] / count
    for n in candidate:
        flat_filled[n] = True
    return candidate


@jit
def _border(filled: np.ndarray, into: np.ndarray, border: np.ndarray) -> None:
    """Mark in ``border`` the ``filled`` texels (P, H, W) next to an unfilled texel of ``into``:
    the first ring's frontier. Only they can grow a texel, and a frontier of every filled texel
    would reserve 8 candidates (64 bytes) per texel: 540 MB for a dense 4096² page."""
    pages, height, width = filled.shape
    for p in range(pages):
        for y in range(height):
            for x in range(width):
                if not filled[p, y, x]:
                    continue
                for k in range(len(_NEIGHBOURS)):
                    v, u = y + _NEIGHBOURS[k, 0], x + _NEIGHBOURS[k, 1]
                    if (0 <= v < height and 0 <= u < width and into[p, v, u]
                            and not filled[p, v, u]):
                        border[p, y, x] = True
                        break


def dilate(values: np.ndarray, filled: np.ndarray, rings: int,
           into: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Grow ``values`` (P, H, W, C) from ``filled`` (P, H, W) texels by ``rings`` texels.

    ``into`` (P, H, W) bool, when given, limits the growth to those texels (e.g. the invalid
    texels inside charts, so that the fill never crosses the padding to another chart).
    """
    values = np.ascontiguousarray(values, np.float64).copy()
    return values, _dilate_in_place((values,), filled, rings, into)


def _dilate_in_place(pages: tuple[np.ndarray, ...], filled: np.ndarray, rings: int,
                     into: np.ndarray | None = None) -> np.ndarray:
    """``dilate`` on each of ``pages`` itself ((P, H, W, C) C-contiguous float64 arrays, grown
    alike); returns the grown mask."""
    filled = np.ascontiguousarray(filled).copy()
    into = np.ones(filled.shape, bool) if into is None else np.ascontiguousarray(into)
    border = np.zeros(filled.shape, bool)
    _border(filled, into, border)
    frontier = np.flatnonzero(border)
    flat = tuple(values.reshape(-1, values.shape[-1]) for values in pages)
    for _ in range(rings):
        frontier = _grow_ring(flat, filled, into, frontier)
        if not len(frontier):
            break
    return filled


def _fill_invalid_in_place(pages: tuple[np.ndarray, ...], covered: np.ndarray,
                           invalid: np.ndarray, rings: int = _FILL_RINGS) -> None:
    """Each of ``pages`` (P, H, W, C; C-contiguous float64, changed in place) with each invalid
    texel (P, H, W) given the mean of its valid 8-neighbours, ring after ring inwards (up to
    ``rings``); invalid texels no valid texel reaches keep their own value."""
    _dilate_in_place(pages, covered & ~invalid, rings, into=invalid & covered)


def postprocess(lightmaps: Lightmaps, padding: int, invalid: np.ndarray | None = None,
                enclosed: np.ndarray | None = None, seams: Seams | None = None,
                steps: Steps | None = None) -> Lightmaps:
    """Clean the composed pages: enclosed texels dark, invalid ones from valid neighbours,
    dilation past the padding (at least 4 texels, for bilinear + 1 mip), then both sides of
    every smooth UV seam made to agree (``seams.stitch``); the directional pages alike (an
    enclosed texel's h 0: no tilt changes its darkness).

    invalid, enclosed: (P, H, W) bool masks from ``validity.Validity.page_masks`` (None: none).
    seams: from ``seams.find_seams`` (None: no stitching).
    steps: its three passes over the pages' texels (fill, dilation, seams), counted as done.

    The pages of ``lightmaps`` are cleaned in place (float64 C-contiguous ones, as compose and
    denoise make them; others are converted first) and returned: the composed pages are not
    needed after, and a copy of a 4096² page pair would add 800 MB to the bake's peak memory.
    """
    covered = lightmaps.covered
    steps = steps or Steps()
    steps.expect(3 * covered.size)
    pages = [np.ascontiguousarray(values, np.float64)
             for values in (lightmaps.light, lightmaps.visibility, lightmaps.direction)]
    kept = tuple(values for values in pages if len(values))  # W's pages may not be kept
    if not kept:  # nothing baked
        return Lightmaps(light=pages[0], visibility=pages[1], covered=covered,
                         direction=pages[2])
    if enclosed is not None and enclosed.any():
        for values in kept:
            values[enclosed] = 0.0  # shut inside a solid: no light reaches it
    if invalid is not None and invalid.any():
        _fill_invalid_in_place(kept, covered, invalid)
    steps.advance(covered.size)
    _dilate_in_place(kept, covered, max(2 * padding, 4))
    steps.advance(covered.size)
    if seams is not None and len(seams):
        pages = [stitch(values, covered, seams) if len(values) else values for values in pages]
    steps.advance(covered.size)
    return Lightmaps(light=pages[0], visibility=pages[1], covered=covered, direction=pages[2])
