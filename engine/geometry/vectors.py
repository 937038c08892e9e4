# SPDX-License-Identifier: GPL-3.0-or-later
"""Row-wise operations on (n, 3) vector arrays.

``np.linalg.norm(v, axis=1)`` and ``(a * b).sum(axis=1)`` reduce over a tiny axis,
which numpy does slowly; ``einsum`` over rows is several times faster, and the hot
paths (exact solver, ray tracer) do these on millions of rows. Likewise ``np.cross``
on rows costs about six times a column-by-column product.
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


def unit(v: np.ndarray) -> np.ndarray:
    """Vectors along the last axis of an array of any shape scaled to unit length (zero
    vectors stay zero); :func:`normalized` for (n, k) rows."""
    return v / np.maximum(np.sqrt(np.einsum("...j,...j->...", v, v)), 1e-300)[..., None]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross products of (n, 3) arrays, (n, 3)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


def cross_rows(a, b) -> tuple:
    """Cross products of vectors held as three coordinate rows (a (3, n) array, or a
    sequence of three (n,) arrays): structure-of-arrays code keeps every coordinate
    contiguous. Returns the three rows of the result."""
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


def dot_rows(a, b) -> np.ndarray:
    """Dot products of vectors held as three coordinate rows (see :func:`cross_rows`)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
