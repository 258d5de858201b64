"""Inverse queries of a texel's sample points, for the dirty search: which of its rays can go
into a narrow cone of directions, found without drawing the others.

``cap_boxes`` maps a cone (a cap of directions) to boxes of the unit square that hold every
sample point ``rays.sampling.concentric_hemisphere`` maps into it; ``sobol_cell_sample`` finds
the one ``sobol`` point of a texel in a cell of such a box (the first 2^bits points are a
(0, bits, 2)-net), by undoing the Owen scrambles and Sobol's generator matrix
(``net_solve``). Only the rebake asks these questions; a bake draws its points forwards
(``rays.sampling``).
"""

from __future__ import annotations

import numpy as np

from baker.jit import inline, jit
from baker.rays.sampling import (
    SOBOL_SECOND_DIRECTIONS,
    laine_karras,
    owen_scramble,
    reverse_bits,
    sobol_second_reversed,
)

_U32 = np.uint32  # the points' 32-bit fixed point, as ``rays.sampling`` computes them


@inline
def _laine_karras_preimage(target, seed, bits, most):
    """The x < 2^bits with ``laine_karras(x, seed)`` ≡ ``target`` (mod 2^bits). Bit j of the
    permutation is bit j of x flipped by a function of x's lower bits, so x is found a bit at a
    time from the lowest, ``bits`` evaluations in all. The loop runs ``most`` ≥ ``bits`` times
    (a constant where it is inlined, ``sobol_cell_sample``), the steps past ``bits`` doing
    nothing: unrolled, it costs half what a loop of ``bits`` steps does."""
    x = _U32(0)
    for j in range(most):
        if j < bits:
            bit = _U32(1) << _U32(j)
            if (laine_karras(x, seed) ^ _U32(target)) & bit:
                x |= bit
    return x


@inline
def _sample_of_index(low, shuffle, bits, most):
    """The sample s < 2^bits whose scrambled index ``owen_scramble(s, shuffle)`` has ``low`` as
    its lowest ``bits`` bits. Index bit i is bit 31 − i of LK(rev(s)), which depends on the
    bits of rev(s) up to 31 − i (those of s from i): solved a bit at a time as above, from
    bit p = 32 − bits of rev(s) up (``most`` as in ``_laine_karras_preimage``)."""
    w = _U32(0)
    for q in range(most):
        if q < bits:
            p = 32 - bits + q
            want = (_U32(low) >> _U32(bits - 1 - q)) & _U32(1)
            if ((laine_karras(w, shuffle) >> _U32(p)) & _U32(1)) != want:
                w |= _U32(1) << _U32(p)
    return reverse_bits(w)


@jit
def net_solve(bits):
    """(bits + 1, 24) uint32: row a solves for the index bits a … bits − 1 of a point of the
    first 2^bits of a texel's ``sobol`` points from the top bits − a bits of its Sobol y
    (``sobol_cell_sample``). Those y bits are the XOR of the direction numbers v_k
    (``SOBOL_SECOND_DIRECTIONS``) of the index's set bits; with the index's other bits known,
    that is a square system over GF(2), invertible because the points form a (0, bits, 2)-net.
    Entry r of row a is the mask (over y bits j = 0 … bits − a − 1, bit 31 − j of y as bit j)
    whose parity is index bit a + r: Gauss–Jordan elimination, made once per search."""
    out = np.zeros((bits + 1, 24), np.uint32)
    system = np.zeros(24, np.uint32)
    for a in range(bits + 1):
        c = bits - a
        for j in range(c):  # row j of the system: which unknowns bit 31 − j of y holds
            system[j] = _U32(0)
            for r in range(c):
                if (SOBOL_SECOND_DIRECTIONS[a + r] >> _U32(31 - j)) & _U32(1):
                    system[j] |= _U32(1) << _U32(r)
            out[a, j] = _U32(1) << _U32(j)
        for r in range(c):
            pivot = r
            while not (system[pivot] >> _U32(r)) & _U32(1):
                pivot += 1
            system[r], system[pivot] = system[pivot], system[r]
            out[a, r], out[a, pivot] = out[a, pivot], out[a, r]
            for j in range(c):
                if j != r and (system[j] >> _U32(r)) & _U32(1):
                    system[j] ^= system[r]
                    out[a, j] ^= out[a, r]
    return out


@inline
def _parity(x):
    """The parity of the set bits of a uint32."""
    x ^= x >> _U32(16)
    x ^= x >> _U32(8)
    x ^= x >> _U32(4)
    x ^= x >> _U32(2)
    x ^= x >> _U32(1)
    return x & _U32(1)


@inline
def _cell_sample(columns, column, row, bits, scrambles, solve, most):
    """``sobol_cell_sample`` with its loops run ``most`` ≥ ``bits`` times."""
    shuffle, sx, sy = scrambles
    c = bits - columns
    low = _U32(0)
    if columns > 0:  # x = rev(LK(index, sx)): its top bits are LK(index)'s low ones
        target = reverse_bits(_U32(column)) >> _U32(32 - columns)  # lowest first
        low = _laine_karras_preimage(target, sx, columns, most)
    if c > 0:  # y = rev(LK(rev(sobol2(index)), sy)): the top c bits of sobol2(index)
        target = reverse_bits(_U32(row)) >> _U32(32 - c)
        top = reverse_bits(_laine_karras_preimage(target, sy, c, most))
        mask = (_U32(1) << _U32(bits)) - _U32(1)
        known = (owen_scramble(0, shuffle) & ~mask) | low  # the same for every sample < 2^bits
        rhs = reverse_bits(top ^ reverse_bits(sobol_second_reversed(known)))
        for r in range(most):
            if r < c:
                low |= _parity(solve[columns, r] & rhs) << _U32(columns + r)
    return int(_sample_of_index(low, shuffle, bits, most))


@inline
def sobol_cell_sample(columns, column, row, bits, scrambles, solve):
    """Which sample s < 2^bits of a texel (its ``texel_scrambles``) has its ``sobol`` point in
    cell (``column``, ``row``) of the grid of 2^columns columns × 2^(bits − columns) rows on
    [0, 1)²; bits ≤ 24, ``solve`` = ``net_solve(bits)``. The first 2^bits points of each texel
    form a (0, bits, 2)-net, so exactly one lies in each such cell: a texel's rays that can go
    in a narrow cone of directions are found without drawing the others
    (``near_rays._cell_candidates``), in the grid whose cells a box of the cone crosses
    fewest of (columns = bits: strips of x; 0: strips of y). Both coordinates are
    Owen-scrambled values of the index, and the index an Owen-scrambled sample number: each
    scramble is undone a bit at a time (``_laine_karras_preimage``); x gives the index's low
    bits, y the others through Sobol's generator matrix (``net_solve``). The bit loops have a
    fixed length up to 256 rays, 8, so that they unroll: 108 -> 76 ns a cell at 64 rays
    (another fixed length for 16 bits unrolled a third copy: the search took 15 s to compile
    cold, not 12)."""
    if bits == 0:
        return 0
    if bits <= 8:
        return _cell_sample(columns, column, row, bits, scrambles, solve, 8)
    return _cell_sample(columns, column, row, bits, scrambles, solve, bits)


_QUARTER_PI = np.pi / 4

_ANGLE_SLACK = 1e-7  # radians added to the cap's azimuths: far beyond rounding of the map

_UNIT_SLACK = 1e-9  # added to the boxes in [0, 1)²


@inline
def _region_box(region, r0, r1, lo, hi, boxes, row):
    """Row ``row`` of ``boxes``: (u0, u1, v0, v1), the box of the points that
    ``concentric_hemisphere`` maps into radii [r0, r1] and azimuths [lo, hi] of one of its
    four regions (0: a = r, azimuths [−π/4, π/4]; 1: b = r, [π/4, 3π/4]; 2: a = −r,
    [3π/4, 5π/4]; 3: b = −r, [5π/4, 7π/4]), where (a, b) = (2u − 1, 2v − 1). In each region
    (a, b) is bilinear in (r, azimuth): the box of the four corners holds them all."""
    a_low = b_low = 1.0
    a_high = b_high = -1.0
    for r in (r0, r1):
        for phi in (lo, hi):
            if region == 0:
                a, b = r, r * phi / _QUARTER_PI
            elif region == 1:
                a, b = r * (2 * _QUARTER_PI - phi) / _QUARTER_PI, r
            elif region == 2:
                a, b = -r, -r * (phi - 4 * _QUARTER_PI) / _QUARTER_PI
            else:
                a, b = r * (phi - 6 * _QUARTER_PI) / _QUARTER_PI, -r
            a_low, a_high = min(a_low, a), max(a_high, a)
            b_low, b_high = min(b_low, b), max(b_high, b)
    boxes[row, 0] = (a_low + 1.0) / 2 - _UNIT_SLACK
    boxes[row, 1] = (a_high + 1.0) / 2 + _UNIT_SLACK
    boxes[row, 2] = (b_low + 1.0) / 2 - _UNIT_SLACK
    boxes[row, 3] = (b_high + 1.0) / 2 + _UNIT_SLACK


@inline
def cap_boxes(cx, cy, cz, sin_half, boxes):
    """Boxes of [0, 1)² that hold every point ``concentric_hemisphere`` maps into the cap of
    directions within asin(``sin_half``) of the unit axis (cx, cy, cz) (any z): rows (u0, u1,
    v0, v1) of ``boxes`` (8, 4), at most two per region of the map. Returns how many, or −1 when
    the cap holds the pole, so that any point may (0: the cap is below the hemisphere).

    A direction at polar angle θ and azimuth φ comes from a point at "radius" max(|a|, |b|) =
    sin θ, in the region of its azimuth: the cap spans θ ∈ [θc − α, θc + α] and, when it holds
    no pole, φ ∈ φc ± asin(sin α / sin θc). The radii come from the sines and cosines of θc and
    α without an angle (two calls to libm's trigonometry remain: a texel's search makes
    millions of these)."""
    sin_alpha = min(max(sin_half, 0.0) * (1.0 + 1e-9) + 1e-9, 1.0)
    cos_alpha = np.sqrt(1.0 - sin_alpha * sin_alpha)
    sin_theta = np.sqrt(cx * cx + cy * cy)
    if cz >= cos_alpha:  # θc ≤ α
        return -1
    if cz * cos_alpha + sin_theta * sin_alpha <= 0.0:  # cos(θc − α) ≤ 0: all below
        return 0
    r0 = max(sin_theta * cos_alpha - cz * sin_alpha - _UNIT_SLACK, 0.0)  # sin(θc − α)
    if cz * cos_alpha - sin_theta * sin_alpha >= 0.0:  # θc + α ≤ π/2
        r1 = min(sin_theta * cos_alpha + cz * sin_alpha + _UNIT_SLACK, 1.0)
    else:
        r1 = 1.0
    if sin_alpha >= sin_theta:
        spread = 4 * _QUARTER_PI  # every azimuth
    else:
        spread = np.arcsin(sin_alpha / sin_theta) + _ANGLE_SLACK
    centre = np.arctan2(cy, cx)
    count = 0
    for region in range(4):
        start = (2 * region - 1) * _QUARTER_PI  # the region's azimuths [start, start + π/2]
        for turn in (-8 * _QUARTER_PI, 0.0, 8 * _QUARTER_PI):
            lo = max(centre - spread, start + turn)
            hi = min(centre + spread, start + 2 * _QUARTER_PI + turn)
            if lo <= hi:
                _region_box(region, r0, r1, lo - turn, hi - turn, boxes, count)
                count += 1
    return count
