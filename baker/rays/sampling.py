"""Deterministic sample points: a pure function of (seed, texel key, sample index, dimension).

No random state flows between texels, chunks or threads (docs/design.md §4): the same texel asks for
the same sample and always gets the same number, as in pbrt-v4's ``StartPixelSample``.

Three techniques (``TECHNIQUES``), all pure functions of those four numbers:

- ``sobol`` (default): the first two dimensions of the Sobol sequence (a (0, 2)-sequence in
  base 2), Owen-scrambled per texel with the hash of Burley, "Practical Hash-based Owen
  Scrambling" (JCGT 2020); the sample index is Owen-scrambled too, so every texel walks its own
  permutation of a Sobol net. Error falls faster than 1/sqrt(N) on smooth integrands. A
  texel's N samples are two such nets, independently scrambled (the first ⌊N/2⌋ and the rest),
  and each adaptive round's batch a net of its own (``fill_points``): like the stratified
  grid's two layers, independent halves make the error measurable without a model of how it
  falls (``hemisphere.Terms.rmse``, ``direct_estimators.mean_and_variance``).
- ``stratified``: a jittered grid of ⌊N/2⌋ cells (rows × columns, as square as N allows) laid
  twice: the first half of the texel's N samples puts one point in every cell and so does the
  second, independently (an odd last sample is independent). Two samples per stratum are what
  make the error measurable (Cochran, "Sampling Techniques", §5A): the halves' means are
  independent estimates of equal variance, so their difference gives the variance of the whole
  mean without bias (``integrate.Terms.rmse``). Each call's samples form one such grid, so an
  adaptive round (a batch of samples) is a stratified estimate of its own.
- ``random``: independent uniform points (plain Monte Carlo).

Each further 2D ``dimension`` is an independently randomised copy. The per-sample arithmetic is
compiled with numba (``nogil``, so the integrator's threads run it side by side): the scalar
functions below are the one implementation, which both the array functions and the integrator's
fused ray-generation kernel call. uint64/uint32 arithmetic wraps as the hashes intend.
"""

from __future__ import annotations

import numpy as np

from baker.jit import inline, jit
from baker.settings import TECHNIQUES

_U64 = np.uint64
_U32 = np.uint32
_GOLDEN = _U64(0x9E3779B97F4A7C15)
_MIX1 = _U64(0xBF58476D1CE4E5B9)
_MIX2 = _U64(0x94D049BB133111EB)
_S30, _S27, _S31 = _U64(30), _U64(27), _U64(31)
_LOW32 = _U64(0xFFFFFFFF)
_TO_UNIT = 1.0 / 16777216.0  # 2^-24: a 24-bit fixed-point value to [0, 1)


@jit
def _mix(h, word):
    """One splitmix64 finaliser round of ``word`` into the state ``h`` (both uint64)."""
    h = h ^ word
    h = (h ^ (h >> _S30)) * _MIX1
    h = (h ^ (h >> _S27)) * _MIX2
    return h ^ (h >> _S31)


@jit
def hash4(a, b, c, d):
    """uint32 hash of four integer words (each taken mod 2^64)."""
    h = _mix(_GOLDEN, _U64(a))
    h = _mix(h, _U64(b))
    h = _mix(h, _U64(c))
    h = _mix(h, _U64(d))
    return _U32(h & _LOW32)


@jit
def reverse_bits(x):
    """Reverse the 32 bits of a uint32."""
    x = ((x >> _U32(1)) & _U32(0x55555555)) | ((x & _U32(0x55555555)) << _U32(1))
    x = ((x >> _U32(2)) & _U32(0x33333333)) | ((x & _U32(0x33333333)) << _U32(2))
    x = ((x >> _U32(4)) & _U32(0x0F0F0F0F)) | ((x & _U32(0x0F0F0F0F)) << _U32(4))
    x = ((x >> _U32(8)) & _U32(0x00FF00FF)) | ((x & _U32(0x00FF00FF)) << _U32(8))
    return _U32((x >> _U32(16)) | (x << _U32(16)))


@jit
def laine_karras(x, seed):
    """Burley's improved Laine–Karras permutation: each bit flips depending on lower bits only."""
    x = _U32(x + seed)
    x ^= _U32(x * _U32(0x6C50B47C))
    x ^= _U32(x * _U32(0xB82F1E52))
    x ^= _U32(x * _U32(0xC7AFE638))
    x ^= _U32(x * _U32(0x8D22F6E6))
    return x


@jit
def owen_scramble(x, seed):
    """Nested uniform (Owen) scrambling of a 32-bit fixed-point value ``x`` with ``seed``."""
    return reverse_bits(laine_karras(reverse_bits(_U32(x)), _U32(seed)))


def _sobol_second_directions() -> list[int]:
    """The 32 direction numbers of dimension 1 of Sobol: the generator matrix of the polynomial
    x + 1 has v_k = v_{k-1} ^ (v_{k-1} >> 1), v_0 = 2^31 (rows of Pascal's triangle mod 2: v_k's
    lowest set bit is bit 31 − k)."""
    directions = [1 << 31]
    for _ in range(31):
        directions.append(directions[-1] ^ (directions[-1] >> 1))
    return directions


SOBOL_SECOND_DIRECTIONS = np.array(_sobol_second_directions(), np.uint32)


def _sobol_second_table() -> np.ndarray:
    """(4, 256) uint32: dimension 1 of Sobol for each byte value at each byte position.

    The point of an index is the XOR of the direction numbers v_k over its set bits, so it is
    the XOR of one table entry per byte of the index.
    """
    directions = _sobol_second_directions()
    table = np.zeros((4, 256), np.uint32)
    for position in range(4):
        for value in range(256):
            for bit in range(8):
                if value >> bit & 1:
                    table[position, value] ^= directions[8 * position + bit]
    return table


# Bit-reversed entries: Owen scrambling works on reversed bits, and reversal commutes with XOR.
_SOBOL_SECOND_REVERSED = np.array(
    [[int(f"{v:032b}"[::-1], 2) for v in row] for row in _sobol_second_table()], np.uint32)


@jit
def sobol_second_reversed(index):
    """Dimension 1 of the Sobol sequence at ``index``, 32-bit fixed point, bits reversed.

    (Dimension 0 is the van der Corput sequence, ``reverse_bits(index)``.)
    """
    table = _SOBOL_SECOND_REVERSED
    return _U32(table[0, index & _U32(255)] ^ table[1, (index >> _U32(8)) & _U32(255)]
                ^ table[2, (index >> _U32(16)) & _U32(255)] ^ table[3, index >> _U32(24)])


@jit
def _unit(bits):
    """The top 24 bits of a uint32 as a float in (0, 1), centred: never exactly 0 or 1."""
    return ((bits >> _U32(8)) + 0.5) * _TO_UNIT


@jit
def texel_scrambles(seed, key, dimension):
    """The three per-(texel, dimension) hashes the sample points need (index, x, y scrambles)."""
    return (hash4(seed, key, dimension, 0), hash4(seed, key, dimension, 1),
            hash4(seed, key, dimension, 2))


@jit
def _sobol_point(sample, shuffle, sx, sy):
    """Owen-scrambled Sobol point ``sample`` of a texel with scrambles (shuffle, sx, sy).

    owen_scramble(x, seed) = rev(LK(rev(x), seed)); dimension 0 is rev(index), so its scramble
    is rev(LK(index)), and dimension 1 is read from the bit-reversed table.
    """
    index = owen_scramble(_U32(sample), shuffle)
    return (_unit(reverse_bits(laine_karras(index, sx))),
            _unit(reverse_bits(laine_karras(sobol_second_reversed(index), sy))))


@jit
def _grid(count):
    """(cells, columns) of the stratified grid for ``count`` samples: ⌊count/2⌋ cells in the
    most nearly square rows × columns (rows the largest divisor of cells up to its root)."""
    cells = count // 2
    rows = max(int(np.sqrt(cells)), 1)
    while cells % rows:
        rows -= 1
    return cells, max(cells // rows, 1)


@jit
def _hashed_point(technique, sample, local, cells, columns, shuffle, sx, sy):
    """Point ``sample`` for the ``stratified`` (1) or ``random`` (2) technique: the jitter is
    hashed from the sample index, the stratum is the ``local``-th of a grid of ``cells`` cells in
    ``columns`` columns laid twice (``_grid``); samples past both layers are independent."""
    jitter_x = _unit(hash4(sx, sample, shuffle, 3))
    jitter_y = _unit(hash4(sy, sample, shuffle, 4))
    if technique == 1 and local < 2 * cells:
        cell = local % cells
        return ((cell % columns + jitter_x) / columns,
                (cell // columns + jitter_y) / (cells // columns))
    return jitter_x, jitter_y


@jit
def point(technique, sample, count, scrambles):
    """Sample ``sample`` of ``count`` for one texel and dimension: a point (x, y) of (0, 1)².

    technique: 0 sobol, 1 stratified, 2 random (the order of ``TECHNIQUES``); scrambles: that
    texel's ``texel_scrambles``. ``count`` matters to the stratified grid only (samples
    0 … count − 1 form one grid).
    """
    shuffle, sx, sy = scrambles
    if technique == 0:
        return _sobol_point(sample, shuffle, sx, sy)
    cells, columns = _grid(count)
    return _hashed_point(technique, sample, sample, cells, columns, shuffle, sx, sy)


REPLICA = 1 << 32  # the net of a dimension d's samples from sample f on: scrambles of word
# d + f·REPLICA (``net_word``; no dimension reaches 2^32)


@jit
def net_word(dimension, start):
    """The scramble word of the ``sobol`` net of ``dimension``'s samples that starts at sample
    ``start`` (``fill_points``): the dimension itself for the net from sample 0."""
    return _U64(dimension) + _U64(start) * _U64(REPLICA)


@jit
def fill_points(technique, seed, keys, first, count, dimension, u, v):
    """Samples ``first`` … ``first + count − 1`` of every texel in ``keys`` (k,) into ``u``, ``v``
    (k·count,), texel-major; for ``stratified`` these samples form one grid of their own
    (``_grid(count)``), as ``point`` gives them.

    ``sobol``: independent scrambled nets, so that the error of a texel's mean can be measured
    from its halves (``hemisphere.Terms.rmse``, ``direct_estimators.mean_and_variance``): from
    ``first`` = 0, samples 0 … ⌊count/2⌋ − 1 are the first points of one net and the rest the
    first points of another; from ``first`` > 0 (an adaptive round) the ``count`` samples are
    one net. The net that starts at sample f takes the scrambles of ``net_word(dimension, f)``
    (``point`` with a net's own sample numbers gives its points). One net's halves would be
    anti-correlated, and no estimate from them holds on every integrand.

    The technique is chosen once per texel, outside the inner loop, so that the compiler
    vectorises the Sobol case.
    """
    cells, columns = _grid(count)
    split = first if first > 0 else count // 2  # where the (second) net starts
    for i in range(len(keys)):
        shuffle, sx, sy = texel_scrambles(seed, keys[i], dimension)
        base = i * count - first
        if technique == 0:
            for s in range(first, split):  # the first net, from sample 0 (word ``dimension``)
                u[base + s], v[base + s] = _sobol_point(s, shuffle, sx, sy)
            shuffle, sx, sy = texel_scrambles(seed, keys[i], net_word(dimension, split))
            for s in range(split, first + count):
                u[base + s], v[base + s] = _sobol_point(s - split, shuffle, sx, sy)
        else:
            for s in range(first, first + count):
                u[base + s], v[base + s] = _hashed_point(technique, s, s - first, cells, columns,
                                                         shuffle, sx, sy)


@jit
def extend_nets(seed, keys, have, more, second, dimension, u, v):
    """The ``sobol`` points of an adaptive round: each texel of ``keys`` (k,) has points
    0 … have − 1 of its two nets already; write points have … have + more − 1 of the first net
    (word ``dimension``) then the same of the second (word ``second``: the ``net_word`` of the
    sample where ``fill_points`` started it) into ``u``, ``v`` (k·2·more,), texel-major. Both
    nets grow as one longer net would, so a texel with n rays holds two nets of n/2 points,
    as a bake with n rays from the start does (Owen-scrambled Sobol prefixes are nets)."""
    count = 2 * more
    for i in range(len(keys)):
        base = i * count
        for net in range(2):
            word = dimension if net == 0 else second
            shuffle, sx, sy = texel_scrambles(seed, keys[i], word)
            for s in range(more):
                u[base + net * more + s], v[base + net * more + s] = _sobol_point(
                    have + s, shuffle, sx, sy)


def net_points(seed: int, keys: np.ndarray, first: int, count: int, dimension: int,
               technique: str = "sobol", start: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Points u, v (k·count,) of samples ``first`` … ``first + count − 1`` of the texels
    ``keys`` (k,), texel-major, as ``fill_points`` lays them out: with ``sobol`` from
    ``first`` = 0 two independent nets, the first ⌊count/2⌋ samples of one then the rest of the
    other. ``start`` > 0 (``sobol``, an adaptive round: ``first`` and ``count`` even): the
    samples grow the two nets that a first round of ``start`` samples began, to ``first``/2 +
    ``count``/2 points each (``extend_nets``), the first net's new points then the second's."""
    u, v = np.empty(len(keys) * count), np.empty(len(keys) * count)
    if start and first and technique == "sobol":
        extend_nets(_U64(seed), keys, first // 2, count // 2,
                    net_word(_U64(dimension), start // 2), _U64(dimension), u, v)
    else:
        fill_points(TECHNIQUES.index(technique), _U64(seed), keys, first, count,
                    _U64(dimension), u, v)
    return u, v


@jit
def _points_kernel(technique, seed, keys, samples, counts, dimension, out):
    for i in range(len(keys)):
        out[i, 0], out[i, 1] = point(technique, samples[i], counts[i],
                                     texel_scrambles(seed, keys[i], dimension))


def sample_2d(seed: int, keys: np.ndarray, samples: np.ndarray, dimension: int,
              technique: str = "sobol", count: int | None = None) -> np.ndarray:
    """Points in (0, 1)² for (texel ``keys``, ``samples``) pairs, broadcast together.

    keys: uint64 texel keys; samples: sample indices; dimension: which 2D pair of dimensions;
    count: samples per texel (for ``stratified``; default max(samples) + 1). Returns (..., 2)
    float64. A pure function of its arguments.
    """
    keys, samples = np.broadcast_arrays(np.asarray(keys, np.uint64), np.asarray(samples, np.int64))
    if count is None:
        count = int(samples.max()) + 1 if samples.size else 1
    out = np.empty(keys.shape + (2,))
    _points_kernel(TECHNIQUES.index(technique), _U64(seed), np.array(keys.reshape(-1)),
                   np.array(samples.reshape(-1)), np.full(keys.size, count, np.int64), _U64(dimension),
                   out.reshape(-1, 2))
    return out


def split_samples(seed: int, keys: np.ndarray, n: int, dimension: int) -> np.ndarray:
    """(k, n, 2) ``sobol`` points for ``n`` samples of each of the (k,) ``keys``, as
    ``fill_points`` draws them from sample 0: two independent nets, samples 0 … ⌊n/2⌋ − 1 and
    ⌊n/2⌋ … n − 1, so that the difference of their means measures the error of the whole mean
    without bias (``direct_estimators.mean_and_variance``). n = 1 gives sample 0 of
    ``dimension``, as ``sample_2d`` does."""
    keys = np.ascontiguousarray(np.asarray(keys, np.uint64).reshape(-1))
    u, v = np.empty(len(keys) * n), np.empty(len(keys) * n)
    fill_points(0, _U64(seed), keys, 0, n, _U64(dimension), u, v)
    return np.stack([u, v], axis=1).reshape(len(keys), n, 2)


@jit
def _sin_cos(t):
    """(sin t, cos t) for |t| ≤ π/4 by their Taylor polynomials (error below 1e-16).

    Several times faster than libm's sin and cos, which reduce any argument's range first.
    """
    t2 = t * t
    sin = t * (1.0 + t2 * (-1.0 / 6 + t2 * (1.0 / 120 + t2 * (-1.0 / 5040 + t2 * (
        1.0 / 362880 + t2 * (-1.0 / 39916800 + t2 * (1.0 / 6227020800 + t2 * (
            -1.0 / 1307674368000))))))))
    cos = 1.0 + t2 * (-0.5 + t2 * (1.0 / 24 + t2 * (-1.0 / 720 + t2 * (1.0 / 40320 + t2 * (
        -1.0 / 3628800 + t2 * (1.0 / 479001600 + t2 * (-1.0 / 87178291200 + t2 * (
            1.0 / 20922789888000))))))))
    return sin, cos


@jit
def concentric_hemisphere(u, v):
    """Map (u, v) of [0, 1)² to a unit direction (x, y, z), z ≥ 0, with pdf cosθ / π.

    Shirley–Chiu concentric disk mapping, lifted to the hemisphere (Malley's method); the
    mapping keeps the points' stratification. In both wedges the angle is t = (π/4)·minor/major
    in [−π/4, π/4], so that ``_sin_cos`` applies; the wedge is chosen by selects, not branches,
    so that loops over points vectorise.
    """
    a = 2.0 * u - 1.0
    b = 2.0 * v - 1.0
    first = abs(a) > abs(b)
    major = a if first else b
    minor = b if first else a
    sin, cos = _sin_cos((np.pi / 4) * (minor / (major if major != 0.0 else 1.0)))
    x = major * (cos if first else sin)
    y = major * (sin if first else cos)
    return x, y, np.sqrt(max(1.0 - major * major, 0.0))


@jit
def fill_cosine(u, v, x, y, z):
    """``concentric_hemisphere`` of every point (u, v) (n,) into x, y, z (n,) (vectorised)."""
    for i in range(len(u)):
        x[i], y[i], z[i] = concentric_hemisphere(u[i], v[i])


@jit
def _cosine_kernel(points, out):
    for i in range(len(points)):
        out[i, 0], out[i, 1], out[i, 2] = concentric_hemisphere(points[i, 0], points[i, 1])


def cosine_hemisphere(u: np.ndarray) -> np.ndarray:
    """Map points (..., 2) of [0, 1)² to unit directions (..., 3) around +z with pdf cosθ / π."""
    u = np.ascontiguousarray(u, np.float64)
    out = np.empty(u.shape[:-1] + (3,))
    _cosine_kernel(u.reshape(-1, 2), out.reshape(-1, 3))
    return out


@jit
def frame(nx, ny, nz):
    """Two unit tangents orthogonal to the unit normal (nx, ny, nz) and to each other.

    Duff et al., "Building an Orthonormal Basis, Revisited" (JCGT 2017): no singularity.
    Returns (t1x, t1y, t1z, t2x, t2y, t2z).
    """
    sign = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (1.0 + sign * nx * nx * a, sign * b, -sign * nx, b, sign + ny * ny * a, -ny)


@jit
def _frames_kernel(normals, t1, t2):
    for i in range(len(normals)):
        f = frame(normals[i, 0], normals[i, 1], normals[i, 2])
        t1[i, 0], t1[i, 1], t1[i, 2] = f[0], f[1], f[2]
        t2[i, 0], t2[i, 1], t2[i, 2] = f[3], f[4], f[5]


def tangent_frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (k, 3) each, orthogonal to unit ``normals`` (k, 3) and to each other."""
    normals = np.ascontiguousarray(normals, np.float64)
    t1, t2 = np.empty_like(normals), np.empty_like(normals)
    _frames_kernel(normals, t1, t2)
    return t1, t2


# Shading normals within this distance (unit vectors) of their triangle's front-face normal are
# taken as the face normal: float32 normals and positions of a flat surface differ by ~1e-7, and
# a hemisphere tilted by 1e-5 rad changes no estimate visibly, while the face normal keeps the
# flat surface's rays the very bits they had before shading normals were followed.
FLAT_NORMAL = 1e-5


def hemisphere_normals(shading: np.ndarray, geometric: np.ndarray) -> np.ndarray:
    """(k, 3) the normals that points' hemispheres of rays are drawn about: the unit shading
    normals ``shading`` (k, 3) (interpolated vertex normals), or the unit front-face normals
    ``geometric`` (k, 3) where the two lie within ``FLAT_NORMAL`` of each other (a flat surface)
    or the front face has none (zeros: no area). Rays drawn about them that point below the
    front face's plane are folded back above it (``fold``)."""
    flat = ((np.abs(shading - geometric).max(axis=1) <= FLAT_NORMAL)
            | ~(np.abs(geometric).max(axis=1) > 0))
    return np.where(flat[:, None], geometric, shading)


@inline
def fold(dx, dy, dz, gx, gy, gz):
    """The direction (dx, dy, dz) mirrored about the plane of unit normal (gx, gy, gz) when it
    points below that plane (itself otherwise). A hemisphere drawn about a shading normal that
    tilts from the face normal g has a sliver below the face's plane; a ray there would start
    into its own surface (the shadow terminator's self-shadowing) or through it (a leak). Folded,
    every ray leaves on the face's front side, from an origin lifted along g, and keeps its
    weight: a point that nothing surrounds still sees all its rays escape."""
    dot = dx * gx + dy * gy + dz * gz
    if dot < 0.0:
        return dx - 2.0 * dot * gx, dy - 2.0 * dot * gy, dz - 2.0 * dot * gz
    return dx, dy, dz


@jit
def _fold_kernel(directions, frames, geometric):
    for i in range(len(directions)):
        if (frames[i, 0] != geometric[i, 0] or frames[i, 1] != geometric[i, 1]
                or frames[i, 2] != geometric[i, 2]):
            directions[i, 0], directions[i, 1], directions[i, 2] = fold(
                directions[i, 0], directions[i, 1], directions[i, 2],
                geometric[i, 0], geometric[i, 1], geometric[i, 2])


def folded(directions: np.ndarray, frames: np.ndarray, geometric: np.ndarray) -> np.ndarray:
    """(m, 3) float64 ``directions`` (m, 3) drawn about the normals ``frames`` (m, 3)
    (``hemisphere_normals``) with those below their front face ``geometric`` (m, 3) folded above
    it (``fold``); rows whose frame is the face normal itself are left as drawn, bit for bit."""
    out = np.array(directions, np.float64)
    _fold_kernel(out, np.ascontiguousarray(frames, np.float64),
                 np.ascontiguousarray(geometric, np.float64))
    return out


def hash_u32(*words) -> np.ndarray:
    """uint32 hash of up to four integer words (arrays broadcast together), zero-padded.

    The same ``hash4`` the samplers use, for callers that need a deterministic integer per item.
    """
    arrays = np.broadcast_arrays(*[np.asarray(w).astype(np.uint64) for w in words],
                                 *([np.uint64(0)] * (4 - len(words))))
    flat = [np.array(a.reshape(-1)) for a in arrays]  # own, writeable, contiguous copies
    out = np.empty(flat[0].size, np.uint32)
    _hash_kernel(*flat, out)
    return out.reshape(arrays[0].shape)


@jit
def _hash_kernel(a, b, c, d, out):
    for i in range(len(out)):
        out[i] = hash4(a[i], b[i], c[i], d[i])
