# SPDX-License-Identifier: GPL-3.0-or-later
"""Reflection morphing on a tetrahedral grid of panoramic sample-based cameras (SBC paper,
section VI): Morphing mode.

- :mod:`.morph_grid`: the grid in the reflector's rigid frame, its nodes' cameras;
- :mod:`.morphing`: a view between nodes, blended from the four nodes of its tetrahedron
  (and refined on a surface fitted to the images of its cube's eight);
- :mod:`.morph_surface`: the blend refined on the local surface the node images lie on.

The ray-octree grid (:mod:`..octree`) reuses the grid, the matching and the blend; both
are baked by :mod:`...baking`.
"""
