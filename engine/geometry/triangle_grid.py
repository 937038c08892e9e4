# SPDX-License-Identifier: GPL-3.0-or-later
"""Walking a mirror's surface without a BVH: a triangle near any point close to the
surface, by table lookup, and each triangle's neighbours across its edges.

A search for a reflection point that starts near its answer (a node image polished on
the GPU, ``drawing/methods/polish_gpu.py``) needs only a triangle to start from and
a way to walk to the triangle under a point: a uniform grid of cells, each holding a
triangle through or near it, and the edge adjacency. Both are flat integer tables a
shader reads. Built in blocks of triangles, so that a million-triangle mirror's
temporaries stay small (the grid itself is at most ``MAX_CELLS`` cells a side).
"""

from __future__ import annotations

import numpy as np

#: Cells per side of the grid's longest axis, at most: 128**3 int32 cells are 8 MB.
MAX_CELLS = 128
#: A cell is this many times the mirror's median edge long, at least.
CELL_PER_EDGE = 1.0
#: Samples per triangle edge (a barycentric lattice) when registering a triangle in the
#: cells it crosses.
EDGE_SAMPLES = 3
#: Dilation passes, at most (each over every cell): with cells of at least 1/128 of the
#: mirror, 8 cells reach 6 % of its size along the axes, 3.6 % diagonally.
MAX_DILATION = 8
#: Triangles registered at a time.
BLOCK = 1 << 16
#: Triangles whose edges give the median edge length, at most (evenly strided).
EDGE_SAMPLE_TRIANGLES = 100_000


class TriangleGrid:
    """Cells of a box around a mirror's triangles, each holding the index of a triangle
    through or near it, -1 where none lies within ``reach``."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, reach: float):
        """``reach``: how far off the surface (in the mirror's units) a point still finds
        a triangle: the grid is dilated by that many cells (``MAX_DILATION`` at most)."""
        vertices = np.asarray(vertices, dtype=np.float64)
        triangles = np.asarray(triangles, dtype=np.int64)
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        sampled = vertices[triangles[::max(1, len(triangles) // EDGE_SAMPLE_TRIANGLES)]]
        edges = np.linalg.norm(sampled - np.roll(sampled, 1, axis=1), axis=2)
        size = float(np.max(hi - lo))
        self.cell = max(CELL_PER_EDGE * float(np.median(edges)), size / MAX_CELLS, 1e-12)
        # Each pass grows the grid by one cell along the axes, by 1/sqrt(3) cell diagonally.
        dilation = min(int(np.ceil(np.sqrt(3.0) * reach / self.cell)), MAX_DILATION)
        self.origin = lo - (dilation + 0.5) * self.cell
        self.shape = (np.floor((hi - self.origin) / self.cell).astype(np.int64) + dilation + 1)
        cells = np.full(int(np.prod(self.shape)), -1, dtype=np.int32)
        weights = _lattice(EDGE_SAMPLES)
        for start in range(0, len(triangles), BLOCK):
            corners = vertices[triangles[start:start + BLOCK]]
            samples = np.einsum("sk,tkd->tsd", weights, corners).reshape(-1, 3)
            cells[self._flat_index(samples)] = np.repeat(np.arange(start, start + len(corners), dtype=np.int32),
                                                        len(weights))
        self.cells = cells.reshape(tuple(self.shape))
        for _ in range(dilation):
            self._dilate()

    def nearby(self, points: np.ndarray) -> np.ndarray:
        """(P,) a triangle through or near the cell of each point, -1 where none (off the
        grid, or farther than ``reach`` from the surface)."""
        index = self._cell_of(points)
        with np.errstate(invalid="ignore"):
            inside = np.all((index >= 0) & (index < self.shape), axis=1)
        found = np.full(len(index), -1, dtype=np.int64)
        cells = index[inside].astype(np.int64)
        found[inside] = self.cells[cells[:, 0], cells[:, 1], cells[:, 2]]
        return found

    def _cell_of(self, points: np.ndarray) -> np.ndarray:
        """(P, 3) float: the integer cell coordinates of each point (NaN stays NaN)."""
        return np.floor((np.asarray(points, dtype=np.float64) - self.origin) / self.cell)

    def _flat_index(self, points: np.ndarray) -> np.ndarray:
        index = np.clip(self._cell_of(points).astype(np.int64), 0, self.shape - 1)
        return np.ravel_multi_index(index.T, tuple(self.shape))

    def _dilate(self) -> None:
        """Every empty cell takes the triangle of a face neighbour that has one."""
        grown = self.cells.copy()
        for axis in range(3):
            for shift in (1, -1):
                source = np.roll(self.cells, shift, axis=axis)
                wrapped = [slice(None)] * 3
                wrapped[axis] = 0 if shift == 1 else -1
                source[tuple(wrapped)] = -1
                np.copyto(grown, source, where=grown < 0)
        self.cells = grown


def edge_neighbours(welded_triangles: np.ndarray) -> np.ndarray:
    """(T, 3) the triangle across the edge opposite each corner (between corners k + 1
    and k + 2, of welded vertices), -1 on an open edge or one shared by more than two
    triangles (no unique way on)."""
    welded = np.asarray(welded_triangles, dtype=np.int64)
    a, b = np.roll(welded, -1, axis=1), np.roll(welded, -2, axis=1)
    keys = (np.minimum(a, b) * (int(welded.max()) + 1) + np.maximum(a, b)).reshape(-1)
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    starts = np.flatnonzero(np.r_[True, sorted_keys[1:] != sorted_keys[:-1]])
    counts = np.diff(np.r_[starts, len(keys)])
    pairs = starts[counts == 2]
    first, second = order[pairs], order[pairs + 1]
    neighbours = np.full(len(keys), -1, dtype=np.int64)
    neighbours[first], neighbours[second] = second // 3, first // 3
    return neighbours.reshape(-1, 3)


def _lattice(n: int) -> np.ndarray:
    """(S, 3) barycentric weights of a triangle's lattice with ``n`` steps per edge."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    i, j = i[keep], j[keep]
    return np.column_stack([n - i - j, i, j]).astype(np.float64) / n
