"""Every sampler dimension baker draws random numbers from, in one table.

A random number is a pure function of (seed, key, sample, dimension) (docs/design.md §4). Two
estimators that use the same dimension with the same keys get the same numbers, so their errors
are correlated instead of independent: each estimator owns a range of dimensions here, and
``tests/test_dimensions.py`` lists every range in use (its ``ranges``: a new range goes there
too) and checks that no two of one stream overlap for any number of lights or bounces.

The numbers come from three streams, whose hashes never take the same words:

- ``sobol``: ``sampling.sample_2d`` / ``fill_points``, Owen-scrambled points whose scrambles are
  ``hash4(seed, key, dimension, j)`` with j = 0, 1, 2 (and jitters ``hash4(·, sample, ·, 3 or 4)``);
  a texel's second net, or an adaptive round's, from sample f takes the word
  ``sampling.net_word(dimension, f)`` = dimension + f·2³² in place of the dimension (f > 0:
  above every dimension of this table).
- ``uniform``: ``hash4(seed, key, sample, dimension)`` (``hemisphere._uniform``), one number per
  ray; its dimensions start above 4, so its last word never equals a ``sobol`` scramble's j.
- ``ray``: the alpha-blend coin, a hash of the ray's own float32 bits and its continuation step
  (``trace._coin``), keyed by no texel at all.

Keys are texel keys, a texel's other side (``inner.OTHER_SIDE``), the power-estimate points
(``power._POWER_KEY_BASE``), the sources whose power is traced from them
(``power._TRACED_KEY_BASE``) or the GI paths' vertices (``gi._bounce_keys``); a range says
which.
"""

from __future__ import annotations

# --- the sobol stream ---------------------------------------------------------------------------
OBSCURANCE = 0  # the hemisphere directions of obscurance rays (texel keys, other-side keys)
SUPERSAMPLE = 9  # sub-positions of a supersampled texel
POWER = (10, 11)  # where the power-estimate points fall on the surfaces (power keys)
SKY = 12  # cosine directions towards the sky
EMISSIVE = 13  # the emitter point of each emissive next-event sample
POWER_TRACED = (14, 15)  # rays from the sources for their power: where (an emitter's point),
# which way (traced-power keys, one per source)
_LIGHTS_LOW = 16  # light l < _LIGHTS_LOW_COUNT: 16 + 2l (the layout of bakes before the table)
_LIGHTS_LOW_COUNT = 12
GI_FIRST = 40  # the first bounce's direction of each path (texel keys)
GI_BOUNCE = 41  # later bounces' directions (vertex keys)
GI_ROULETTE = 42  # the Russian-roulette coin at each vertex (vertex keys)
GI_EMITTER = 43  # the next-event emitter point at each vertex (vertex keys)
_LIGHTS_HIGH = 64  # light l ≥ 12: 64 + 2(l − 12), above every other sobol range

# --- the uniform stream -------------------------------------------------------------------------
FOLIAGE_FIT = 5  # the rank of a crown's texels, which picks its fit texels (sample 0, texel keys)
MATERIAL = 60  # mirror/glass/translucent chains: 60 + 3·depth + (branch 0, Fresnel 1, roulette 2)
MATERIAL_STRIDE = 3

# --- the ray stream -----------------------------------------------------------------------------
ALPHA = 60  # the BLEND coin of continuation step s: 60 + 256·s
ALPHA_STRIDE = 256


def light_dimension(light: int) -> int:
    """The sobol dimension of light ``light``'s shadow samples (index in ``Scene.lights``).

    Lights 0–11 keep 16 + 2l, as bakes made before this table had them (their bytes are
    unchanged); later lights continue above the GI's range, where nothing else lies.
    """
    if light < _LIGHTS_LOW_COUNT:
        return _LIGHTS_LOW + 2 * light
    return _LIGHTS_HIGH + 2 * (light - _LIGHTS_LOW_COUNT)


def material_dimension(depth: int) -> int:
    """The first of the three uniform dimensions of a material chain's bounce ``depth``."""
    return MATERIAL + MATERIAL_STRIDE * depth


def alpha_dimension(step: int) -> int:
    """The ray-stream dimension of the alpha-blend coin at continuation ``step``."""
    return ALPHA + ALPHA_STRIDE * step
