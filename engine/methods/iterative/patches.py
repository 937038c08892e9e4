# SPDX-License-Identifier: GPL-3.0-or-later
"""Where a search on a map starts: patches of its surface with their cones of normals.

A map whose search cannot start from one guess (a piece of a mirror that is not
star-shaped, :mod:`.pieces`; a folded star-shaped mirror, :mod:`.fold_patches`) starts
from every patch that may hold a point's reflection (``search.patch_admits``). A patch
is a group of the map's texels: the mean direction of its texels (where Newton starts),
the cone of its normals and its bounding sphere (``ReflectorMap.patches``).
"""

from __future__ import annotations

import numpy as np

from ...geometry.vectors import dot, lengths, normalized
from .reflector_map import ReflectorMap, texel_directions


def texel_grid(face_size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(face, row, column) of every atlas texel, flat, rows and columns within the face
    (0 .. S + 1, the border included)."""
    side = int(face_size) + 2
    row, column = np.divmod(np.arange(6 * side * side), side)
    face, row = np.divmod(row, side)
    return face, row, column


def face_cells(face_size: int, cells: int) -> np.ndarray:
    """(6 (S + 2)^2,) the cell of every atlas texel on a ``cells`` x ``cells`` grid of its face."""
    side = int(face_size) + 2
    face, row, column = texel_grid(face_size)
    return (face * cells + row * cells // side) * cells + column * cells // side


def grouped_patches(rmap: ReflectorMap, texels: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """(K, 3, 4) float32 patches (``ReflectorMap.patches``) of the atlas ``texels`` (flat
    indices, each with a radius) grouped by ``groups`` (one key per texel), in the order
    of the keys: (normal-cone axis, half-angle), (bounding sphere's centre relative to O,
    radius), (start direction, 0)."""
    directions = texel_directions(rmap.face_size).reshape(-1, 3)[texels]
    values = rmap.texels.reshape(-1, 4)[texels].astype(np.float64)
    normal, position = normalized(values[:, 1:]), values[:, :1] * directions
    used, cell = np.unique(groups, return_inverse=True)
    cell = cell.reshape(-1)
    count = np.bincount(cell, minlength=len(used)).astype(np.float64)

    def mean(rows):
        return np.stack([np.bincount(cell, rows[:, k], len(used)) for k in range(3)], axis=1) / count[:, None]

    start, axis, centre = normalized(mean(directions)), normalized(mean(normal)), mean(position)
    half_angle = np.zeros(len(used))
    np.maximum.at(half_angle, cell, np.arccos(np.clip(dot(normal, axis[cell]), -1.0, 1.0)))
    radius = np.zeros(len(used))
    np.maximum.at(radius, cell, lengths(position - centre[cell]))
    patches = np.zeros((len(used), 3, 4), np.float32)
    patches[:, 0, :3], patches[:, 0, 3] = axis, half_angle
    patches[:, 1, :3], patches[:, 1, 3] = centre, radius
    patches[:, 2, :3] = start
    return patches
