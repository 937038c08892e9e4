# SPDX-License-Identifier: GPL-3.0-or-later
"""A method's accuracy in the current view, measured on a few of its answers.

Every method answers with first reflector points; whichever drew a reflector, a handful
of its answers (a seeded sample of vertices that have one) are checked against exactly
traced rays: the answer's pixel starts Gauss-Newton on the true reflection law of the
mesh (``true_rays.polish_on_true_rays``, the iteration Roger & Holzschuch 2006, section
3.2, use to find reflections), which converges to the exact reflection nearest to it.
The distance between the two pixels is the answer's error. An answer whose iteration
does not converge within MAX_ERROR_PX (no true reflection near it: a reflection drawn
where there is none, or one off by more) is counted as *unconfirmed*. A few hundred
traced rays.

Only answers the picture shows are measured (:func:`shown_answers`): the renderer's
fragment stage drops a reflected fragment whose pixel sees another mirror, or where the
eye's ray, reflected at the mirror point it sees there, leaves far from the fragment's
point of the mesh (``drawing/reflected_meshes.py``), as a blend's answers for points
with no reflection are. The check does the same with the exact mirror point.

It also measures what is missing (:func:`coverage_check`): a method that finds one image
per point (the iterative search on a folded mirror) or none near a fold leaves some of
the mirror's reflections out, and its drawn answers all check out. A seeded sample of the
points answered for is solved exactly (``reference/exact.py``: every visible first-order
reflection on the reflector), and an exact image with no drawn answer within
:data:`COVERED_PX` is *missed*. Images seen at a grazing angle (the band along the
mirror's silhouette, which a render traces and the viewport fills) are not counted. The
sample is taken per object and half among the points nearest the mirror
(:func:`checked_points`): an object almost touching a mirror has few vertices and large
reflections, and is where methods leave images out (contact).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry.raytrace import ReflectorSet, reflect
from .reference.exact import solve_reflections
from .reference.true_rays import polish_on_true_rays
from .view import View

#: Answers checked per reflector and view.
SAMPLE = 96
#: An answer more than this many pixels from every exact reflection is unconfirmed.
MAX_ERROR_PX = 12.0
#: Points a check looks at per reflector and view (:func:`checked_points`): its answers
#: and exact images are sampled among them.
POOL = 1024
#: Mirror vertices the distances of :func:`checked_points` are measured to (a sample).
NEAR_VERTICES = 256
#: Points solved exactly per reflector and view for the coverage count: their visible
#: images on the reflector are the ones counted (one to three per point).
COVERAGE_SAMPLE = 96
#: An exact image with a drawn answer of its point this close (px) is drawn: the images
#: of one point in a fold lie tens of pixels apart, a method's error is below one.
COVERED_PX = 4.0
#: An exact image whose eye ray meets the mirror at a cosine below this (about 76
#: degrees from the normal) lies in the band along the silhouette (on a ball 100 px
#: across, its outer 3 px: cos ~ sqrt(2 d / r)), which a render traces and a viewport
#: fills, and where images crowd into few pixels: not counted.
GRAZING_COSINE = 0.25
#: A method is within an Accuracy when at most this share of its checked answers lies
#: beyond it (unconfirmed ones count as beyond): a percentile, p95, not the worst one.
MAX_OFF_SHARE = 0.05
#: A method draws a mirror right when at most this share of its exact images is missed
#: (as many as :data:`MAX_OFF_SHARE` of its answers may be off), ...
MAX_MISSED_SHARE = 0.05
#: ... or, of one object's, more than MAX_OBJECT_MISSED_SHARE and at least MIN_MISSED
#: of at least MIN_GROUP_IMAGES (an object seen only along the mirror's rim, a few
#: images, is judged with the rest). Measured on sbc_fig3's cube 3 % of the radius from
#: the ball: the iterative search misses up to 6 % of its sampled images near the
#: contact, perturbation 10-15 %; a small sample's one or two misses are noise.
MAX_OBJECT_MISSED_SHARE = 0.1
MIN_MISSED = 3
MIN_GROUP_IMAGES = 8
#: Points of each object solved exactly for the coverage count (``groups``), drawn at
#: random: the exact solver costs about a millisecond a point on a curved mirror of 20k
#: triangles, so most objects get a few ...
GROUP_SAMPLE = 8
#: ... and an object within CONTACT_SHARE of the mirror's size of it (contact, where
#: methods leave a tenth of an object's images out) this many.
CONTACT_SAMPLE = 48
CONTACT_SHARE = 0.1


@dataclass(frozen=True)
class SpotCheck:
    """Errors (desired-view px) of the answers checked for one reflector in one view."""

    checked: int  # answers checked
    errors: np.ndarray  # (confirmed,) px from each confirmed answer to the exact reflection
    images: int = 0  # exact images of the coverage sample (:func:`coverage_check`) ...
    missed: int = 0  # ... with no drawn answer within COVERED_PX
    missed_in: str = ""  # the object those are of, where one object fails ("": all of them)

    @property
    def confirmed(self) -> int:
        return len(self.errors)

    @property
    def unconfirmed(self) -> int:
        return self.checked - self.confirmed

    def percentile(self, q: float) -> float:
        return float(np.percentile(self.errors, q)) if len(self.errors) else float("nan")

    def within(self, accuracy_px: float) -> bool:
        """Whether all but :data:`MAX_OFF_SHARE` of the checked answers lie within
        ``accuracy_px`` of an exact reflection (unconfirmed ones count as beyond it), and
        the answers miss at most :data:`MAX_MISSED_SHARE` of the exact images counted. A view that shows no
        reflection to check passes: a method that draws nothing where images are is
        failed by the images it misses (:func:`coverage_check`), not by the silence."""
        return (np.count_nonzero(self.errors <= accuracy_px) >= (1.0 - MAX_OFF_SHARE) * self.checked
                and self.missed <= MAX_MISSED_SHARE * self.images)

    def with_coverage(self, coverage: Coverage, missed_in: str = "") -> "SpotCheck":
        """This check with the count of :func:`coverage_check` (``missed_in``: the name of
        its group, the object, when it is one's)."""
        return SpotCheck(self.checked, self.errors, coverage.images, coverage.missed, missed_in)

    def _of(self) -> str:
        return f" of {self.missed_in}" if self.missed_in else ""

    def shortfall(self) -> str:
        """Why the check fails an Accuracy, for the panel: the images it left out, else its error."""
        if self.missed > MAX_MISSED_SHARE * self.images:
            return f"{self.missed} of {self.images} exact images{self._of()} not drawn"
        if self.unconfirmed > MAX_OFF_SHARE * self.checked:
            return f"{self.unconfirmed} of {self.checked} answers more than {MAX_ERROR_PX:.0f} px off or not there"
        return f"p95 {self.percentile(95):.2f} px" if self.confirmed else "no answer confirmed"

    def summary(self) -> str:
        """One panel line, e.g. ``p95 0.31 px, max 0.84 px (96 checked)``."""
        if self.checked == 0:
            return "no reflection to check in this view"
        text = (f"p95 {self.percentile(95):.2f} px, max {self.errors.max():.2f} px" if self.confirmed
                else "no answer confirmed")
        text += f" ({self.checked} checked"
        if self.unconfirmed:
            text += f", {self.unconfirmed} more than {MAX_ERROR_PX:.0f} px off or not there"
        if self.missed:
            text += f"; {self.missed} of {self.images} exact images{self._of()} not drawn"
        return text + ")"


def _on_screen(view: View, pixels: np.ndarray) -> np.ndarray:
    """(N,) bool: the pixel positions (N, 2) lie in the image (an answer off it is not
    drawn, and its exact reflection, off the image too, cannot be traced)."""
    with np.errstate(invalid="ignore"):
        return ((pixels >= 0.0) & (pixels <= (view.width, view.height))).all(axis=1)


def spot_check(reflector_set: ReflectorSet, view: View, reflector_index: int, points: np.ndarray,
               answers: np.ndarray, sample: int = SAMPLE, seed: int = 0) -> SpotCheck:
    """Check up to ``sample`` of a method's first-order answers on the image for one reflector.

    ``points`` (P, 3) are the vertices the method answered for, ``answers`` (K, P, 3) its
    first reflector points in world space per image slot, NaN where none (the layout of
    every GPU pass's answer textures and of ``Projection.reflector_points``).
    """
    answers = np.asarray(answers, dtype=np.float64).reshape(-1, len(points), 3)
    slot, vertex = np.nonzero(np.isfinite(answers[..., 0]))
    pixels, _ = view.to_pixels(answers[slot, vertex])
    on_screen = _on_screen(view, pixels)
    pixels, vertex = pixels[on_screen], vertex[on_screen]
    if len(vertex) == 0:
        return SpotCheck(0, np.zeros(0))
    chosen = np.random.default_rng(seed).choice(len(vertex), size=min(sample, len(vertex)), replace=False)
    pixels, vertex = pixels[chosen], vertex[chosen]
    exact, _, _, ok = polish_on_true_rays(reflector_set, view, reflector_index, pixels, points[vertex],
                                          cell_px=MAX_ERROR_PX / 12.0)
    errors = np.linalg.norm(exact - pixels, axis=1)
    return SpotCheck(len(vertex), errors[ok & (errors <= MAX_ERROR_PX)])


@dataclass(frozen=True)
class Coverage:
    """Exact images counted and missed (:func:`coverage_check`): of the worst group of
    points (``group``: an object) where one misses more than
    :data:`MAX_OBJECT_MISSED_SHARE` of its images, else of all of them (``group`` -1)."""

    images: int
    missed: int
    group: int = -1


def coverage_check(reflector_set: ReflectorSet, view: View, reflector_index: int, points: np.ndarray,
                   answers: np.ndarray, sample: int = COVERAGE_SAMPLE, seed: int = 0,
                   groups: np.ndarray | None = None, distances: np.ndarray | None = None,
                   contact_distance: float = 0.0, band_px: int = 0) -> Coverage:
    """The exact images a method's first-order answers for one reflector leave out.

    ``points`` and ``answers`` as :func:`spot_check`: every point the method answered
    for (with an answer or not), its answers per image slot. Up to ``sample`` points
    (seeded) are solved exactly, or with ``groups`` ((P,) int: each point's object) up
    to :data:`GROUP_SAMPLE` of each group's, :data:`CONTACT_SAMPLE` of a group with a
    point within ``contact_distance`` of the mirror (``distances``, (P,):
    :func:`mirror_distances`): a method that fails on one object (the near face of a
    cube almost touching the mirror) fails there, however small the object. Each
    visible, not grazing, exact image of a chosen point on this reflector is missed
    unless an answer of the same point lies within :data:`COVERED_PX` of it on screen,
    or, with ``band_px``, it lies within that many pixels of the reflector's outline (a
    sample-based camera's band, which a render ray traces: :func:`near_outline`).
    """
    points = np.asarray(points, dtype=np.float64)
    answers = np.asarray(answers, dtype=np.float64).reshape(-1, len(points), 3)
    rng = np.random.default_rng(seed + 1)
    if groups is None:
        chosen = rng.choice(len(points), size=min(sample, len(points)), replace=False)
    else:
        groups = np.asarray(groups)
        chosen = _per_object_sample(groups, distances, contact_distance, rng)
    if len(chosen) == 0:
        return Coverage(0, 0)
    exact = solve_reflections(reflector_set, view, points[chosen])
    exact = exact.select(exact.visible & (exact.reflector == reflector_index))
    if len(exact.point) == 0:
        return Coverage(0, 0)
    _, directions = view.pixel_rays(exact.pixel)
    exact = exact.select(np.abs(np.einsum("ij,ij->i", exact.normal, directions)) >= GRAZING_COSINE)
    drawn, _ = view.to_pixels(answers[:, chosen[exact.point]].reshape(-1, 3))
    drawn = drawn.reshape(len(answers), len(exact.point), 2)
    distance = np.linalg.norm(drawn - exact.pixel[None], axis=2)  # (K, S), NaN where no answer
    missed = ~(np.nan_to_num(distance, nan=np.inf) <= COVERED_PX).any(axis=0)
    if band_px > 0 and missed.any():
        missed[missed] = ~near_outline(reflector_set, view, reflector_index, exact.pixel[missed], band_px)
    worst = Coverage(len(missed), int(np.count_nonzero(missed)))
    group_of = None if groups is None else groups[chosen[exact.point]]
    for group in () if groups is None else np.unique(group_of):
        mine = group_of == group
        counted = Coverage(int(np.count_nonzero(mine)), int(np.count_nonzero(missed & mine)), int(group))
        if counted.images >= MIN_GROUP_IMAGES and counted.missed >= MIN_MISSED and \
                counted.missed > MAX_OBJECT_MISSED_SHARE * counted.images and (
                worst.group < 0 or counted.missed * worst.images > worst.missed * counted.images):
            worst = counted
    return worst


def near_outline(reflector_set: ReflectorSet, view: View, reflector_index: int, pixels: np.ndarray,
                 radius: int) -> np.ndarray:
    """(N,) bool: whether a pixel within ``radius`` (Chebyshev, as
    ``band_trace.band_pixels`` picks a render's band) of each of ``pixels`` sees
    something other than this reflector: the eye rays of the square's corners and edge
    midpoints."""
    offsets = radius * np.array([(dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy], np.float64)
    around = (np.asarray(pixels, np.float64)[:, None] + offsets[None]).reshape(-1, 2)
    origins, directions = view.pixel_rays(around)
    hits = reflector_set.intersect(origins, directions)
    return (hits.reflector != reflector_index).reshape(len(pixels), len(offsets)).any(axis=1)


def _per_object_sample(groups: np.ndarray, distances: np.ndarray | None, contact_distance: float,
                       rng) -> np.ndarray:
    """Indices of :data:`GROUP_SAMPLE` points of each group drawn at random, or
    :data:`CONTACT_SAMPLE` of a group with a point within ``contact_distance`` of the
    mirror (``distances``)."""
    picked = []
    for group in np.unique(groups):
        members = np.flatnonzero(groups == group)
        near = distances is not None and distances[members].min() <= contact_distance
        size = min(CONTACT_SAMPLE if near else GROUP_SAMPLE, len(members))
        picked.append(rng.choice(members, size=size, replace=False))
    return np.concatenate(picked) if picked else np.zeros(0, np.int64)


def shown_answers(reflector_set: ReflectorSet, view: View, reflector_index: int, points: np.ndarray,
                  answers: np.ndarray, reflection_cosine: float, hidden_fraction: float) -> np.ndarray:
    """``answers`` (K, P, 3) with NaN where the renderer would not show them: the eye's
    ray through the answer's pixel meets another reflector first (or none); or the
    answer lies behind the mirror point it meets, farther from the eye by more than
    ``hidden_fraction`` of the reflector's bounding-box diagonal (the fragment stage's
    hidden-point test, ``FramePass.hidden_fraction``: the far side of a ball); or the
    ray, reflected at that point, leaves more than ``reflection_cosine`` away from the
    direction to the answer's point of the mesh (its law-of-reflection test,
    ``reflected_meshes.REFLECTION_COSINE``)."""
    answers = np.array(answers, dtype=np.float64).reshape(-1, len(points), 3)
    slot, vertex = np.nonzero(np.isfinite(answers[..., 0]))
    if len(vertex) == 0:
        return answers
    pixels, _ = view.to_pixels(answers[slot, vertex])
    on_screen = _on_screen(view, pixels)
    origins, directions = view.pixel_rays(np.where(on_screen[:, None], pixels, 0.0))
    hits = reflector_set.intersect(origins, directions)
    corners = reflector_set.reflectors[reflector_index].vertices
    diagonal = float(np.linalg.norm(corners.max(axis=0) - corners.min(axis=0)))
    behind = np.einsum("ij,ij->i", answers[slot, vertex] - origins, directions) - hits.t > hidden_fraction * diagonal
    to_point = points[vertex] - hits.position
    to_point /= np.maximum(np.linalg.norm(to_point, axis=1, keepdims=True), 1e-300)
    with np.errstate(invalid="ignore"):
        cosine = np.einsum("ij,ij->i", reflect(directions, hits.normal), to_point)
        shown = on_screen & (hits.reflector == reflector_index) & ~behind & (cosine >= reflection_cosine)
    answers[slot[~shown], vertex[~shown]] = np.nan
    return answers


def mirror_distances(points: np.ndarray, mirror_vertices: np.ndarray, seed: int = 0) -> np.ndarray:
    """(P,) each point's distance to the nearest of :data:`NEAR_VERTICES` of the mirror's
    vertices (drawn at random, seeded): how near it is to the mirror, roughly."""
    rng = np.random.default_rng(seed)
    mirror = np.asarray(mirror_vertices, np.float64)
    mirror = mirror[rng.choice(len(mirror), size=min(len(mirror), NEAR_VERTICES), replace=False)]
    mirror_squares = np.einsum("ij,ij->i", mirror, mirror)
    squared = np.empty(len(points))
    for first in range(0, len(points), 4096):
        chunk = np.asarray(points[first:first + 4096], np.float64)
        # |p - m|^2 = |p|^2 - 2 p.m + |m|^2, the nearest sampled vertex's.
        squared[first:first + 4096] = (np.einsum("ij,ij->i", chunk, chunk)
                                       + (mirror_squares[None] - 2.0 * chunk @ mirror.T).min(axis=1))
    return np.sqrt(np.maximum(squared, 0.0))


def checked_points(distances: np.ndarray, size: int = POOL, seed: int = 0) -> np.ndarray:
    """Indices (sorted) of up to ``size`` points that a check looks at, of points at
    ``distances`` from the mirror (:func:`mirror_distances`): half drawn at random, half
    the nearest. Objects almost touching a mirror are where methods fail (contact: a
    near face left out), and they have few vertices but large reflections: a uniform
    sample alone would rarely meet them."""
    if len(distances) <= size:
        return np.arange(len(distances))
    uniform = np.random.default_rng(seed).choice(len(distances), size=size // 2, replace=False)
    nearest = np.argsort(distances, kind="stable")
    near = nearest[~np.isin(nearest, uniform)][:size - len(uniform)]
    return np.sort(np.concatenate([uniform, near]))
