"""What ``--target-error`` decides with: the rule a texel stops by, and how the target is
shared between the lightmap's two noisy terms.

The lightmap is L = D + I_A·W (docs/design.md §2); both terms are estimated from rays and their
errors are independent, so a texel's predicted error is σ = sqrt(σ_W² + σ_D²) in luminance.
A texel is settled when ``WITHIN``·σ ≤ E. One term's rounds come first and aim at E/√2
(``first_target``; E when the direct light is quiet: hard lights), the other's then get what
the first left of E² at each texel, at least E/√2 (``what_is_left``): the obscurance's
(``hemisphere.hemisphere_terms``) first and the direct light's
(``direct.adaptive_direct_light``) second, or with ``--method gi`` the direct light first and
the path-traced indirect light (``gi.indirect_light``) second (``direct_goes_first``). Each
term's prediction is its rays' sample variance times a
gain measured on the texels themselves (``pooled_gain``): the estimators' two independent nets
make the split of a texel's mean an unbiased, if noisy, measure of its error, and the ratio of
the splits to the sample variances, pooled over texels of like variance, is the nets'
advantage over independent rays (GI paths are independent: their sample variance is theirs).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from baker.atlas.rasterise import Texels
from baker.settings import Resolved

WITHIN = 2.0  # a texel stops when WITHIN × its predicted error ≤ the target: 95.4 % of
# normal errors lie within 2σ, and issue 22 asks for 95 % of texels within the target

NEAR = 2  # texels: a texel's neighbours are those within this many rows and columns

GAIN_TEXELS = 256  # texels at least in each group that ``pooled_gain`` measures a gain over
GAIN_GROUPS = 8


def pooled_gain(iid: np.ndarray, split: np.ndarray, seen: np.ndarray,
                like: np.ndarray) -> np.ndarray:
    """(N,) each texel's gain: Σ split / Σ iid over its group of the ``seen`` texels, grouped
    by ``like`` in up to ``GAIN_GROUPS`` equal groups of ``GAIN_TEXELS`` or more (the gain
    differs between quiet texels and noisy ones: a smooth integrand gains more); texels not
    seen take the gain of all. Sorted stably, so ties go in row order.

    iid: (N,) the variance of a texel's mean were its rays independent (sample variance / n);
    split: (N,) the square of half the difference of its two nets' means (one degree of
    freedom, unbiased for the variance of the mean); like: (N,) a measure of each texel's
    variance not taken from its own rays: its neighbours' iid (``neighbours_among``). Grouped
    by their own iid, texels whose nets happened to agree gathered in a group of their own
    and measured a gain of 0: under a ceiling at 0.3 d_max with ρ = step, 560 texels of 1681
    whose nets both saw 12 escapes of 128 (truth 11.52) stopped at 256 rays, 0.0038 off at
    E = 0.002."""
    order = np.flatnonzero(seen)[np.argsort(like[seen], kind="stable")]
    groups = max(1, min(GAIN_GROUPS, len(order) // GAIN_TEXELS))
    gain = np.full(len(iid), _gain(iid[order], split[order]))
    for part in np.array_split(order, groups):
        gain[part] = _gain(iid[part], split[part])
    return gain


def _gain(iid: np.ndarray, split: np.ndarray) -> float:
    """Σ split / Σ iid, 1 when there is no variance to measure it on."""
    pooled = float(np.sum(iid))
    return float(np.sum(split)) / pooled if pooled > 0 else 1.0


FIRST_SHARE = 1.0 / math.sqrt(2.0)  # of the target, the first noisy term's rounds aim at


def direct_goes_first(settings: Resolved) -> bool:
    """Whether the direct light's rounds come first (``--method gi``) or the obscurance's.
    The first aims at ``first_target`` and the other takes what it leaves (``what_is_left``):
    the quieter term should go first, so that the noisier one, where the rays go, gets the
    larger share. GI's paths are far noisier than the direct light's estimates; the
    obscurance's rays were the quieter on every scene of ``benchmarks/bench_target_error.py``
    with a noisy direct light (a soft light, an emissive lamp, the sky: 0.74–1.23× the rays
    of the best uniform count with the obscurance first, 0.89–1.53× with the direct light
    first)."""
    return settings.method == "gi"


def first_target(settings: Resolved, noisy_direct: bool) -> float:
    """The first term's target: ``FIRST_SHARE`` of E when the direct light is noisy too, else
    E (a quiet direct light leaves it the whole target)."""
    return settings.target_error * (FIRST_SHARE if noisy_direct else 1.0)


def obscurance_settings(settings: Resolved) -> Resolved:
    """The settings the obscurance's rounds run with: as they are, or with no target with
    ``--method gi`` (the lightmap is D + the indirect light then: W is not in it)."""
    if settings.target_error is None or settings.method != "gi":
        return settings
    return replace(settings, target_error=None)


def what_is_left(target: float, first_error: np.ndarray) -> np.ndarray:
    """(N,) the error each texel's second term may have, in ``WITHIN``·σ of lightmap
    luminance, given the first term's predicted σ (N,): what is left of E² once
    (WITHIN·σ)² is taken, at least E² − (E·``FIRST_SHARE``)² (where the first term stopped at
    ``max_rays`` short of its share, the lightmap may miss E: the rays were not allowed)."""
    left = target * target - (WITHIN * np.asarray(first_error, np.float64)) ** 2
    return np.sqrt(np.maximum(left, (1.0 - FIRST_SHARE ** 2) * target * target))


def neighbour_mean(texels: Texels, values: np.ndarray, rows: np.ndarray,
                   known: np.ndarray | None = None) -> np.ndarray:
    """(k,) the mean of ``values`` (N,) over the neighbours of the texels ``rows`` — the
    texels within ``NEAR`` rows and columns on their page, themselves left out, and of those
    only the ``known`` ones ((N,) bool, default all) — or their own value where they have none
    (a lone texel of a tiny chart). The texels are sorted by key, (page·height + y)·width + x;
    a row's last columns count as beside the next row's first (the keys run on), which only
    adds a few."""
    keys = texels.key[rows]
    total, seen = np.zeros(len(rows)), np.zeros(len(rows))
    for dy in range(-NEAR, NEAR + 1):
        for dx in range(-NEAR, NEAR + 1):
            if dy or dx:  # one vectorised pass per offset
                shifted = keys + np.uint64((dy * texels.page_width + dx) % (1 << 64))
                at = np.minimum(np.searchsorted(texels.key, shifted), len(texels.key) - 1)
                hit = texels.key[at] == shifted
                if known is not None:
                    hit &= known[at]
                total += np.where(hit, values[at], 0.0)
                seen += hit
    return np.where(seen > 0, total / np.maximum(seen, 1), values[rows])


def neighbours_among(texels: Texels, values: np.ndarray, rows: np.ndarray,
                     about: np.ndarray | None = None) -> np.ndarray:
    """``neighbour_mean`` of ``values`` (k,), known at the texels ``rows`` (k,) of ``texels``
    only: each texel's mean over its neighbours among ``rows``, for the rows ``about`` (k,)
    bool (default all)."""
    full, known = np.zeros(len(texels.key)), np.zeros(len(texels.key), bool)
    full[rows], known[rows] = values, True
    return neighbour_mean(texels, full, rows if about is None else rows[about], known)
