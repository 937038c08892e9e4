# SPDX-License-Identifier: GPL-3.0-or-later
"""Reductions over segments: per-node sums and maxima of per-member values.

The BSP builder processes every node of a tree level at once: members (node, ray) are
rows, and a node's statistics are reductions over the rows that carry its index.
``np.add.reduceat`` on rows sorted by node does this in one pass, with no per-node loop.
The other way round, ``expand_ranges`` lists the members of CSR ranges as rows.
"""

from __future__ import annotations

import numpy as np

from .spd_solve import solve_spd


def expand_ranges(start: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every index of the ranges start[k] .. start[k] + count[k] - 1, in order: (owner k,
    index) per entry. With start 0 this is each entry's place in its range."""
    count = np.asarray(count, dtype=np.int64)
    owner = np.repeat(np.arange(len(count)), count)
    return owner, np.repeat(np.asarray(start, dtype=np.int64) - np.cumsum(count) + count, count) + np.arange(count.sum())


def ranks_in_runs(sorted_keys: np.ndarray) -> np.ndarray:
    """(n,) each entry's place in its run of equal ``sorted_keys`` (0 for the run's first):
    with pairs sorted by owner and then by preference, the entries of rank below k are
    each owner's k best."""
    keys = np.asarray(sorted_keys)
    if len(keys) == 0:
        return np.zeros(0, dtype=np.int64)
    start = np.flatnonzero(np.concatenate([[True], keys[1:] != keys[:-1]]))
    return np.arange(len(keys)) - np.repeat(start, np.diff(np.append(start, len(keys))))


def range_offsets(owner: np.ndarray, n: int) -> np.ndarray:
    """(n + 1,) offsets of each owner's range once entries are sorted by ``owner`` (CSR)."""
    return np.concatenate([[0], np.cumsum(np.bincount(owner, minlength=n))])


def _sorted_starts(node: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    order = np.argsort(node, kind="stable")
    counts = np.bincount(node, minlength=n_nodes)
    if np.any(counts == 0):
        raise ValueError("every node needs at least one member")
    return order, np.concatenate([[0], np.cumsum(counts)[:-1]])


def segment_sum(values: np.ndarray, node: np.ndarray, n_nodes: int) -> np.ndarray:
    """Sum of ``values`` (m, ...) over rows sharing a node index; (n_nodes, ...)."""
    order, starts = _sorted_starts(node, n_nodes)
    return np.add.reduceat(values[order], starts, axis=0)


def segment_max(values: np.ndarray, node: np.ndarray, n_nodes: int) -> np.ndarray:
    """Maximum of ``values`` (m, ...) over rows sharing a node index; (n_nodes, ...)."""
    order, starts = _sorted_starts(node, n_nodes)
    return np.maximum.reduceat(values[order], starts, axis=0)


def segment_min(values: np.ndarray, node: np.ndarray, n_nodes: int) -> np.ndarray:
    """Minimum of ``values`` (m, ...) over rows sharing a node index; (n_nodes, ...)."""
    order, starts = _sorted_starts(node, n_nodes)
    return np.minimum.reduceat(values[order], starts, axis=0)


def segment_mean(values: np.ndarray, node: np.ndarray, n_nodes: int) -> np.ndarray:
    counts = np.bincount(node, minlength=n_nodes).astype(np.float64)
    return segment_sum(values, node, n_nodes) / counts.reshape((-1,) + (1,) * (values.ndim - 1))


def solve_least_squares(design: np.ndarray, targets: np.ndarray, node: np.ndarray, n_nodes: int,
                        ridge: float = 1e-10) -> np.ndarray:
    """Per-node least squares: coefficients (n_nodes, k, t) of design (m, k) -> targets (m, t).

    Normal equations with a small ridge relative to each node's trace, so nodes with
    fewer members than coefficients still get a (minimum-norm-like) answer. Solved by
    batched Cholesky (spd_solve), not LAPACK per node.
    """
    normal = segment_sum(design[:, :, None] * design[:, None, :], node, n_nodes)
    rhs = segment_sum(design[:, :, None] * targets[:, None, :], node, n_nodes)
    k = design.shape[1]
    trace = np.trace(normal, axis1=1, axis2=2)
    normal = normal + (ridge * np.maximum(trace, 1e-300) / k)[:, None, None] * np.eye(k)
    return solve_spd(normal, rhs)
