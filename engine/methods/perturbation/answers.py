# SPDX-License-Identifier: GPL-3.0-or-later
"""One point's answers of one reflection history: which are one image, and their ranks.

The grid's steps, the rim band's and Newton's method on the mesh (``mesh_polish.py``)
can each answer one image of a point; answers closer than SAME_IMAGE_PX are that one
image, and the images left are numbered (ranked) per point for the projection's slots.
"""

from __future__ import annotations

import numpy as np

from .candidates import MAX_IMAGES

#: Two answers of one point and history closer than this (px) are one image.
SAME_IMAGE_PX = 1.0


def repeats(point_of, pixel, priority=None) -> np.ndarray:
    """(K,) bool: the answers (point ``point_of`` (K,) at ``pixel`` (K, 2)) that another
    answer of their point, closer than SAME_IMAGE_PX, precedes: lower in ``priority``
    (K,), by default farther left in the view. Pairs are looked for among the
    MAX_IMAGES answers of the point nearest in x."""
    order = np.lexsort((pixel[:, 1], pixel[:, 0], point_of))
    p, x = point_of[order], pixel[order]
    rank = np.arange(len(order)) if priority is None else np.asarray(priority)[order]
    repeat = np.zeros(len(order), dtype=bool)
    for lag in range(1, MAX_IMAGES):
        same = (p[lag:] == p[:-lag]) & (np.linalg.norm(x[lag:] - x[:-lag], axis=1) < SAME_IMAGE_PX)
        later = rank[lag:] > rank[:-lag]
        repeat[lag:] |= same & later
        repeat[:-lag] |= same & ~later
    found = np.empty(len(order), dtype=bool)
    found[order] = repeat
    return found


def ranked(n_points, point_of, first, last, pixel):
    """Answers per image rank: ([first (P, 3)] * ranks, [last (P, 3)] * ranks), one image
    per group of answers closer than SAME_IMAGE_PX (:func:`repeats`), a point's images
    ranked from left to right in the view."""
    keep = ~repeats(point_of, pixel)
    order = np.flatnonzero(keep)[np.lexsort((pixel[keep, 1], pixel[keep, 0], point_of[keep]))]
    point_of, first, last = point_of[order], first[order], last[order]
    rank = np.arange(len(point_of)) - np.searchsorted(point_of, point_of)
    firsts, lasts = [], []
    for r in range(int(rank.max()) + 1 if len(rank) else 0):
        f, l = np.full((n_points, 3), np.nan), np.full((n_points, 3), np.nan)
        on = rank == r
        f[point_of[on]], l[point_of[on]] = first[on], last[on]
        firsts.append(f)
        lasts.append(l)
    return firsts, lasts
