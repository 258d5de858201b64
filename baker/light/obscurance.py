"""The obscurance functions ρ(d): how much a hit at distance d lets ambient light through.

Each takes x = d / d_max (0 ≤ x < 1 for hits) and returns ρ in [0, 1]; a ray with no hit closer
than d_max counts ρ = 1 with R(Q) = R_ave. "step" is classic ambient occlusion: every hit blocks
all light, and (see ``UNIT_REFLECTIVITY``) surfaces count as white.

``rho`` is compiled (numba) so that the integrator's per-ray kernel calls it; ``RHO_KINDS`` maps
the setting's name to the ``kind`` number it takes.
"""

from __future__ import annotations

import numpy as np

from baker.jit import jit

RHO_KINDS = {"sqrt": 0, "linear": 1, "step": 2}

# ρ functions for which the model is classic ambient occlusion: R(Q) = 1, R_ave = 1.
UNIT_REFLECTIVITY = {"step"}


@jit
def rho(kind, x):
    """ρ at x = d / d_max (clamped to [0, 1]): sqrt(x) the paper's default, x, or 0 (step)."""
    x = min(max(x, 0.0), 1.0)
    if kind == 0:
        return np.sqrt(x)
    if kind == 1:
        return x
    return 0.0
