"""Clean-up of the composed pages before encoding: dilation into the padding.

Bilinear filtering (and mipmapping) reads texels around a chart's border that no triangle
covers; left black they show as dark seams. Dilation fills each empty texel with the mean of its
filled 8-neighbours, ring after ring.
"""

from __future__ import annotations

import numpy as np

from .compose import Lightmaps

_NEIGHBOURS = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)]


def _shift(a: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """``a`` (P, H, W, …) moved by (dy, dx) within each page, zeros shifted in."""
    out = np.zeros_like(a)
    h, w = a.shape[1], a.shape[2]
    ys, yd = (slice(0, h - dy), slice(dy, h)) if dy >= 0 else (slice(-dy, h), slice(0, h + dy))
    xs, xd = (slice(0, w - dx), slice(dx, w)) if dx >= 0 else (slice(-dx, w), slice(0, w + dx))
    out[:, yd, xd] = a[:, ys, xs]
    return out


def dilate(values: np.ndarray, filled: np.ndarray, rings: int) -> tuple[np.ndarray, np.ndarray]:
    """Grow ``values`` (P, H, W, C) from ``filled`` (P, H, W) texels by ``rings`` texels."""
    values, filled = values.copy(), filled.copy()
    for _ in range(rings):
        total = np.zeros_like(values)
        count = np.zeros(filled.shape)
        for dy, dx in _NEIGHBOURS:
            total += _shift(values * filled[..., None], dy, dx)
            count += _shift(filled.astype(np.float64), dy, dx)
        grow = ~filled & (count > 0)
        if not grow.any():
            break
        values[grow] = total[grow] / count[grow][:, None]
        filled = filled | grow
    return values, filled


def postprocess(lightmaps: Lightmaps, padding: int) -> Lightmaps:
    """Dilate light and obscurance past the padding (at least 4 texels, for bilinear + 1 mip)."""
    rings = max(2 * padding, 4)
    light, filled = dilate(lightmaps.light, lightmaps.covered, rings)
    obscurance, _ = dilate(lightmaps.obscurance, lightmaps.covered, rings)
    return Lightmaps(light=light, obscurance=obscurance, covered=lightmaps.covered)
