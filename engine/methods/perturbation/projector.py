# SPDX-License-Identifier: GPL-3.0-or-later
"""Perturbation (Chen & Arvo 2000) behind the one interface: where does each point
appear, reflected, in this view?

Per view (section III):

1. *Seeds*: exact paths traced from the eye through every ``seed_stride_px``-th pixel
   and scan line (``seeds.py``, III-B.1), grouped by reflection history; a history
   with fewer than MIN_GROUP_SEEDS is traced again at half the spacing.
2. *Nearest path*: instead of the paper's ray octree (III-B.2) the seeds' image-plane
   grid is searched (``candidates.py``): the local minima of the distance from the
   point to the seeds' outgoing rays over a coarse sub-grid (every COARSE-th seed,
   COARSE_CONVEX-th on a convex mirror) are the point's candidate images; each then
   *hops*: a first-order step from its seed predicts the pixel, and the seed there
   (else the last one on the way) is taken, until the seed stays. Along a non-convex
   mirror's silhouette, where its images crowd, seeds at every second pixel of a band
   are searched as well (``rim.py``).
3. *Perturbation* (``taylor_step.py``): from the point p on the seed's outgoing ray closest to the vertex
   p', the path Jacobian and Hessian give the reflector points of the path to p'
   (eq. 4, ``path_derivatives.py``; orders 2 and more in one system).
4. *Error estimate*: the series' next term from the last two (e2^2 / e1, in pixels),
   and on a mesh twice the seed's model error (:func:`_model_errors`) times e1. A step
   is trusted only when local (REACH spacings in the image, MAX_RELATIVE_STEP of the
   path in the scene), in front of the next reflector on the ray, and not landing on
   the surface's far side.
5. *Adaptive seeds*: where the estimate exceeds ``accuracy_px`` a new seed is traced
   toward the predicted pixel (damped to REACH spacings) and the step is taken again
   from it (up to REFINE_ROUNDS times). An answer still above the bound, or whose
   pixel falls outside the seeds' footprint of its history (an image beyond the
   mirror's silhouette), is not given: never drawn at a wrong place.
6. *Newton on the mesh*: on a mirror that bends both ways, the candidates whose series
   did not converge (dropped in 4, refused in 5), and the seeds a candidate hopped away
   from in 2, start Newton's method on the law of reflection in their seed's triangle
   (``mesh_polish.py``); a root the eye and the point both see is an exact answer
   (:meth:`PerturbationMethod._polished`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ...projection import NOT_PROJECTED, PERTURBATION_ANSWER, Projection
from ...geometry.raytrace import ReflectorSet
from ...geometry.vectors import dot, normalized
from ...view import View
from .answers import ranked, repeats
from .candidates import candidate_images
from .mesh_polish import walk_to_roots
from .rim import RimBand
from .seeds import SeedPaths, seed_quadrics, trace_seed_paths
from .taylor_step import MODEL_SAFETY, first_order_pixels, taylor_step

#: A history with fewer grid seeds is traced again at half the spacing over its footprint.
MIN_GROUP_SEEDS = 600
#: Seed spacing of the coarse search for candidate images, in grid seeds: every seed
#: on a mirror that bends both ways, where a point's images crowd (two images a few
#: pixels apart share one basin of every other seed; docs/benchmarks/perturbation.md).
COARSE = 1
#: ... on a mirror whose seeds all bend one way (convex): a point has one image there,
#: one minimum of the distance, which a coarser scan finds as well (the hops refine it).
COARSE_CONVEX = 4
#: Tangential curvatures against the largest, below which a seed counts as bending the
#: other way (a saddle or a dent).
CONVEX_TOLERANCE = 0.05
#: Hops from a candidate seed to the seed at its predicted pixel.
HOPS = 3
#: Cells tried along the way when no seed is at the predicted pixel (the last with one is taken).
HOP_SAMPLES = 8
#: How far (in seed spacings) a Taylor step may move an image from its seed's pixel.
REACH = 1.5
#: Rounds of adaptive seeds through predicted pixels.
REFINE_ROUNDS = 12
#: A candidate whose adaptive seeds leave the history this often gives up (an image
#: beyond the silhouette, or none). Each miss halves the way back toward the last seed:
#: 8 reach a twentieth of a pixel, where a grazing image lies (R c^2 / 2 pixels inside
#: the silhouette of a mirror R pixels across, at cosine c).
MAX_MISSES = 8
#: On a mirror that bends both ways, with adaptive seeds (the numpy path; the GPU twin
#: scans the grid alone), a candidate is also stepped from the grid seeds in these cells
#: around its own (``_answer_group``).
NEIGHBOUR_CELLS = ((-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (1, 1), (1, -1), (-1, 1))
#: The grid seeds two cells from any candidate's (the ring around those) start Newton's
#: method on the mesh (``_polished``): most images the steps miss lie within 2.5 cells of
#: a seed, a few cells from a point's only candidate.
POLISH_RING_CELLS = tuple((a, b) for a in range(-2, 3) for b in range(-2, 3) if max(abs(a), abs(b)) == 2)
#: On such a mirror an answer is given when the step from a seed traced through its own
#: pixel moves it by at most this (px) (``PerturbationMethod._confirm``; adaptive seeds only).
CONFIRM_PX = 1.0
#: A root found on the mesh (``_polished``) is seen where the eye's ray through its pixel
#: meets the mirror within this share of the mirrors' size of it.
SAME_POINT = 1e-6
#: Reflections more grazing than this (cosine to the normal) are not drawn
#: (:func:`grazing`): the silhouette's last pixel (R / 200 of a mirror R pixels across).
GRAZING_COSINE = 0.1
#: Answered from the grid alone (no adaptive seeds: the GPU twin on a mesh), a history's
#: seeds are traced again at half the spacing while this share of them would give a step
#: of half a spacing an estimate over the accuracy by their model error alone...
FINER_SHARE = 0.1
#: ... down to this spacing (px).
MIN_GRID_STRIDE = 2


@dataclass(frozen=True)
class PerturbationSettings:
    """What the method does per view."""

    seed_stride_px: int = 8
    accuracy_px: float = 0.5
    max_order: int = 1
    #: Trace seeds where a step's estimate exceeds the accuracy (off: answer from the
    #: grid alone, what the GPU twin does on a mesh, where it traces no rays).
    adaptive_seeds: bool = True


@dataclass
class PerturbationStats:
    """What one projection cost: seeds traced (grid and adaptive), answers refined."""

    grid_seeds: int = 0
    adaptive_seeds: int = 0
    refused: int = 0
    #: Answers found by Newton's method on the mesh where the series did not converge.
    polished: int = 0
    per_history: dict = field(default_factory=dict)


@dataclass(frozen=True)
class PerturbationReflector:
    """One reflector drawn by perturbation: its index among the scene's reflectors, its
    name and, when declared, its exact surface (``quadrics.AnalyticSurface``)."""

    index: int
    name: str
    surface: object = None


@dataclass(frozen=True)
class SeedGroup:
    """The grid seeds of one reflection history: their paths, quadrics, grid (what the
    GPU twin, ``drawing/methods/perturbation_gpu.py``, uploads)."""

    history: tuple
    seeds: SeedPaths
    quadrics: list
    grid: np.ndarray  # (rows, columns) seed index, -1 where the history has none
    origin: tuple  # (column, row) of grid[0, 0] in the view's seed grid
    model_error: np.ndarray  # (S,) per seed, :func:`_model_errors`
    stride: int  # pixels between grid seeds
    coarse: int  # grid seeds between the candidate scan's (COARSE or COARSE_CONVEX)
    #: (rows, columns) bool, cells whose images another group answers (a rim band's
    #: inner edge): never candidates. None: all may be.
    inner: np.ndarray | None = None


class PerturbationMethod:
    """Chen-Arvo perturbation for the reflectors of a :class:`ReflectorSet`; reflectors
    in ``analytic`` ({reflector index: quadrics.AnalyticSurface}) use their exact
    surface."""

    def __init__(self, reflector_set: ReflectorSet, analytic: dict | None = None,
                 settings: PerturbationSettings = PerturbationSettings()):
        self.reflector_set = reflector_set
        self.analytic = dict(analytic or {})
        self.settings = settings
        self.stats = PerturbationStats()

    def project(self, view: View, points, histories=None) -> Projection:
        """Every image of ``points`` in ``view``; ``histories``: answer only these
        reflection histories (tuples of reflector indices; default all up to the order)."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        self.stats = PerturbationStats()
        groups = self.grid_groups(view)
        if histories is not None:
            wanted = {tuple(h) for h in histories}
            groups = [g for g in groups if g.history in wanted]
        histories, rows = [], []
        for group in groups:
            if not self.settings.adaptive_seeds:
                group = self.fine_enough(view, group)
            answers = self._answer_group(view, group, points)
            band = self.rim_band(view, group) if self.settings.adaptive_seeds and group.coarse == COARSE else None
            if band is not None:
                answers = tuple(np.concatenate(pair) for pair in zip(answers, self._answer_group(view, band, points)))
            answers = ranked(len(points), *answers)
            self.stats.per_history[group.history] = int(sum(np.isfinite(a[:, 0]).sum() for a in answers[0]))
            for rank in range(len(answers[0])):
                histories.append(group.history)
                rows.append((answers[0][rank], answers[1][rank]))
        return _as_projection(view, points, histories, rows)

    def grid_groups(self, view: View) -> list:
        """The seeds of every history: the view's grid, refined (halving the spacing) over
        the footprint of a history with fewer than MIN_GROUP_SEEDS seeds: a small image,
        such as a second-order one, needs denser paths than the first-order footprints."""
        stride = int(self.settings.seed_stride_px)
        pixels = view.pixel_grid(stride)
        traced = trace_seed_paths(self.reflector_set, view, pixels, self.settings.max_order, self.analytic)
        self.stats.grid_seeds = len(pixels)
        groups = []
        for seeds in traced:
            if len(seeds.pixels) == 0:
                continue
            keys, inverse = np.unique(seeds.histories, axis=0, return_inverse=True)
            for k, key in enumerate(keys):
                members = seeds.select(np.flatnonzero(inverse.reshape(-1) == k))
                group = self._group(tuple(int(r) for r in key), members, stride)
                while len(group.seeds.pixels) < MIN_GROUP_SEEDS and group.stride > 1:
                    finer = self._finer(view, group)
                    if finer is None:
                        break
                    group = finer
                groups.append(group)
        return groups

    def fine_enough(self, view: View, group: SeedGroup) -> SeedGroup:
        """``group`` traced again at half its spacing until a step from the grid alone can
        meet the accuracy: the estimate's model term (MODEL_SAFETY x model error x step,
        ``taylor_step``) for a step of half a spacing is over ``accuracy_px`` at no more than
        FINER_SHARE of the seeds. On a bumpy mesh the quadric fitted at a seed misses the
        surface a spacing away (the model error falls slowly with the spacing, the step
        in proportion), and the grid's answers would be refused over half the mirror; adaptive
        seeds (the numpy path) trace rays per answer instead. The candidate scan keeps its
        spacing in pixels (its cost), hops and steps use the finer seeds."""
        coarse_px = group.coarse * group.stride
        while group.stride > MIN_GRID_STRIDE:
            model = MODEL_SAFETY * group.model_error * 0.5 * group.stride
            if np.mean(model > self.settings.accuracy_px) <= FINER_SHARE:
                break
            finer = self._finer(view, group)
            if finer is None:
                break
            group = dataclasses.replace(finer, coarse=max(finer.coarse, coarse_px // finer.stride))
        return group

    def rim_band(self, view: View, group: SeedGroup) -> SeedGroup | None:
        """The seeds of ``group``'s history at every second pixel of its rim band
        (``rim.py``), scanned at each seed; None when the band has none."""
        rim = RimBand.around(group.grid, group.origin, group.stride)
        pixels = rim.pixels(view.width, view.height)
        traced = self._traced_in(view, group.history, pixels)
        self.stats.grid_seeds += len(pixels)
        if len(traced.pixels) == 0:
            return None
        band = self._group(group.history, traced, rim.step)
        inner = np.zeros(band.grid.shape, dtype=bool)
        cell = _cells(band, band.seeds.pixels)
        inner[cell[:, 1], cell[:, 0]] = rim.touches_interior(band.seeds.pixels)
        return dataclasses.replace(band, coarse=1, inner=inner)

    def _group(self, history: tuple, seeds: SeedPaths, stride: int) -> SeedGroup:
        cell = np.floor(seeds.pixels / stride).astype(np.int64)
        lo = cell.min(axis=0)
        grid = np.full(tuple((cell.max(axis=0) - lo + 1)[::-1]), -1, dtype=np.int64)
        grid[cell[:, 1] - lo[1], cell[:, 0] - lo[0]] = np.arange(len(cell))
        quadrics = seed_quadrics(self.reflector_set, seeds, self.analytic)
        coarse = COARSE_CONVEX if all(_bends_one_way(seeds.points[:, k], q) for k, q in enumerate(quadrics)) \
            else COARSE
        return SeedGroup(history, seeds, quadrics, grid, tuple(lo), _model_errors(seeds, quadrics, grid), stride,
                         coarse)

    def _finer(self, view: View, group: SeedGroup) -> SeedGroup | None:
        """The group traced again at half its spacing over its footprint (one old cell
        around); None when that finds no more seeds."""
        stride = group.stride // 2
        lo, hi = group.seeds.pixels.min(axis=0) - group.stride, group.seeds.pixels.max(axis=0) + group.stride
        pixels = view.pixel_grid(stride)
        pixels = pixels[((pixels >= lo) & (pixels <= hi)).all(axis=1)]
        traced = self._traced_in(view, group.history, pixels)
        self.stats.grid_seeds += len(pixels)
        if len(traced.pixels) <= len(group.seeds.pixels):
            return None
        return self._group(group.history, traced, stride)

    def _traced_in(self, view: View, history: tuple, pixels) -> SeedPaths:
        """The seeds traced through ``pixels`` whose paths have ``history`` (``ray``: their
        rows in ``pixels``)."""
        traced = trace_seed_paths(self.reflector_set, view, pixels, len(history), self.analytic)[-1]
        return traced.select(np.flatnonzero((traced.histories == np.array(history)).all(axis=1)))

    def _step_from(self, view, traced: SeedPaths, targets, model_error, reach_px):
        """:func:`.taylor_step.taylor_step` from each of the ``traced`` seeds to its target
        (its row of ``targets`` and ``model_error``), with the seeds' own quadrics."""
        quadrics = seed_quadrics(self.reflector_set, traced, self.analytic)
        return taylor_step(view, traced, quadrics, targets, np.arange(len(targets)), model_error, reach_px)

    def _answer_group(self, view, group: SeedGroup, points):
        """The images found from ``group``'s seeds: (K,) point index, (K, 3) first and
        last reflector points, (K, 2) pixel (one point may have several)."""
        point_of, found_at = candidate_images(group, points)
        seed_of = self._hop(view, group, points, point_of, found_at)
        crowded = self.settings.adaptive_seeds and group.coarse != COARSE_CONVEX  # the numpy path, bending both ways
        # Near a fold the first-order hop can carry a candidate cells away from its image,
        # onto another image's seeds: the seed it was found at starts Newton on the mesh
        # too: most images missed away from the rim have a candidate within a cell before
        # its hops.
        walk_from = _left_by_hops(point_of, found_at, seed_of)
        if crowded:
            if group.inner is None:  # the grid's seeds (the rim band's lie RIM_STEP px apart)
                around = _around(group, point_of, seed_of, POLISH_RING_CELLS)
                walk_from = tuple(np.concatenate(pair) for pair in zip(walk_from, around))
            # Two images a few pixels apart can share one candidate (its hops and steps reach
            # one of them); the step from a seed beside it reaches the other. Stepping around
            # a point's only candidate too would cost seconds a view more.
            several = np.bincount(point_of)[point_of] > 1
            beside = _around(group, point_of[several], seed_of[several], NEIGHBOUR_CELLS)
            point_of, seed_of = np.concatenate([point_of, beside[0]]), np.concatenate([seed_of, beside[1]])
        # Candidates that hopped onto one seed are one image.
        _, first_of = np.unique(point_of * len(group.seeds.pixels) + seed_of, return_index=True)
        point_of, seed_of = point_of[first_of], seed_of[first_of]
        model_error = group.model_error[seed_of]
        first, last, estimate, pixel = taylor_step(view, group.seeds, group.quadrics, points[point_of], seed_of,
                                                   model_error, REACH * group.stride)
        # Along a convex mirror's edge the distance falls toward the silhouette, and
        # each edge seed is a candidate whose step leaves the mirror: where the point
        # has a candidate with a local step, those are not followed.
        # A point with no local candidate follows its shortest step only.
        local = np.isfinite(estimate)
        move = np.linalg.norm(pixel - group.seeds.pixels[seed_of], axis=1)
        far = np.flatnonzero(~local & ~np.isin(point_of, point_of[local]) & np.isfinite(move))
        far = far[np.lexsort((move[far], point_of[far]))]
        shortest = far[np.r_[True, point_of[far][1:] != point_of[far][:-1]]] if len(far) else far
        keep = local.copy()
        keep[shortest] = True
        dropped = point_of[~keep], seed_of[~keep]
        point_of, seed_of, model_error = point_of[keep], seed_of[keep], model_error[keep]
        first, last, estimate, pixel = first[keep], last[keep], estimate[keep], pixel[keep]
        ok = np.ones(len(point_of), dtype=bool)
        if self.settings.adaptive_seeds:
            self._refine(view, group, points[point_of], group.seeds.pixels[seed_of], model_error,
                         (first, last, estimate, pixel))
            if crowded:  # one image per point on a convex mirror: none to confuse
                ok = self._confirm(view, group, points[point_of], model_error, (first, last, estimate, pixel))
        ok &= (estimate <= max(self.settings.accuracy_px, 1e-9)) & _in_footprint(group, pixel) \
            & view.in_view(np.nan_to_num(first))
        self.stats.refused += int((~ok).sum())
        answers = point_of[ok], first[ok], last[ok], pixel[ok]
        if crowded and len(group.history) == 1 and group.history[0] not in self.analytic:
            polished = self._polished(view, group, points, np.concatenate([point_of[~ok], dropped[0], walk_from[0]]),
                                      np.concatenate([seed_of[~ok], dropped[1], walk_from[1]]), answers)
            answers = tuple(np.concatenate(pair) for pair in zip(answers, polished))
        return answers

    def _refine(self, view, group: SeedGroup, targets, seed_pixel, model_error, answer) -> None:
        """Adaptive seeds (in place on ``answer``: first, last, estimate, pixel): where the
        estimate is above the accuracy, a seed is traced toward the predicted pixel, at
        most REACH seed spacings from the last seed (a damped step: near the silhouette a
        far step leaves the mirror), halving toward the last seed when the ray misses the
        history; its step replaces the answer when its estimate is lower."""
        first, last, estimate, pixel = answer
        reach = REACH * group.stride
        aim = pixel.copy()
        misses = np.zeros(len(aim), dtype=np.int64)
        for _ in range(REFINE_ROUNDS):
            redo = np.flatnonzero(~(estimate <= self.settings.accuracy_px) & np.isfinite(aim[:, 0]))
            if len(redo) == 0:
                break
            move = aim[redo] - seed_pixel[redo]
            size = np.linalg.norm(move, axis=1)
            target = seed_pixel[redo] + move * np.minimum(1.0, reach / np.maximum(size, 1e-12))[:, None]
            traced = self._traced_in(view, group.history, target)
            self.stats.adaptive_seeds += len(redo)
            missed = np.ones(len(redo), dtype=bool)
            missed[traced.ray] = False
            misses[redo] += missed
            aim[redo[missed]] = np.where((misses[redo[missed]] < MAX_MISSES)[:, None],
                                         0.5 * (seed_pixel[redo[missed]] + target[missed]), np.nan)
            rows = redo[traced.ray]
            f, l, e, p = self._step_from(view, traced, targets[rows], model_error[rows], reach)
            seed_pixel[rows], aim[rows] = target[traced.ray], p
            better = ~(e >= estimate[rows])
            rows = rows[better]
            first[rows], last[rows], estimate[rows], pixel[rows] = f[better], l[better], e[better], p[better]

    def _confirm(self, view, group: SeedGroup, targets, model_error, answer) -> np.ndarray:
        """(K,) bool: which answers a seed traced through their own pixel confirms (in
        place on ``answer``: first, last, estimate, pixel, its step replacing theirs):
        the ray there keeps the history, and its step to the target is trusted and moves
        the image by at most CONFIRM_PX. An estimate is the series' own guess: among a
        bumpy mirror's crowded images a step from a seed two images away can look
        converged on the wrong one, and a step from the answer's own pixel is short
        (about halves the answers farther than a pixel from every exact image on a
        bumpy mirror)."""
        first, last, estimate, pixel = answer
        asked = np.flatnonzero(estimate <= max(self.settings.accuracy_px, 1e-9))
        traced = self._traced_in(view, group.history, pixel[asked])
        self.stats.adaptive_seeds += len(asked)
        rows = asked[traced.ray]
        confirmed = np.zeros(len(estimate), dtype=bool)
        if len(rows) == 0:
            return confirmed
        f, l, e, p = self._step_from(view, traced, targets[rows], model_error[rows], REACH * group.stride)
        good = (e <= max(self.settings.accuracy_px, 1e-9)) & (np.linalg.norm(p - pixel[rows], axis=1) <= CONFIRM_PX)
        rows = rows[good]
        first[rows], last[rows], estimate[rows], pixel[rows] = f[good], l[good], e[good], p[good]
        confirmed[rows] = True
        return confirmed

    def _polished(self, view, group: SeedGroup, points, point_of, seed_of, answers):
        """Answers of the candidates whose series did not converge (``point_of``,
        ``seed_of``: dropped and refused), by Newton's method on the mesh from their
        seeds (``mesh_polish``), as ``_answer_group``'s; the images ``answers`` (its own
        so far) give are not traced again (:func:`answers.repeats`). A root is kept where
        the eye's ray through its pixel meets the mirror there first, with the group's
        history, and its reflected ray reaches the point before any reflector (it is then
        a visible exact reflection), inside the history's footprint and the view."""
        seeds = group.seeds
        roots = walk_to_roots(self.reflector_set, view, points, point_of, seeds.triangles[seed_of, 0],
                              seeds.barycentric[seed_of, 0, 1:])
        rows = np.flatnonzero(np.isfinite(roots[:, 0]))
        pixel = view.to_pixels(roots[rows])[0]
        new = ~repeats(np.concatenate([answers[0], point_of[rows]]), np.concatenate([answers[3], pixel]),
                       np.arange(len(answers[0]) + len(rows)))[len(answers[0]):]
        rows, pixel = rows[new], pixel[new]
        traced = self._traced_in(view, group.history, pixel)
        rows, pixel = rows[traced.ray], pixel[traced.ray]
        root, target = roots[rows], points[point_of[rows]]
        seen = (np.linalg.norm(traced.points[:, 0] - root, axis=1) <= SAME_POINT * self.reflector_set.scale) \
            & (traced.head >= np.linalg.norm(target - root, axis=1)) & _in_footprint(group, pixel) & view.in_view(root)
        self.stats.polished += int(seen.sum())
        return point_of[rows[seen]], root[seen], root[seen], pixel[seen]

    def _hop(self, view, group, points, point_of, seed_of):
        """Move each candidate to the grid seed at its predicted pixel, until it stays.
        Where no seed is there (the image predicted past the footprint's edge), to the
        last seed on the way (HOP_SAMPLES cells along the line): the edge seed nearest
        the image, which the adaptive seeds then have little left to walk."""
        origin = np.array(group.origin)
        current = _cells(group, group.seeds.pixels)
        for _ in range(HOPS):
            pixel = first_order_pixels(view, group.seeds, group.quadrics, points[point_of], seed_of)
            aim = np.nan_to_num(pixel / group.stride, nan=-1e9) - origin
            start = current[seed_of]
            moved = np.full(len(seed_of), -1, dtype=np.int64)
            for t in np.linspace(1.0, 0.0, HOP_SAMPLES, endpoint=False):
                waiting = np.flatnonzero(moved < 0)
                cell = np.floor(start[waiting] + 0.5 + t * (aim[waiting] - start[waiting] - 0.5)).astype(np.int64)
                moved[waiting] = _grid_at(group.grid, cell)
            moved = np.where(moved >= 0, moved, seed_of)
            if (moved == seed_of).all():
                break
            seed_of = moved
        return seed_of


def grazing(view: View, points: np.ndarray, reflector_points: np.ndarray) -> np.ndarray:
    """(P,) bool: first-order reflections of ``points`` at ``reflector_points`` that graze
    the mirror (the cosine between the normal, the bisector of the directions to the eye
    and to the point, and the direction to the eye below GRAZING_COSINE). Such an image
    is compressed into the silhouette's last pixel, and a triangle with such corners
    spans the chord between them, far beyond the image (the floor behind a ball drawn
    over the sky along its rim): the renderer does not draw it, and traces the rim.
    The projection still gives it (the exact solver counts it visible)."""
    to_eye = view.directions_to_eye(np.nan_to_num(reflector_points))
    bisector = normalized(to_eye + normalized(points - reflector_points))
    return dot(bisector, to_eye) < GRAZING_COSINE


def _bends_one_way(points: np.ndarray, quadrics) -> bool:
    """Whether every seed's quadric curves the same way about its normal (all tangential
    curvatures of one sign, up to CONVEX_TOLERANCE of the largest): a convex mirror."""
    normal = normalized(quadrics.gradients(points))
    tangent = np.eye(3) - normal[:, :, None] * normal[:, None, :]
    curvatures = np.linalg.eigvalsh(tangent @ np.asarray(quadrics.hessian) @ tangent)
    scale = np.abs(curvatures).max()
    if scale == 0:
        return True
    return bool((curvatures >= -CONVEX_TOLERANCE * scale).all() or (curvatures <= CONVEX_TOLERANCE * scale).all())


def _model_errors(seeds: SeedPaths, quadrics: list, grid: np.ndarray) -> np.ndarray:
    """(S,) how far each seed's quadrics miss the surface next to it: at each grid
    neighbour's reflection point (same history, so the same reflectors), the normal the
    seed's quadric predicts against the neighbour's own, relative to how much the normal
    turned between the two; the largest over neighbours and bounces. Zero on an exact
    surface (the same quadric); 1, the most cautious, for a seed without neighbours."""
    error = np.zeros(len(seeds.pixels))
    seen = np.zeros(len(seeds.pixels), dtype=bool)
    for di, dj in ((0, 1), (1, 0)):
        a = grid[:grid.shape[0] - di, :grid.shape[1] - dj]
        b = grid[di:, dj:]
        both = (a >= 0) & (b >= 0)
        a, b = a[both], b[both]
        for s, t in ((a, b), (b, a)):
            for bounce, q in enumerate(quadrics):
                x_t = seeds.points[t, bounce]
                own_s = normalized(q.take(s).gradients(seeds.points[s, bounce]))
                own_t = normalized(q.take(t).gradients(x_t))
                predicted = normalized(q.take(s).gradients(x_t))
                turned = np.linalg.norm(own_t - own_s, axis=1)
                ratio = np.linalg.norm(predicted - own_t, axis=1) / np.maximum(turned, 1e-12)
                np.maximum.at(error, s, np.where(turned > 1e-12, ratio, 0.0))
            seen[s] = True
    return np.where(seen, error, 1.0)


def _left_by_hops(point_of, found_at, seed_of):
    """(point_of, seed_of) of the candidates' seeds before their hops (``found_at``),
    where the hops moved them."""
    hopped = found_at != seed_of
    return point_of[hopped], found_at[hopped]


def _around(group: SeedGroup, point_of, seed_of, offsets):
    """(point_of, seed_of) of the grid seeds at ``offsets`` (cells) from each candidate's seed."""
    cell = _cells(group, group.seeds.pixels[seed_of])
    points, seeds = [point_of[:0]], [seed_of[:0]]
    for offset in offsets:
        at = _grid_at(group.grid, cell + np.array(offset))
        points.append(point_of[at >= 0])
        seeds.append(at[at >= 0])
    return np.concatenate(points), np.concatenate(seeds)


def _cells(group: SeedGroup, pixels) -> np.ndarray:
    """(K, 2) the grid cells (column, row) of ``group``'s seed grid that hold ``pixels``."""
    return np.floor(pixels / group.stride).astype(np.int64) - np.array(group.origin)


def _grid_at(grid: np.ndarray, cell: np.ndarray) -> np.ndarray:
    """(K,) the seed index at grid cells (column, row), -1 outside the grid or where none."""
    rows, columns = grid.shape
    inside = (cell[:, 0] >= 0) & (cell[:, 0] < columns) & (cell[:, 1] >= 0) & (cell[:, 1] < rows)
    found = np.full(len(cell), -1, dtype=np.int64)
    found[inside] = grid[cell[inside, 1], cell[inside, 0]]
    return found


def _in_footprint(group: SeedGroup, pixel) -> np.ndarray:
    """(K,) bool: a grid seed of the history lies within one cell of the pixel."""
    cell = _cells(group, np.nan_to_num(pixel, nan=-1e9))
    return np.any([_grid_at(group.grid, cell + (dj, di)) >= 0 for di in (-1, 0, 1) for dj in (-1, 0, 1)], axis=0)


def _as_projection(view, points, histories, rows) -> Projection:
    n = len(points)
    if not rows:
        empty = np.zeros((0, n))
        return Projection([], np.zeros((0, n, 3)), empty.astype(bool), empty.astype(np.int8), np.zeros((0, n, 2)),
                          empty)
    first = np.stack([r[0] for r in rows])
    last = np.stack([r[1] for r in rows])
    valid = np.isfinite(first[..., 0])
    pixels = np.stack([view.to_pixels(np.nan_to_num(f))[0] for f in first])
    pixels[~valid] = np.nan
    distance = np.where(valid, np.linalg.norm(points[None] - last, axis=2), np.nan)
    return Projection(groups=list(histories), reflector_points=first, valid=valid,
                      leaf_kind=np.where(valid, PERTURBATION_ANSWER, NOT_PROJECTED).astype(np.int8),
                      pixels=pixels, ray_distance=distance)
