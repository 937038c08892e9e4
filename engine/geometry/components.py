# SPDX-License-Identifier: GPL-3.0-or-later
"""Connected components of a graph given as groups of nodes, on whole arrays."""

from __future__ import annotations

import numpy as np


def component_roots(groups: np.ndarray, n_nodes: int) -> np.ndarray:
    """(n_nodes,) the lowest node of each node's component, the nodes of a row of
    ``groups`` (M, k) being joined (a triangle's corners, an edge's ends).

    Hooking roots to the lowest and pointer jumping (Shiloach and Vishkin): every
    group's roots hook to its lowest root, then each node jumps to its new root, so
    whole trees merge in a pass and the passes grow with the logarithm of a
    component's size (moving each node's own label takes a pass per ring: tens of
    seconds on a million-triangle mirror)."""
    # Labels are node indices: 32 bits hold them (a million triangles' (T, 3) copies
    # each pass: 12 MB, not 24).
    index = np.int32 if n_nodes < 2 ** 31 else np.int64
    groups = np.asarray(groups).astype(index, copy=False)
    label = np.arange(n_nodes, dtype=index)
    if groups.size == 0:
        return label
    width = groups.shape[1]
    while True:
        roots = label[groups]
        merged = label.copy()
        np.minimum.at(merged, roots.reshape(-1), np.repeat(roots.min(axis=1), width))
        while True:
            jumped = merged[merged]
            if np.array_equal(jumped, merged):
                break
            merged = jumped
        if np.array_equal(merged, label):
            return label
        label = merged


def numbered_in_order(keys: np.ndarray) -> np.ndarray:
    """(K,) the keys renumbered 0, 1, ... in the order each first appears."""
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    renumber = np.empty(len(first), dtype=np.int64)
    renumber[np.argsort(first, kind="stable")] = np.arange(len(first))
    return renumber[inverse.reshape(-1)]
