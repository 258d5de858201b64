"""A texel's terms updated by the change of some of its rays, exactly (the rebake's by-ray path).

Every ray's values are rounded to multiples of 2^-40 before the bake sums them
(``light.hemisphere._on_grid``), so a texel's sums are exact whatever the order. The stored
means give the sums back (``_sums_of``, checked bit for bit by recomputing the means); a move's
changed rays then take their old values out and put their new ones in (``ray_changes``), and
the means of the new sums are what a full bake of the edited scene computes
(``changed_terms``).
"""

from __future__ import annotations

import numpy as np

from baker.geometry.surface import LUMINANCE
from baker.light.hemisphere import (
    COLUMNS,
    ESCAPED,
    HALF,
    NO_DIRECTIONS,
    RGB,
    SQUARE,
    Surfaces,
    Terms,
    accumulate_kernel,
    grid_values,
    hit_shading,
    luminance_and_escaped,
    terms_of_sums,
)
from baker.light.obscurance import RHO_KINDS
from baker.rays.trace import LocalHits
from baker.settings import Resolved


def ray_changes(surfaces: Surfaces, settings: Resolved, target: np.ndarray,
                sample: np.ndarray, before: LocalHits, after: LocalHits,
                count: int) -> np.ndarray:
    """(count, 7) what some rays' change adds to their texels' sums (``accumulate_kernel``'s
    columns, exact): rays of no mirror, glass or translucent surface (``Surfaces.special``),
    ray j being sample ``sample[j]`` (m,) of texel ``target[j]`` (m,) (rows 0 … count − 1),
    whose hits went from ``before`` to ``after`` (within d_max)."""
    changes = np.zeros((count, COLUMNS))
    for sign, hits in ((-1.0, before), (1.0, after)):
        kind, ray_albedo = hit_shading(surfaces, settings, hits)
        accumulate_kernel(settings.rays, hits.triangle, hits.distance,
                          np.float32(settings.d_max), RHO_KINDS[settings.rho], surfaces.table,
                          kind, ray_albedo, LUMINANCE, changes, target, sample, sign,
                          NO_DIRECTIONS)
    return changes


def _sums_of(terms: Terms) -> np.ndarray:
    """(k, 7) the sums ``terms_of_sums`` made ``terms`` from (of one round of rays), worked back from
    the means: each is a multiple of 2^-40 far smaller than float64's precision can tell apart,
    so rounding recovers it. ``changed_terms`` checks the result."""
    n = terms.counts.astype(np.float64)
    sums = np.zeros((len(n), COLUMNS))
    sums[:, RGB] = grid_values(terms.w_hit * n[:, None])
    sums[:, ESCAPED] = grid_values(terms.escaped * n)
    sums[:, SQUARE] = grid_values(terms.hit_sq * n)
    sums[:, HALF] = _part_sums(terms.half_split, terms.counts // 2,
                               luminance_and_escaped(sums), terms.counts)
    return sums


def _part_sums(split: np.ndarray, part: np.ndarray, whole: np.ndarray,
               whole_count: np.ndarray) -> np.ndarray:
    """(k, 2) the sums over the first ``part`` (k,) of ``whole_count`` (k,) rays, whose sums are
    ``whole`` (k, 2), from ``_split``'s split = sum/p − (whole − sum)/(n − p), rounded to the
    grid; 0 where ``_split`` gave 0 for want of rays."""
    p = part.astype(np.float64)[:, None]
    rest = (whole_count - part).astype(np.float64)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        found = (split + whole / rest) * (p * rest) / (p + rest)
    return np.where((p >= 1) & (rest >= 1), grid_values(found), 0.0)


def changed_terms(terms: Terms, changes: np.ndarray) -> tuple[Terms, np.ndarray]:
    """The terms (k rows) of texels whose rays' values changed by ``changes`` (k, 7)
    (``ray_changes``), and (k,) bool: the rows whose old sums were recovered exactly (the
    others must be traced anew). ``terms``: the texels' terms from one round of rays (no
    adaptive rounds, no light through translucent surfaces)."""
    sums = _sums_of(terms)
    again = terms_of_sums(sums, terms.counts)
    exact = np.ones(len(sums), bool)
    for name in ("w_hit", "escaped", "hit_sq", "half_split"):
        mine, theirs = getattr(again, name), getattr(terms, name)
        same = mine == theirs
        exact &= same.all(axis=tuple(range(1, same.ndim)))
    return terms_of_sums(sums + changes, terms.counts), exact
