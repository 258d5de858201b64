"""Directional lightmaps: what a texel's light does to a normal the normal map tilts.

A plain lightmap holds a texel's irradiance E(n₀) about its (interpolated vertex) normal n₀; a
normal map tilts the normal to n, where the light is E(n) = ∫ L(ω) max(0, n·ω) dω, which a
plain lightmap cannot tell from E(n₀): the face looks flat. With ``--directional`` every
estimator also keeps, per texel, the first moment of what it estimates,

    U = ∫ lum L(ω) · ω · cosθ dω        (world space; |U| ≤ lum E(n₀))

as the mean of each sample's luminance times its world direction (the obscurance's rays, each
light's shadow rays, the emitters', the sky's, GI's first directions), kept per source like
the irradiance, so that a relight recomposes it too. L1 spherical harmonics of the incoming
radiance would need ∫ L ω dω, whose estimate from cosine-distributed rays has unbounded
variance (1/cosθ at grazing rays); U has none beyond the irradiance's own.

**The decoding** (``fit``) fits E(n) = E(n₀)·(1 + (n − n₀)·g), linear in n as L1 irradiance
is. With u = U / lum E, u_n its part along n₀ and u_t its part across:

    g = u_t / u_n + (1 + f)/2 · n₀

where f is the share of the light that comes from one direction, were the light one direction
l plus a uniform hemisphere (then u = f·l + (2/3)(1 − f)·n₀, a quadratic in f:
f = (6a + 3·sqrt(9a² + 5|u_t|²))/5, a = u_n − 2/3). A point light or a sun (f = 1, u = l)
gives E(n) = E(n₀)·(n·l)/(n₀·l), its closed form; a uniform sky (f = 0, u_t = 0)
E(n₀)·(1 + n·n₀)/2, its closed form too; a window and the ambient light between. For such a
mix the exact part across n₀ would be f·u_t / (u_n − (2/3)(1 − f)), which under a nearly
uniform sky divides the rays' noise by almost nothing (g's spread was 1.6 for u's 0.003 on an
open floor at 64 rays); u_t / u_n is well conditioned and within 10 % of it for half the light
from 45° (0.51 for 0.5). It is capped at ``MOST_TILT`` (a light 76° off the normal). Light
whose direction no estimator follows (through translucent leaves, the foliage's closed form)
counts as uniform.

**The page** holds h = g / (1 + |g|) as 0.5 + 0.5·h in each 8-bit channel, linear
(``encode_vectors``, ``decode_vectors``): |h| < 1 whatever g, finer where g is small. A viewer
decodes irradiance × max(0, 1 + (n − n₀)·g), with n and n₀ world-space unit normals, the
normal-mapped one and the interpolated vertex one (``shading_factor``; the three.js plugin
``view_static/moz_lightmap.js`` and ``baker preview`` compute the same).
"""

from __future__ import annotations

import math

import numpy as np

from baker.jit import jit

MOST_TILT = 4.0
"""The largest part of g across n₀ (tan of a light's angle from the normal: 76°)."""
UNIFORM = 2.0 / 3.0
"""U / lum E of light uniform over the hemisphere about n₀, along n₀."""


def uniform_aim(luminance: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(k, 3) U of light of luminance ``luminance`` (k,) whose direction is not followed,
    counted as uniform over the hemisphere about unit ``normals`` (k, 3)."""
    return UNIFORM * luminance[:, None] * normals


def fit(luminance: np.ndarray, aim: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(k, 3) g of texels of irradiance luminance ``luminance`` (k,), first moment ``aim``
    (k, 3) (U, world) and unit normals ``normals`` (k, 3) (see the module's docstring); n₀/2
    where the luminance is 0 (no light: the factor multiplies nothing)."""
    out = np.empty((len(luminance), 3))
    _fit_kernel(np.ascontiguousarray(luminance, np.float64),
                np.ascontiguousarray(aim, np.float64),
                np.ascontiguousarray(normals, np.float64), MOST_TILT, out)
    return out


@jit
def _fit_kernel(luminance, aim, normals, most, out):
    for i in range(len(luminance)):
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        if not luminance[i] > 0.0:
            out[i, 0], out[i, 1], out[i, 2] = 0.5 * nx, 0.5 * ny, 0.5 * nz
            continue
        ux, uy, uz = aim[i, 0] / luminance[i], aim[i, 1] / luminance[i], aim[i, 2] / luminance[i]
        along = ux * nx + uy * ny + uz * nz
        tx, ty, tz = ux - along * nx, uy - along * ny, uz - along * nz
        across = math.sqrt(tx * tx + ty * ty + tz * tz)
        a = along - UNIFORM
        share = (6.0 * a + 3.0 * math.sqrt(9.0 * a * a + 5.0 * across * across)) / 5.0
        share = min(max(share, 0.0), 1.0)
        scale = 1.0 / max(along, across / most, 1e-300) if across > 0.0 else 0.0
        along_g = 0.5 * (1.0 + share)
        out[i, 0] = scale * tx + along_g * nx
        out[i, 1] = scale * ty + along_g * ny
        out[i, 2] = scale * tz + along_g * nz


def smoothed(g: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """(P, H, W, 3) the pages of g (P, H, W, 3) averaged over each texel's 3×3 neighbours,
    weighted by ``weight`` (P, H, W) (the texels' irradiance luminance, 0 outside the charts):
    the linear models E(n₀)·(1 + (n − n₀)·g) of the neighbourhood pooled. A texel's own rays
    leave its g noisy (the ambient light's 16 rays a texel: ±2 of 255 in the page), where the
    light's direction varies slowly; the pooled g is 3× less noisy and the page's PNG 2–3×
    smaller. Charts lie at least 2 texels apart (the padding), so no texel reaches another
    chart; a texel with no lit neighbour keeps its own g."""
    padded_g = np.pad(g * weight[..., None], ((0, 0), (1, 1), (1, 1), (0, 0)))
    padded_w = np.pad(weight, ((0, 0), (1, 1), (1, 1)))
    height, width = weight.shape[1:]
    total, sums = np.zeros_like(weight), np.zeros_like(g)
    for dy in range(3):
        for dx in range(3):
            total += padded_w[:, dy:dy + height, dx:dx + width]
            sums += padded_g[:, dy:dy + height, dx:dx + width]
    return np.where(total[..., None] > 0, sums / np.where(total > 0, total, 1.0)[..., None], g)


def encode_vectors(g: np.ndarray) -> np.ndarray:
    """h = g / (1 + |g|) (…, 3), inside the unit ball: what the directional page holds."""
    return g / (1.0 + np.linalg.norm(g, axis=-1, keepdims=True))


def decode_vectors(h: np.ndarray) -> np.ndarray:
    """g (…, 3) from h (…, 3) (``encode_vectors``'s inverse; |h| is kept below 1)."""
    length = np.minimum(np.linalg.norm(h, axis=-1, keepdims=True), 1.0 - 1e-6)
    return h / (1.0 - length)


def page_texels(h: np.ndarray) -> np.ndarray:
    """(…, 3) uint8 texels of a directional page: round(255 · (0.5 + 0.5·h))."""
    return np.round(255.0 * np.clip(0.5 + 0.5 * h, 0.0, 1.0)).astype(np.uint8)


def texel_vectors(texels: np.ndarray) -> np.ndarray:
    """h (…, 3) float64 from a directional page's texels (…, 3) uint8 (or bilinearly
    filtered values on the same 0–255 scale)."""
    return np.asarray(texels, np.float64) / 255.0 * 2.0 - 1.0


def shading_factor(normals: np.ndarray, base: np.ndarray, g: np.ndarray) -> np.ndarray:
    """(k,) the factor on the irradiance at unit normals ``normals`` (k, 3) of texels baked
    about unit ``base`` normals (k, 3): max(0, 1 + (n − n₀)·g)."""
    return np.maximum(0.0, 1.0 + np.einsum("kc,kc->k", normals - base, g))
