# SPDX-License-Identifier: GPL-3.0-or-later
"""The rim band: the cells along a seed footprint's edge, traced at every second pixel."""

import numpy as np

from curved_reflections.engine.methods.perturbation.rim import RIM_CELLS, RimBand


def _disc(radius=6, stride=8, origin=(10, 5)):
    rows, columns = np.mgrid[-radius:radius + 1, -radius:radius + 1]
    grid = np.where(rows ** 2 + columns ** 2 <= radius ** 2, 0, -1)
    grid[grid == 0] = np.arange((grid == 0).sum())
    return grid, origin, stride


def test_the_band_is_the_cells_within_rim_cells_of_the_edge_on_both_sides():
    grid, origin, stride = _disc()
    rim = RimBand.around(grid, origin, stride)
    rows, columns = np.nonzero(rim.band)
    centre = np.array([6, 6]) + RIM_CELLS + 1
    radius = np.hypot(rows - centre[0], columns - centre[1])
    assert radius.min() >= 6 - 2 * RIM_CELLS - 1 and radius.max() <= 6 + RIM_CELLS + 1.5
    assert not (rim.band & rim.interior).any()
    assert rim.interior[centre[0], centre[1]] and not rim.band[centre[0], centre[1]]
    assert rim.band.sum() + rim.interior.sum() > (grid >= 0).sum()  # the band reaches outside


def test_band_pixels_fill_its_cells_inside_the_view_and_touch_the_interior_at_its_inner_edge():
    grid, origin, stride = _disc()
    rim = RimBand.around(grid, origin, stride)
    pixels = rim.pixels(width=640, height=480)
    assert rim.step == 2 and len(pixels) == rim.band.sum() * (stride // rim.step) ** 2
    assert np.allclose(pixels % 1.0, 0.5)
    cell = np.floor(pixels / stride).astype(int) - np.array(rim.origin)
    assert rim.band[cell[:, 1], cell[:, 0]].all()
    touching = rim.touches_interior(pixels)
    assert 0 < touching.sum() < len(pixels) // 2
    # Touching pixels sit one pixel from an interior cell, the others farther.
    near = np.zeros(len(pixels), dtype=bool)
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            c = np.floor((pixels + (dx, dy)) / stride).astype(int) - np.array(rim.origin)
            near |= rim.interior[c[:, 1], c[:, 0]]
    assert (touching == near).all()
    clipped = rim.pixels(width=150, height=480)
    assert len(clipped) < len(pixels) and clipped[:, 0].max() < 150
