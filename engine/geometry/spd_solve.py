# SPDX-License-Identifier: GPL-3.0-or-later
"""Many small symmetric positive definite systems, solved together by Cholesky.

The engine fits thousands of tiny least-squares problems at once (a 6x6 system per BSP
node, per morphed point): normal equations, symmetric and positive definite once a
ridge is added. ``np.linalg.solve`` hands each matrix to LAPACK in turn, and OpenBLAS
may split each of those calls over threads: on two cores already busy (two bake
workers, or Blender drawing), the threads wait on each other and a batch of 1,000 6x6
systems took 40 ms instead of 2 ms. Here the factorisation runs column by column with
numpy's vector operations over the whole batch: k^2 / 2 array operations for k
unknowns, whatever the batch size, and no thread pool involved.
"""

from __future__ import annotations

import numpy as np

#: Smallest pivot, relative to the matrix's largest diagonal entry: a matrix that is
#: singular to rounding gets a finite (minimum-norm-like) answer, never NaN.
PIVOT_FLOOR = 1e-14


def cholesky_factor(matrices: np.ndarray) -> np.ndarray:
    """Lower triangular L (n, k, k) with L L^T = matrices (n, k, k), each symmetric
    positive (semi-)definite; pivots are kept at least ``PIVOT_FLOOR`` of the largest
    diagonal entry."""
    matrices = np.asarray(matrices, dtype=np.float64)
    k = matrices.shape[-1]
    floor = PIVOT_FLOOR * np.maximum(np.abs(np.diagonal(matrices, axis1=1, axis2=2)).max(axis=1), 1e-300)
    lower = np.zeros_like(matrices)
    for j in range(k):
        row = lower[:, j, :j]
        pivot = np.sqrt(np.maximum(matrices[:, j, j] - np.einsum("ni,ni->n", row, row), floor))
        lower[:, j, j] = pivot
        if j + 1 < k:
            below = matrices[:, j + 1:, j] - np.einsum("nri,ni->nr", lower[:, j + 1:, :j], row)
            lower[:, j + 1:, j] = below / pivot[:, None]
    return lower


def solve_spd(matrices: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """x with matrices @ x = rhs for every system: matrices (n, k, k) symmetric positive
    definite, rhs (n, k) or (n, k, t); x has rhs's shape."""
    lower = cholesky_factor(matrices)
    rhs = np.asarray(rhs, dtype=np.float64)
    vector = rhs.ndim == 2
    b = rhs[:, :, None] if vector else rhs
    k = lower.shape[-1]
    y = np.empty_like(b)
    for j in range(k):  # forward: L y = b
        y[:, j] = (b[:, j] - np.einsum("ni,nit->nt", lower[:, j, :j], y[:, :j])) / lower[:, j, j, None]
    x = np.empty_like(b)
    for j in reversed(range(k)):  # back: L^T x = y
        x[:, j] = (y[:, j] - np.einsum("ni,nit->nt", lower[:, j + 1:, j], x[:, j + 1:])) / lower[:, j, j, None]
    return x[:, :, 0] if vector else x
