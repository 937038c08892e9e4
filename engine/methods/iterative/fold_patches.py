# SPDX-License-Identifier: GPL-3.0-or-later
"""Every image of a point in a folded star-shaped mirror: the search's starts.

A star-shaped mirror that is not convex shows a point several times where its surface
folds the reflected rays (a bump's flank, a dent, the saddle between two bumps): the
bumpy benchmark mirrors show some points three to nine times. Roger & Holzschuch's
search finds one image per vertex (2006, section 3.3.5 starts from one guess); the
sample-based camera paper splits such a reflector into pieces whose rays do not cross,
one reflection group each (Popescu et al. 2006, section VII, Fig. 20a). Here the pieces
are where the search starts, and every distinct root is kept (``search.py``,
``ReflectorMap.images``):

- For far points, a point's images are where the surface normal bisects the directions
  to the eye and to the point: the preimages of one direction under the Gauss map.
  That map folds along the surface's parabolic curves (Gaussian curvature K = 0), and
  is one-to-one near any point where K is not zero. So the surface is split by the
  sign of K and of the mean curvature (convex, concave, saddle; measured on the map's
  radii and normals) into connected regions, each cut by a grid on the cube faces
  (:data:`CELLS`) so that a region's normals span a narrow cone; the texels near a
  parabolic curve (|K| small) form patches of their own by cell.
- A patch holds at most one image of a far point, near enough; Newton starts from
  every patch whose cone may hold the point's reflection (``search.patch_admits``) and
  runs on the whole map, so an image near a patch's border is found from either side.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...geometry.components import component_roots
from .patches import face_cells, grouped_patches, texel_grid
from .reflector_map import ReflectorMap, face_coordinates, texel_directions

#: |K| r^2 below this (r the map's mean radius) is near a parabolic curve: between the
#: classes, where the finite differences of the interpolated normals are noise.
CURVED = 0.1
#: A region's texels are grouped by a grid of this many cells along each cube face's
#: side: a region that winds round several bumps (the saddles between them) holds a
#: point's image once per bump, each cell of it about once.
CELLS = 4
#: Patches are made of the texels on a grid this many apart.
STRIDE = 2
#: Images of one point a search keeps at most (answer slots per vertex); the bumpy
#: family's mirrors show a point up to nine times, all but a few points at most seven.
MAX_IMAGES = 8
#: A map is folded where this share of its texels or more lies in concave or saddle
#: regions: below it, a few texels of noise.
FOLDED_SHARE = 1e-3
#: Whether a map folds is decided on every this-many-th texel of a face's rows and
#: columns, at a quarter of the full classification's cost: 98k texels of a map of
#: 256-texel faces, a hundred of them at that share.
DECISION_STRIDE = 2


def interior_index(face_size: int) -> np.ndarray:
    """(6 (S + 2)^2,) the interior texel (0 .. 6 S^2 - 1) each atlas texel stands for:
    itself, or for a border texel the texel of the next face its direction falls in."""
    size = int(face_size)
    face, u, v = face_coordinates(texel_directions(size).reshape(-1, 3))
    column = np.clip(np.floor((u + 1.0) * 0.5 * size), 0, size - 1).astype(np.int64)
    row = np.clip(np.floor((v + 1.0) * 0.5 * size), 0, size - 1).astype(np.int64)
    return (face * size + row) * size + column


def interior_neighbours(face_size: int) -> np.ndarray:
    """(6 S^2, 4) the four neighbours of every interior texel, across cube faces."""
    size, side = int(face_size), int(face_size) + 2
    owner = interior_index(size).reshape(6, side, side)
    inner = np.arange(1, size + 1)
    return np.stack([owner[:, inner + dj][:, :, inner + di].reshape(-1)
                     for dj, di in ((0, 1), (0, -1), (1, 0), (-1, 0))], axis=1)


def curvatures(rmap: ReflectorMap, stride: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(Gaussian K, mean H) of every interior texel (6 S^2,) from the map's points and
    normals by central differences (outward normals: H < 0 where convex), from the
    first and second fundamental forms; with ``stride``, of every stride-th interior
    texel along each side of a face only."""
    size, side = rmap.face_size, rmap.face_size + 2
    texels = rmap.texels.reshape(6, side, side, 4).astype(np.float64)
    point = texels[..., :1] * texel_directions(size).reshape(6, side, side, 3)
    normal = texels[..., 1:]
    inner = slice(1, side - 1, stride)

    def along_u(a):
        return 0.5 * (a[:, inner, 2::stride] - a[:, inner, :-2:stride])

    def along_v(a):
        return 0.5 * (a[:, 2::stride, inner] - a[:, :-2:stride, inner])

    pu, pv, nu, nv = along_u(point), along_v(point), along_u(normal), along_v(normal)
    e, f, g = (pu * pu).sum(-1), (pu * pv).sum(-1), (pv * pv).sum(-1)
    l, n = -(nu * pu).sum(-1), -(nv * pv).sum(-1)
    m = -0.5 * ((nu * pv).sum(-1) + (nv * pu).sum(-1))
    area = np.maximum(e * g - f * f, 1e-300)
    return ((l * n - m * m) / area).reshape(-1), ((e * n - 2 * f * m + g * l) / (2 * area)).reshape(-1)


def curvature_classes(rmap: ReflectorMap, stride: int = 1) -> np.ndarray:
    """(6 S^2,) per interior texel (``stride``: as :func:`curvatures`): 0 convex, 1
    concave, 2 saddle, -1 near a parabolic curve (|K| r^2 < :data:`CURVED`) or a hole."""
    gauss, mean = curvatures(rmap, stride)
    radius = rmap.texels[..., 0]
    scale = float(radius[radius > 0].mean()) ** 2
    side = rmap.face_size + 2
    inner = slice(1, side - 1, stride)
    hole = rmap.texels.reshape(6, side, side, 4)[:, inner, inner, 0].reshape(-1) <= 0
    classes = np.where(gauss * scale > CURVED, np.where(mean < 0, 0, 1), np.where(gauss * scale < -CURVED, 2, -1))
    return np.where(hole | ~np.isfinite(gauss), -1, classes)


def regions(classes: np.ndarray, face_size: int) -> np.ndarray:
    """(6 S^2,) the connected region of each classed interior texel (its lowest texel),
    -1 where unclassed: neighbours across cube faces join where their classes agree."""
    neighbours = interior_neighbours(face_size)
    node = np.repeat(np.arange(len(classes)), 4)
    other = neighbours.reshape(-1)
    joined = (classes[node] == classes[other]) & (classes[node] >= 0)
    roots = component_roots(np.stack([node[joined], other[joined]], axis=1), len(classes))
    return np.where(classes >= 0, roots, -1)


def fold_patches(rmap: ReflectorMap, classes: np.ndarray | None = None, cells: int = CELLS) -> np.ndarray:
    """The search's starts on a folded star-shaped mirror's map (``ReflectorMap.patches``):
    the texels on a grid :data:`STRIDE` apart grouped by curvature region (of
    ``classes``, :func:`curvature_classes` by default) and cell of a ``cells`` x
    ``cells`` grid on their cube face (near a parabolic curve, by cell alone)."""
    size = rmap.face_size
    classes = curvature_classes(rmap) if classes is None else classes
    region = regions(classes, size)[interior_index(size)]
    _, row, column = texel_grid(size)
    sampled = np.flatnonzero((rmap.texels.reshape(-1, 4)[:, 0] > 0) & (row % STRIDE == 0) & (column % STRIDE == 0))
    cell = face_cells(size, cells)[sampled]
    group = (region[sampled] + 1) * (6 * cells * cells) + cell
    return grouped_patches(rmap, sampled, group)


def folds(rmap: ReflectorMap) -> bool:
    """Whether the map folds its reflections: concave or saddle texels make at least
    :data:`FOLDED_SHARE` of it, counted on every :data:`DECISION_STRIDE`-th texel."""
    return not rmap.convex and np.isin(curvature_classes(rmap, DECISION_STRIDE), (1, 2)).mean() >= FOLDED_SHARE


def folded(rmap: ReflectorMap, patched: bool = True) -> ReflectorMap:
    """The map searched for every image (:data:`MAX_IMAGES` slots, from
    :func:`fold_patches`, unless not ``patched``: what says that it folds, without the
    search's starts) where it folds (:func:`folds`); else the map as it is (one image
    per point)."""
    if not folds(rmap):
        return rmap
    return dataclasses.replace(rmap, patches=fold_patches(rmap) if patched else None, images=MAX_IMAGES)
