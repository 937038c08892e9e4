# SPDX-License-Identifier: GPL-3.0-or-later
"""The exact reference solver of refracted images: where a point appears through glass.

A point p appears through glass at the pixel q whose eye ray, bent at every interface it
meets (``engine/glass/paths.py``: Snell's law, total internal reflection), leaves the
glass on a segment passing through p. A reflection's law holds at one surface point, so
``exact.py`` solves it triangle by triangle; a refracted path crosses two or more
interfaces whose triangles are not known in advance, so this solver works in the image:

1. eye rays through a grid of pixels ``stride`` apart are followed through the glass;
2. a grid cell whose four corner rays came out along the same history (the same glass at
   each interface) may hold p when p lies ahead of its four last segments and, seen
   along their mean direction, within the quadrilateral of p's offsets from them (the
   cell's bundle of rays passes around p: SBC paper, section III, a ray map cell);
3. from the cell's centre, Gauss-Newton on the pixel drives p's offset from the true
   traced segment to zero, its Jacobian from rays a small step away, as images are
   polished on true rays (``true_rays.py``; Roger & Holzschuch 2006, section 3.2);
4. images of one point with one history less than :data:`MERGE_PX` apart are one.

An image is kept where the converged segment passes within :data:`RESIDUAL_FRACTION` of
the glass's size of p, ahead of its start, with no glass in between, on the view. An
image smaller than a cell is found only where a neighbouring cell's iteration reaches
it, so the reference is run at a fine ``stride``. Only glass is traced: mirrors and
diffuse objects between the eye and the glass, or between the glass and p, are not.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..engine.glass.paths import GlassSet
from ..engine.reference.exact import first_of_duplicates
from ..engine.view import View

#: Gauss-Newton iterations at most.
ITERATIONS = 16
#: Finite-difference step of the Jacobian, pixels.
STEP_PX = 1e-3
#: A step shorter than this (pixels) ends the iteration.
CONVERGED_PX = 1e-6
#: Longest step of one iteration, in grid cells: far from the root the model is poor.
MAX_STEP_CELLS = 1.0
#: A converged segment passes this close to its point (a share of the glass's size).
RESIDUAL_FRACTION = 1e-7
#: Images of one point and history closer than this (pixels) are one.
MERGE_PX = 1e-3
#: Slack of the cell test (in units of the quadrilateral's own coordinates): a point on
#: the edge between two cells is tried from both.
CELL_SLACK = 0.05
#: (point, cell) pairs tested at a time.
PAIR_CHUNK = 1 << 18


@dataclass(frozen=True)
class Refractions:
    """Every refracted image found; one row per (point, image), sorted by point."""

    point: np.ndarray  # (S,) index of the point
    pixel: np.ndarray  # (S, 2) where it appears
    history: np.ndarray  # (S, K) glass met at each interface, -1 past the last
    first_position: np.ndarray  # (S, 3) the first glass point on the eye's ray
    distance: np.ndarray  # (S,) from the last interface to the point

    def count_per_point(self, n_points: int) -> np.ndarray:
        return np.bincount(self.point, minlength=n_points)

    def crossing(self, interfaces: int, more: bool = False) -> "Refractions":
        """The images whose paths cross ``interfaces`` glass surfaces (``more``: at least
        that many). Two: in and out of a convex solid; more: reflected inside first."""
        count = (self.history >= 0).sum(axis=1)
        keep = count >= interfaces if more else count == interfaces
        return Refractions(self.point[keep], self.pixel[keep], self.history[keep], self.first_position[keep],
                           self.distance[keep])

    def matched(self, answers) -> tuple[np.ndarray, np.ndarray]:
        """How a search's answers meet these images: ``answers`` (slots, N, 2) pixels of
        the N points (NaN: no answer in that slot). Returns (S,) each exact image's
        distance to its point's nearest answer (inf: none), and (slots, N) each answer's
        distance to its point's nearest exact image (inf where the point has none, NaN
        where there is no answer)."""
        answers = np.asarray(answers, dtype=np.float64)
        answers = answers.reshape((-1,) + answers.shape[-2:])
        apart = np.linalg.norm(answers[:, self.point] - self.pixel[None], axis=2)
        apart = np.nan_to_num(apart, nan=np.inf)
        nearest = np.full(answers.shape[:2], np.inf)
        for slot in range(len(answers)):
            np.minimum.at(nearest[slot], self.point, apart[slot])
        return apart.min(axis=0), np.where(np.isnan(answers[..., 0]), np.nan, nearest)


def solve_refractions(glass: GlassSet, view: View, points: np.ndarray, stride: float = 2.0) -> Refractions:
    """Every image of ``points`` (P, 3) seen through ``glass`` in ``view`` (see the module)."""
    points = np.asarray(points, dtype=np.float64)
    grid_x = np.unique(np.minimum(np.arange(0.0, view.width + stride, stride), view.width))
    grid_y = np.unique(np.minimum(np.arange(0.0, view.height + stride, stride), view.height))
    corners = np.stack(np.meshgrid(grid_x, grid_y), axis=-1).reshape(-1, 2)
    paths = glass.trace(*view.pixel_rays(corners))
    cells = _through_cells(paths, len(grid_x), len(grid_y))
    point, cell = _candidates(paths, cells, points)
    corner = cells[cell, 0]
    start = corners[corner] + 0.5 * np.array([grid_x[1] - grid_x[0], grid_y[1] - grid_y[0]])
    history = paths.history[corner]
    pixel, ok = _gauss_newton(glass, view, points[point], start, history, stride)
    found = _traced_images(glass, view, points[point[ok]], pixel[ok], history[ok])
    keep = found["kept"]
    point, pixel, history = point[ok][keep], pixel[ok][keep], history[ok][keep]
    unique = _first_of_each(point, history, pixel)
    order = np.argsort(point[unique], kind="stable")
    chosen = unique[order]
    return Refractions(point[chosen], pixel[chosen], history[chosen], found["first_position"][keep][chosen],
                       found["distance"][keep][chosen])


def _through_cells(paths, nx: int, ny: int) -> np.ndarray:
    """(C, 4) corner indices (counter-clockwise in the image) of the grid cells whose four
    rays came through the glass along one history into one medium."""
    index = np.arange(nx * ny).reshape(ny, nx)
    cells = np.stack([index[:-1, :-1], index[:-1, 1:], index[1:, 1:], index[1:, :-1]], axis=-1).reshape(-1, 4)
    through = paths.through_glass[cells].all(axis=1)
    same = np.all(paths.history[cells] == paths.history[cells[:, :1]], axis=(1, 2))
    same &= np.all(paths.medium[cells] == paths.medium[cells[:, :1]], axis=1)
    return cells[through & same]


def _candidates(paths, cells: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(point, cell) pairs whose cell's bundle of last segments passes around the point."""
    origin, direction = paths.origin[cells], paths.direction[cells]  # (C, 4, 3)
    mean = direction.sum(axis=1)
    mean /= np.linalg.norm(mean, axis=1, keepdims=True)
    u = np.cross(mean, np.where(np.abs(mean[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]]))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(mean, u)
    found_points, found_cells = [], []
    per_chunk = max(1, PAIR_CHUNK // max(1, len(cells)))
    for first in range(0, len(points), per_chunk):
        p = points[first:first + per_chunk]
        w = p[:, None, None, :] - origin[None]  # (P, C, 4, 3)
        along = np.einsum("pckj,ckj->pck", w, direction)
        offset = w - along[..., None] * direction[None]
        e = np.stack([np.einsum("pckj,cj->pck", offset, u), np.einsum("pckj,cj->pck", offset, v)], axis=-1)
        inside = _holds_origin(e[..., 0, :], e[..., 1, :], e[..., 2, :]) | _holds_origin(
            e[..., 0, :], e[..., 2, :], e[..., 3, :])
        inside &= (along > 0).all(axis=-1)
        pi, ci = np.nonzero(inside)
        found_points.append(pi + first)
        found_cells.append(ci)
    return np.concatenate(found_points), np.concatenate(found_cells)


def _holds_origin(a, b, c) -> np.ndarray:
    """Whether the 2D triangles (a, b, c) (..., 2) hold the origin, with CELL_SLACK."""
    def cross(p, q):
        return p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0]

    area = cross(b - a, c - a)
    with np.errstate(divide="ignore", invalid="ignore"):
        wa, wb, wc = cross(b, c) / area, cross(c, a) / area, cross(a, b) / area
    return (wa >= -CELL_SLACK) & (wb >= -CELL_SLACK) & (wc >= -CELL_SLACK) & (np.abs(area) > 0)


def _offsets(glass: GlassSet, view: View, points, pixels, history):
    """(K, 3) offset of each point from the last segment of the traced ray through its
    pixel (its part across the segment), (K,) distance along it, and (K,) whether the
    ray kept ``history``."""
    paths = glass.trace(*view.pixel_rays(pixels))
    w = points - paths.origin
    along = np.einsum("ij,ij->i", w, paths.direction)
    same = np.all(paths.history == history, axis=1) & paths.through_glass
    return w - along[:, None] * paths.direction, along, same, paths


def _gauss_newton(glass: GlassSet, view: View, points, start, history, stride: float):
    """Pixels whose traced segments pass through ``points``, from ``start``; (K,) ok."""
    pixel = start.copy()
    ok = np.zeros(len(pixel), dtype=bool)
    active = np.arange(len(pixel))
    for _ in range(ITERATIONS):
        if len(active) == 0:
            break
        m = len(active)
        q = pixel[active]
        steps = np.concatenate([np.zeros((m, 2)), np.tile([STEP_PX, 0.0], (m, 1)), np.tile([0.0, STEP_PX], (m, 1))])
        f, _, same, _ = _offsets(glass, view, np.tile(points[active], (3, 1)), np.tile(q, (3, 1)) + steps,
                                 np.tile(history[active], (3, 1)))
        ju, jv = (f[m:2 * m] - f[:m]) / STEP_PX, (f[2 * m:] - f[:m]) / STEP_PX
        f, usable = f[:m], same[:m] & same[m:2 * m] & same[2 * m:]
        a, b, c = (np.einsum("ij,ij->i", x, y) for x, y in ((ju, ju), (ju, jv), (jv, jv)))
        gu, gv = np.einsum("ij,ij->i", ju, f), np.einsum("ij,ij->i", jv, f)
        det = a * c - b * b
        usable &= np.abs(det) > 1e-300
        det = np.where(usable, det, 1.0)
        step = np.stack([(c * gu - b * gv) / det, (a * gv - b * gu) / det], axis=1)
        length = np.linalg.norm(step, axis=1)
        step *= np.minimum(1.0, MAX_STEP_CELLS * stride / np.maximum(length, 1e-300))[:, None]
        pixel[active] = q - np.where(usable[:, None], step, 0.0)
        done = usable & (length < CONVERGED_PX)
        ok[active[done]] = True
        active = active[usable & ~done]
    return pixel, ok


def _traced_images(glass: GlassSet, view: View, points, pixels, history) -> dict:
    """The images whose traced ray keeps its history and passes through its point, ahead
    of the last interface with no glass before it, on the view: ``kept`` (K,) and the
    path's first glass point and last distance."""
    f, along, same, paths = _offsets(glass, view, points, pixels, history)
    kept = same & (along > 0) & (np.linalg.norm(f, axis=1) <= RESIDUAL_FRACTION * glass.surfaces.scale)
    kept &= (pixels >= 0).all(axis=1) & (pixels[:, 0] <= view.width) & (pixels[:, 1] <= view.height)
    check = np.flatnonzero(kept)
    if len(check):
        hits = glass.surfaces.intersect(paths.origin[check], paths.direction[check], along[check])
        kept[check] &= ~hits.hit
    return {"kept": kept, "first_position": paths.first_position, "distance": along}


def _first_of_each(point, history, pixel) -> np.ndarray:
    """Indices keeping one of each group of images of one point and history within
    MERGE_PX of each other (``exact.first_of_duplicates`` on the pixels)."""
    keep = first_of_duplicates((point,) + tuple(history.T), (np.c_[pixel, np.zeros(len(pixel))],), MERGE_PX / 1e-7)
    return np.flatnonzero(keep)
