"""The obscurance functions ρ(d): how much a hit at distance d lets ambient light through.

Each takes x = d / d_max (array, 0 ≤ x < 1 for hits) and returns ρ in [0, 1]; a ray with no hit
closer than d_max counts ρ = 1 with R(Q) = R_ave. "step" is classic ambient occlusion: every hit
blocks all light, and (see ``unit_reflectivity``) surfaces count as white.
"""

from __future__ import annotations

import numpy as np

RHO = {
    "sqrt": np.sqrt,  # the paper's default, sqrt(d / d_max)
    "linear": lambda x: np.asarray(x, np.float64),
    "step": np.zeros_like,
}

# ρ functions for which the model is classic ambient occlusion: R(Q) = 1, R_ave = 1.
UNIT_REFLECTIVITY = {"step"}
