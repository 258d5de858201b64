"""Sums of products over each row's entries, in one fixed order: for per-texel and per-ray arrays.

numpy's ``@`` hands its work to BLAS, whose sum for a row can differ in the last bit with the
row's place in the array and the array's length (its kernels take rows in unrolled blocks, and
the rows left over another way): of 7,000 rows of 7 numbers times a 7 × 3 matrix, 12 came out
other bits when multiplied within shorter slices of the same array. A rebake computes its dirty
texels in other arrays than the full bake, so a term made with ``@`` could differ by an ulp
between the two and round to another 8-bit step on a page (issue 39: a room of 60 boxes, a box
moved, 21 texels one step off). Here every row gets the same bits wherever it is: elementwise
products added in order of the summed index (numpy's elementwise operations are IEEE's, one
rounding each, no fused multiply-add).
"""

from __future__ import annotations

import numpy as np


def dot_rows(x: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(...,) Σ_j x[..., j] · weights[j], added in order of j: x (..., n), weights (n,)."""
    weights = np.asarray(weights, np.float64)
    if not len(weights):
        return np.zeros(np.shape(x)[:-1])
    out = x[..., 0] * weights[0]
    for j in range(1, len(weights)):
        out = out + x[..., j] * weights[j]
    return out


def matmul_rows(x: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """(..., c) Σ_j x[..., j] · matrix[j], added in order of j: x (..., n), matrix (n, c); what
    ``x @ matrix`` gives in exact arithmetic, with a row's bits independent of the array."""
    matrix = np.asarray(matrix, np.float64)
    if not matrix.shape[0]:
        return np.zeros((*np.shape(x)[:-1], matrix.shape[1]))
    out = x[..., 0, None] * matrix[0]
    for j in range(1, matrix.shape[0]):
        out = out + x[..., j, None] * matrix[j]
    return out
