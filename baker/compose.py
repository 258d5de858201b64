"""Compose the stored terms into lightmap pages: L(P) = D(P) + I_A · W(P).

A recomposition needs no ray: it only combines the terms the integrator kept apart, so a change of
R_ave or I_A costs a few array operations (DESIGN.md §2). D, the direct light (direct.py), is kept
per light at unit intensity, so a light's new colour or intensity is a recomposition too.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Callable

import numpy as np

from .ambient import Ambient
from .atlas import Atlas
from .direct import Direct
from .integrate import Terms
from .obscurance import UNIT_REFLECTIVITY
from .rasterise import Texels


@dataclass(frozen=True)
class Lightmaps:
    """Float lightmap pages, linear RGB.

    light: (P, H, W, 3) float64, what arrives at the surface (the shader multiplies by albedo).
    obscurance: (P, H, W, 3) float64, W itself. covered: (P, H, W) bool, texels that were baked
    (the rest are padding, filled by dilation).
    """

    light: np.ndarray
    obscurance: np.ndarray
    covered: np.ndarray


def effective_r_ave(ambient: Ambient, rho: str) -> np.ndarray:
    """R_ave as the estimator uses it: 1 for classic ambient occlusion (every surface white)."""
    return np.ones(3) if rho in UNIT_REFLECTIVITY else ambient.r_ave


def compose(atlas: Atlas, texels: Texels, terms: Terms, ambient: Ambient, rho: str,
            direct: Direct | None = None, light_colours: np.ndarray | None = None,
            indirect: np.ndarray | None = None) -> Lightmaps:
    """Scatter the texels' light L = D + I_A·W and obscurance W into page images.

    ``direct``: the texels' direct light (None: L = I_A·W); ``light_colours`` (L, 3) replaces the
    baked colour × intensity of its punctual lights (relighting without rays). ``indirect``
    (N, 3): path-traced indirect irradiance (``--method gi``) to use instead of I_A·W.
    """
    shape = (atlas.page_count, atlas.height, atlas.width)
    obscurance = np.zeros(shape + (3,))
    covered = np.zeros(shape, bool)
    r_ave = effective_r_ave(ambient, rho)
    _scatter(obscurance, texels, lambda block: _rows(terms, block, len(texels)).obscurance(r_ave))
    _scatter(covered, texels, lambda block: True)
    light = obscurance * ambient.intensity
    if indirect is not None:
        _scatter(light, texels, lambda block: indirect[block])
    if direct is not None:
        _scatter(light, texels, lambda block: _rows(direct, block, len(texels)).irradiance(
            light_colours), add=True)
    return Lightmaps(light=light, obscurance=obscurance, covered=covered)


_TEXELS_AT_ONCE = 1 << 16


def _rows(per_texel, block: slice, count: int):
    """``per_texel`` (Terms, Direct: a dataclass of (N, …) arrays) for the texels ``block``
    only: every array field with ``count`` = N rows sliced (views), the others kept (empty
    optional terms; ``Direct.light_colours``, (L, 3) per light, whatever L is)."""
    return replace(per_texel, **{
        f.name: value[block] for f in fields(per_texel)
        if isinstance(value := getattr(per_texel, f.name), np.ndarray) and value.ndim
        and len(value) == count and f.name != "light_colours"})


def _scatter(pages: np.ndarray, texels: Texels, values: Callable[[slice], np.ndarray],
             add: bool = False) -> None:
    """Write (or ``add``) the texels' values into ``pages`` (P, H, W, …), a block of texels at
    a time: ``values(block)`` gives the (k, …) values of the texels ``block``. At once, the
    (N, 3) values and ``+=``'s gathered copies would be 200 MB each at 4096²."""
    for start in range(0, len(texels), _TEXELS_AT_ONCE):
        block = slice(start, start + _TEXELS_AT_ONCE)
        where = texels.pixels(block)
        pages[where] = pages[where] + values(block) if add else values(block)
