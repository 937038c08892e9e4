# SPDX-License-Identifier: GPL-3.0-or-later
"""The Taylor step from a seed path to a target point, and whether it is trusted
(Chen & Arvo 2000, section III, eq. 4).

From the point on the seed's reflected ray nearest the target (its *foot*), the path
Jacobian and Hessian (``path_derivatives.perturb``) move the path's reflector points so
that it reaches the target; the image moves by e1 pixels to first order and e2 more to
second. The error estimate is the series' next term, e2^2 / e1 (at most e2), and on a
mesh, whose quadric only osculates it, MODEL_SAFETY times the seed's model error times
e1. A step is trusted (a finite estimate) only when it is local (``reach_px`` from its
seed's pixel), short against the path (MAX_RELATIVE_STEP), reaches the target before
the next reflector on the ray, and lands on the side of the surface its seed shows the
eye, as a reflection does. ``projector.py`` takes the steps;
``drawing/glsl/perturbation_step.glsl`` (``take_step``) is their float32 twin.
"""

from __future__ import annotations

import numpy as np

from ...geometry.vectors import dot
from ...view import View
from .path_derivatives import perturb
from .seeds import SeedPaths, seed_paths_to

#: The longest step trusted, against the distance from the seed's last bounce (radians).
MAX_RELATIVE_STEP = 0.3
#: A target behind its seed's reflected ray steps from this share of its distance along it.
BEHIND_START = 0.1
#: Factor on the mesh model's error term of a step's estimate (``projector._model_errors``).
MODEL_SAFETY = 2.0


def taylor_step(view: View, seeds: SeedPaths, quadrics: list, targets, seed_of, model_error, reach_px):
    """The Taylor step from seeds ``seed_of`` to ``targets``: first and last reflector
    points (K, 3), the error estimate (px) and the pixel (K, 2), NaN where the target
    lies beyond the next reflector on the seed's reflected ray (blocked: the seed
    cannot lead to an image). ``model_error`` (K,): how far each seed's quadrics miss
    the surface (``projector._model_errors``); ``reach_px``: the longest step trusted
    (``projector.REACH`` seed spacings)."""
    paths, foot, along = _paths_toward(view, seeds, quadrics, targets, seed_of)
    step = perturb(paths, targets)
    seen = paths.reflector_points[:, -1]
    moves = (0.0, step.first[:, -1], step.first[:, -1] + step.second[:, -1])
    at = [view.to_pixels(seen + move)[0] for move in moves]
    e1 = np.linalg.norm(at[1] - at[0], axis=1)
    e2 = np.linalg.norm(at[2] - at[1], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        estimate = np.where(e2 > 0, e2 * e2 / np.maximum(e1, e2), np.where(e2 == 0, 0.0, np.inf))
    # On a mesh the quadric is only osculating: its series says nothing of where the
    # mesh bends differently. The image moves by e1; the normals it moves over turn
    # by a share ``model_error`` other than the quadric's, and so does the image.
    estimate = np.maximum(estimate, MODEL_SAFETY * model_error * e1)
    # A step is local: it may not carry the image farther than ``reach_px`` from its
    # seed's pixel (farther, the series is taken past a fold or off the mirror).
    local = np.linalg.norm(at[2] - seeds.pixels[seed_of], axis=1) <= reach_px
    # Nor may it be long against the path: at a grazing edge a long step moves the
    # image by little, and its series looks converged in pixels while the point has
    # no image there at all.
    short = np.linalg.norm(targets - foot, axis=1) <= MAX_RELATIVE_STEP * np.maximum(along, 0.0)
    reachable = along < seeds.head[seed_of]
    moved = step.points(paths)
    estimate = np.where(reachable & local & short & _reflects(paths, moved, targets) & _faces_eye(paths, moved),
                        estimate, np.inf)
    return moved[:, -1], moved[:, 0], estimate, np.where(reachable[:, None], at[2], np.nan)


def first_order_pixels(view: View, seeds: SeedPaths, quadrics: list, targets, seed_of) -> np.ndarray:
    """(K, 2) where a first-order step from seeds ``seed_of`` puts ``targets`` (hops)."""
    paths, _, _ = _paths_toward(view, seeds, quadrics, targets, seed_of)
    return view.to_pixels(paths.reflector_points[:, -1] + perturb(paths, targets, order=1).first[:, -1])[0]


def _paths_toward(view, seeds: SeedPaths, quadrics: list, targets, seed_of):
    """The seeds ``seed_of`` as paths to the points on their reflected rays nearest the
    ``targets`` (the feet the steps start from), the feet and the targets' distances
    along the rays."""
    tail, direction = seeds.points[seed_of, -1], seeds.outgoing[seed_of]
    along = np.einsum("ki,ki->k", targets - tail, direction)
    # A target behind the ray's start (a fast-spreading fan: a small second-order
    # image) steps from a point a little way along the ray: a long step, not trusted,
    # but it points the adaptive seeds the right way.
    reach = np.maximum(along, BEHIND_START * np.linalg.norm(targets - tail, axis=1))
    foot = tail + reach[:, None] * direction
    paths = seed_paths_to(seeds.select(seed_of), [q.take(seed_of) for q in quadrics], view, foot)
    return paths, foot, along


def _reflects(paths, moved, targets) -> np.ndarray:
    """(K,) bool: at every moved bounce the path arrives and leaves on the same side of
    the surface (its quadric's tangent plane), as a reflection does. A step carried
    past the silhouette lands on the far side, where the eye cannot see it."""
    k = len(targets)
    before = np.concatenate([np.asarray(targets)[:, None], moved[:, :-1]], axis=1)
    if paths.orthographic:
        after_direction = np.concatenate([moved[:, 1:] - moved[:, :-1], np.broadcast_to(paths.eye, (k, 1, 3))], axis=1)
    else:
        after_direction = np.concatenate([moved[:, 1:], np.broadcast_to(paths.eye, (k, 1, 3))], axis=1) - moved
    normal = paths.gradients(moved)
    arrive = np.einsum("kni,kni->kn", normal, before - moved)
    leave = np.einsum("kni,kni->kn", normal, after_direction)
    return (arrive * leave > 0).all(axis=1)


def _faces_eye(paths, moved) -> np.ndarray:
    """(K,) bool: the moved point the eye sees lies on the side of the surface its seed's
    point shows the eye. :func:`_reflects` holds on a convex mirror's far side too (eye
    and point both behind the tangent plane), where a step carried past the silhouette
    lands and the eye cannot see: the quadric's normal there, oriented along the seed's
    (a step is local), must face the eye as the seed's does."""
    def to_eye(points):
        return np.broadcast_to(paths.eye, points.shape) if paths.orthographic else paths.eye - points

    seen, moved_seen = paths.reflector_points[:, -1], moved[:, -1]
    seed_normal = paths.gradients(paths.reflector_points)[:, -1]
    normal = paths.gradients(moved)[:, -1]
    normal = normal * np.where(dot(normal, seed_normal) < 0.0, -1.0, 1.0)[:, None]
    return dot(normal, to_eye(moved_seen)) * dot(seed_normal, to_eye(seen)) > 0.0
