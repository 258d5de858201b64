"""Per-texel obscurance terms, everything included: the hemisphere's rays (``hemisphere``) and
the light that comes through translucent surfaces (``inner``, paper §4)."""

from __future__ import annotations

from typing import Callable

import numpy as np

from baker.atlas.rasterise import Texels
from baker.context import Context
from baker.light.hemisphere import Surfaces, Terms, hemisphere_terms
from baker.light.inner import add_translucency


def integrate(context: Context, texels: Texels,
              progress: Callable[[int, int], None] | None = None, rows: np.ndarray | None = None,
              error_scale: tuple[np.ndarray, float] | None = None,
              translucency: bool = True, surfaces: Surfaces | None = None,
              targets: np.ndarray | None = None) -> Terms:
    """The obscurance terms of the texels ``rows`` (default: all), in that order, with the
    context's world, tracer and settings
    (``hemisphere.hemisphere_terms``: rays, rounds, ``progress``, ``error_scale``,
    ``surfaces``, ``targets``). ``translucency``: add the leaves' back faces and the inner
    obscurances of closed translucent objects (``inner.add_translucency``, §4)."""
    terms = hemisphere_terms(context, texels, progress, rows, error_scale, surfaces, targets)
    if not translucency:
        return terms
    rows = np.arange(len(texels)) if rows is None else np.asarray(rows, np.int64)
    return add_translucency(context, texels, rows, terms, error_scale, targets)
