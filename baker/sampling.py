"""Deterministic sample points: a pure function of (seed, texel key, sample index, dimension).

No random state flows between texels, chunks or threads (DESIGN.md §4): the same texel asks for
the same sample and always gets the same number, as in pbrt-v4's ``StartPixelSample``.

The points are the first two dimensions of the Sobol sequence (a (0, 2)-sequence in base 2),
Owen-scrambled per texel with the hash of Burley, "Practical Hash-based Owen Scrambling" (JCGT
2020); the sample index is Owen-scrambled too, so every texel walks its own permutation of a
Sobol net. Error falls faster than 1/sqrt(N) on smooth integrands, as quasi-Monte Carlo bakers'
does. Each further 2D ``dimension`` is an independently scrambled copy of the same net.

All arithmetic is on uint32/uint64 numpy arrays, where overflow wraps as the hashes intend.
"""

from __future__ import annotations

import numpy as np

_U32 = np.uint32


def hash_u32(*words: np.ndarray | int) -> np.ndarray:
    """Mix integer words (arrays broadcast together, values taken mod 2^64) into uint32.

    A splitmix64-style finaliser applied after each word; good avalanche, cheap in numpy.
    """
    with np.errstate(over="ignore"):
        h = np.uint64(0x9E3779B97F4A7C15)
        for word in words:
            h = h ^ np.asarray(word).astype(np.uint64)
            h = (h ^ (h >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
            h = (h ^ (h >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
            h = h ^ (h >> np.uint64(31))
        return (h & np.uint64(0xFFFFFFFF)).astype(_U32)


def _reverse_bits(x: np.ndarray) -> np.ndarray:
    """Reverse the 32 bits of every uint32."""
    x = ((x >> _U32(1)) & _U32(0x55555555)) | ((x & _U32(0x55555555)) << _U32(1))
    x = ((x >> _U32(2)) & _U32(0x33333333)) | ((x & _U32(0x33333333)) << _U32(2))
    x = ((x >> _U32(4)) & _U32(0x0F0F0F0F)) | ((x & _U32(0x0F0F0F0F)) << _U32(4))
    x = ((x >> _U32(8)) & _U32(0x00FF00FF)) | ((x & _U32(0x00FF00FF)) << _U32(8))
    return (x >> _U32(16)) | (x << _U32(16))


def _laine_karras(x: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Burley's improved Laine–Karras permutation: each bit flips depending on lower bits only."""
    with np.errstate(over="ignore"):
        x = x + seed
        x = x ^ (x * _U32(0x6C50B47C))
        x = x ^ (x * _U32(0xB82F1E52))
        x = x ^ (x * _U32(0xC7AFE638))
        x = x ^ (x * _U32(0x8D22F6E6))
    return x


def owen_scramble(x: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Nested uniform (Owen) scrambling of 32-bit fixed-point values ``x`` with ``seed``."""
    return _reverse_bits(_laine_karras(_reverse_bits(x), seed))


def _sobol_2d(index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dimensions 0 and 1 of the Sobol sequence at ``index`` (uint32), as 32-bit fixed point.

    Dimension 0 is the van der Corput sequence (bit reversal); dimension 1 uses the generator
    matrix of the polynomial x + 1 (direction numbers v_k = v_{k-1} ^ (v_{k-1} >> 1)).
    """
    first = _reverse_bits(index)
    second = np.zeros_like(index)
    direction = _U32(1 << 31)
    for bit in range(32):
        set_bits = (index >> _U32(bit)) & _U32(1)
        second ^= set_bits * direction
        direction = _U32(direction ^ (direction >> _U32(1)))
    return first, second


def sample_2d(seed: int, keys: np.ndarray, samples: np.ndarray, dimension: int) -> np.ndarray:
    """Points in [0, 1)² for (texel ``keys``, ``samples``) pairs, broadcast together.

    keys: uint64 texel keys; samples: sample indices; dimension: which 2D pair of dimensions.
    Returns (..., 2) float64. A pure function of its arguments.
    """
    keys = np.asarray(keys, np.uint64)
    samples = np.asarray(samples).astype(_U32)
    shuffle = hash_u32(seed, keys, dimension, 0)
    index = owen_scramble(samples, shuffle)
    x, y = _sobol_2d(index)
    x = owen_scramble(x, hash_u32(seed, keys, dimension, 1))
    y = owen_scramble(y, hash_u32(seed, keys, dimension, 2))
    scale = 1.0 / 4294967296.0
    # Take the top 24 bits and centre them so that no coordinate is exactly 0 or 1.
    top = np.float64(256.0)
    return np.stack([((x >> _U32(8)) + 0.5) * scale * top, ((y >> _U32(8)) + 0.5) * scale * top], axis=-1)


def cosine_hemisphere(u: np.ndarray) -> np.ndarray:
    """Map points (..., 2) of [0, 1)² to unit directions (..., 3) around +z with pdf cosθ / π.

    Shirley–Chiu concentric disk mapping, then lifted to the hemisphere (Malley's method); the
    mapping keeps the points' stratification.
    """
    a = 2.0 * u[..., 0] - 1.0
    b = 2.0 * u[..., 1] - 1.0
    first = np.abs(a) > np.abs(b)
    safe_a = np.where(a == 0, 1.0, a)
    safe_b = np.where(b == 0, 1.0, b)
    r = np.where(first, a, b)
    phi = np.where(first, (np.pi / 4) * (b / safe_a), (np.pi / 2) - (np.pi / 4) * (a / safe_b))
    x, y = r * np.cos(phi), r * np.sin(phi)
    z = np.sqrt(np.clip(1.0 - x * x - y * y, 0.0, 1.0))
    return np.stack([x, y, z], axis=-1)


def tangent_frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (k, 3) each, orthogonal to unit ``normals`` (k, 3) and to each other.

    Duff et al., "Building an Orthonormal Basis, Revisited" (JCGT 2017): branch-free, no
    singularity.
    """
    nx, ny, nz = normals[:, 0], normals[:, 1], normals[:, 2]
    sign = np.where(nz >= 0, 1.0, -1.0)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    t1 = np.stack([1.0 + sign * nx * nx * a, sign * b, -sign * nx], axis=1)
    t2 = np.stack([b, sign + ny * ny * a, -ny], axis=1)
    return t1, t2
