# SPDX-License-Identifier: GPL-3.0-or-later
"""Row-wise operations on (n, 3) vector arrays.

``np.linalg.norm(v, axis=1)`` and ``(a * b).sum(axis=1)`` reduce over a tiny axis,
which numpy does slowly; ``einsum`` over rows is several times faster, and the hot
paths (exact solver, ray tracer) do these on millions of rows.
"""

from __future__ import annotations

import numpy as np


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (n, k) arrays, (n,)."""
    return np.einsum("ij,ij->i", a, b)


def lengths(v: np.ndarray) -> np.ndarray:
    """Row lengths of an (n, k) array, (n,)."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def normalized(v: np.ndarray) -> np.ndarray:
    """Rows scaled to unit length (zero rows stay zero)."""
    return v / np.maximum(lengths(v), 1e-300)[:, None]
