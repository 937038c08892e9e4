# SPDX-License-Identifier: GPL-3.0-or-later
"""The rim band of a non-convex mirror: seeds at every second pixel along its silhouette.

Seen toward its silhouette, a bumpy mirror shows a point several times in a band a few
pixels wide: its bumps fold the reflected rays there (on the benchmark's bumpy sphere,
three images of one point within 6 x 40 pixels above the last row of 8-pixel seeds, and
fold pairs 0.3-2 px apart). The grid's seeds and its candidate scan are too coarse to
tell them apart (every miss of the benchmark lay in that band: coverage 96.4-97.9 %),
while seeds at every pixel there find them (every second pixel, RIM_STEP, since the
candidates whose series does not converge are solved on the mesh, ``mesh_polish.py``).
Tracing every pixel of the view costs ten times the projection; the band, the grid
cells within RIM_CELLS of the footprint's edge (and the cells just outside it, where the
silhouette's sliver lies), is a tenth of that, and every second pixel of it a quarter.
Chen & Arvo (2000) place such seeds adaptively (III-B.1, where the Hessian's bound says
so); at a fold no Taylor step from a seed converges far enough to place them. On a
bumpier sphere, folded all over, the band lifts coverage from 79-83 % to 91-93 %, where
seeds at every pixel of the view reach 95 % (docs/benchmarks/perturbation.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Grid cells from the footprint's edge the band reaches, inward and outward.
RIM_CELLS = 1
#: Pixels between the band's seeds, across and up. Every pixel finds images a step cannot
#: reach from a grid seed; with those polished on the mesh from their candidate seeds
#: (``mesh_polish``), every second pixel finds nearly as many at a quarter of the rays.
RIM_STEP = 2


@dataclass(frozen=True)
class RimBand:
    """The cells (of a seed grid with ``stride`` px cells, cell (0, 0) at ``origin``)
    within RIM_CELLS of the footprint's edge, and the grid's other seeded cells."""

    band: np.ndarray  # (rows, columns) bool, the grid grown by RIM_CELLS on each side
    interior: np.ndarray  # (rows, columns) bool: seeded cells off the band
    origin: tuple  # (column, row) of band[0, 0] in the view's seed grid
    stride: int

    @classmethod
    def around(cls, grid: np.ndarray, origin: tuple, stride: int) -> "RimBand":
        present = np.pad(grid >= 0, RIM_CELLS + 1, constant_values=False)
        edge = present & _grown(~present, 1)
        band = _grown(edge, RIM_CELLS)
        return cls(band, present & ~band, (origin[0] - RIM_CELLS - 1, origin[1] - RIM_CELLS - 1), int(stride))

    @property
    def step(self) -> int:
        """Pixels between the band's seeds: RIM_STEP, at most the grid's spacing."""
        return min(RIM_STEP, self.stride)

    def pixels(self, width: int, height: int) -> np.ndarray:
        """(K, 2) centres of every :attr:`step`-th pixel of the band, across and up, inside
        the view, row-major from the bottom row."""
        rows, columns = np.nonzero(self.band)
        offset = np.arange(0, self.stride, self.step) + 0.5
        x = (columns + self.origin[0])[:, None, None] * self.stride + offset[None, None, :]
        y = (rows + self.origin[1])[:, None, None] * self.stride + offset[None, :, None]
        x, y = np.broadcast_arrays(x, y)
        pixels = np.stack([x.reshape(-1), y.reshape(-1)], axis=1)
        inside = (pixels[:, 0] < width) & (pixels[:, 1] < height) & (pixels >= 0).all(axis=1)
        pixels = pixels[inside]
        return pixels[np.lexsort((pixels[:, 0], pixels[:, 1]))]

    def touches_interior(self, pixels: np.ndarray) -> np.ndarray:
        """(K,) bool: a pixel next to one of ``pixels`` (8 neighbours, 1 px away) lies in a
        seeded cell off the band (the grid answers the images there)."""
        touching = np.zeros(len(pixels), dtype=bool)
        rows, columns = self.interior.shape
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                cell = np.floor((pixels + (dx, dy)) / self.stride).astype(np.int64) - np.array(self.origin)
                inside = (cell[:, 0] >= 0) & (cell[:, 0] < columns) & (cell[:, 1] >= 0) & (cell[:, 1] < rows)
                touching[inside] |= self.interior[cell[inside, 1], cell[inside, 0]]
        return touching


def _grown(mask: np.ndarray, cells: int) -> np.ndarray:
    """``mask`` dilated by ``cells`` (8-connected, square), same shape."""
    grown = mask.copy()
    for _ in range(cells):
        padded = np.pad(grown, 1, constant_values=False)
        rows, columns = grown.shape
        grown = np.any([padded[1 + di:1 + di + rows, 1 + dj:1 + dj + columns]
                        for di in (-1, 0, 1) for dj in (-1, 0, 1)], axis=0)
    return grown
