# SPDX-License-Identifier: GPL-3.0-or-later
"""Refinement of a morphing blend on the local surface the nodes' images lie on.

The four nodes' first reflector points of one image, blended with the eye's weights,
lie near the mirror but not on it, and the reflection law does not hold there. A
quadric surface is fitted through the images of the cell's nodes (the tetrahedron's
cube: eight, or fewer where some lie inside the mirror; with their normals), and the
reflection point of the desired eye is solved on it by Newton's method; the refined
point replaces the blend where it stays within reach of the nodes' images
(:mod:`.morphing`, ``MorphingGrid._blend``; the GLSL twin is ``drawing/glsl/morph_blend.glsl``).
"""

from __future__ import annotations

import numpy as np

from ...geometry.spd_solve import solve_spd
from ...geometry.vectors import cross, unit

#: Nodes with an image (and a usable normal) a local surface is fitted to, at least.
MIN_SURFACE_NODES = 3
#: Newton iterations of the reflection law on the local quadric surface.
SURFACE_ITERATIONS = 8
#: The refined point may lie this far (in units of the nodes' images' spread) from the blend.
SURFACE_REACH = 2.0
#: Weight (squared) pulling the quadric's three terms in the height toward the sphere of
#: the quadratic's mean curvature (:func:`sphere_prior`), in the fit's normal equations:
#: where the nodes' images do not pin them (three nodes, images close together, images
#: off by the node cameras' accuracy, float32 on the GPU) the fit falls back toward that
#: sphere. Pulled toward zero (the paraboloid) instead, close views were biased by
#: more than a pixel; a stronger pull biases mirrors that are not spheres.
QUADRIC_RIDGE = 1e-2
#: The same weight where every node image is polished on the mirror (the scene's
#: *Polish Node Images*, ``image_polish.py``) and the fit reads a whole cube of nodes
#: (``MorphingGrid.locate_view``: 24 equations for 9 coefficients): the images then hold
#: no camera error to damp, and the pull would only bias mirrors that are not spheres.
#: The float32 blend on the GPU solves it as well
#: (tests/drawing/methods/test_morph_pass.py).
POLISHED_RIDGE = 1e-4
#: A node's image joins the surface fit where its normal is within about 78 degrees of
#: the nodes' weighted normal (cosine above this).
SURFACE_NORMAL_MIN = 0.2


def refine_on_local_surface(images, present, eyes, points, eye, weights, penalty=None):
    """The reflection point of ``eye`` on a quadric fitted to the nodes' images.

    Our refinement of the paper's blend (SBC VI blends the four first reflector points
    linearly, an error quadratic in the grid spacing). Each node's image x_i of point p
    seen from node eye n_i comes with the mirror normal there: by the law of reflection
    it bisects the directions to n_i and to p. Around the blend, in the frame (a, b, h)
    of the blended normal, a quadric written as a height field,

        h = c0 + c1 a + c2 b + c3 a^2/2 + c4 ab + c5 b^2/2 + c6 h^2 + c7 ah + c8 bh,

    is fitted (least squares, linear in c: 3 equations per node, the height and the
    two slopes the normal gives) to the images, and Newton's method finds the point of
    that surface where its normal bisects the directions to the desired eye and to p.
    The last three terms make the fit exact for any quadric mirror (a sphere, an
    ellipsoid, a cylinder), where the quadratic height field alone (c6 = c7 = c8 = 0)
    erred by many pixels on images spread over a sizeable part of a sphere (its height
    deviates from the osculating paraboloid by r^4 / 8R^3); on other surfaces they take
    up part of the third-order terms. ``QUADRIC_RIDGE`` holds them near a sphere's
    where the images do not pin them (``penalty``, default :data:`FIT_PENALTY`: the
    :func:`sphere_prior` of that weight). Needs MIN_SURFACE_NODES nodes (two give fewer equations
    than the quadratic's unknowns: measured, their fits are often wrong); where it fails
    or leaves the images' neighbourhood, ``ok`` is False.

    images (Q, N, 3), present (Q, N) bool, eyes (N, 3) node positions, points (Q, 3),
    eye (3,), weights (Q, N) (zero where absent, and for nodes that only join the fit);
    N nodes: a tetrahedron's 4 and the rest of its cube, 8 of an octree cell
    (``methods/octree``); ``penalty`` (9, 9). Returns (Q, 3) points, (Q,) ok, (Q, 3) the
    mirror normal there (fitted where ok, else the weighted one) and (Q, 3) the weighted
    normal of the images (the normal at the linear blend).
    """
    q = len(images)
    total = np.maximum(weights.sum(axis=1), 1e-300)
    origin = np.einsum("qn,qnd->qd", weights, images) / total[:, None]
    normals = law_normals(eyes[None], points[:, None], images)
    normal = unit(np.einsum("qn,qnd->qd", weights, normals))
    nz = np.einsum("qnd,qd->qn", normals, normal)
    usable = present & (nz > SURFACE_NORMAL_MIN)
    x, ok, fitted_normal = origin.copy(), np.zeros(q, bool), normal.copy()
    # Only rows with enough usable nodes are fitted (a point's empty image slots and
    # images seen by too few nodes are most rows of a drawn mesh's projection).
    rows = np.flatnonzero(usable.sum(axis=1) >= MIN_SURFACE_NODES)
    if len(rows):
        x[rows], ok[rows], fitted_normal[rows] = _fit_and_reflect(
            images[rows], present[rows], usable[rows], normals[rows], normal[rows], nz[rows], origin[rows],
            points[rows], eye, FIT_PENALTY if penalty is None else penalty)
    # Where the fit is not used, the weighted normal of the nodes' images stands for the
    # mirror's normal at the linear blend.
    return x, ok, np.where(ok[:, None], fitted_normal, normal), normal


def _fit_and_reflect(images, present, usable, normals, normal, nz, origin, points, eye, penalty):
    """:func:`refine_on_local_surface` for rows that have enough usable nodes: the
    height-field fit and Newton on it; returns (x, ok, fitted normal). Newton runs on the
    rows not yet converged only."""
    q = len(images)
    helper = np.where(np.abs(normal[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    t1 = unit(cross(normal, helper))
    t2 = cross(normal, t1)
    offset = images - origin[:, None]
    a, b, h = (np.einsum("qnd,qd->qn", offset, axis) for axis in (t1, t2, normal))
    spread = np.maximum(np.sqrt(np.max(np.where(present, a * a + b * b, 0.0), axis=1)), 1e-12)
    a, b, h = a / spread[:, None], b / spread[:, None], h / spread[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        slope_a = -np.einsum("qnd,qd->qn", normals, t1) / nz
        slope_b = -np.einsum("qnd,qd->qn", normals, t2) / nz
    zero, one = np.zeros_like(a), np.ones_like(a)
    slope_a, slope_b = np.nan_to_num(slope_a), np.nan_to_num(slope_b)
    # h = q + c6 h^2 + c7 ah + c8 bh at each image, and its slopes: F = h - q - c6 h^2 - c7 ah
    # - c8 bh has gradient (-q_a - c7 h, -q_b - c8 h, 1 - 2 c6 h - c7 a - c8 b) along the
    # normal, whose slope -n_a / n_h = -F_a / F_h is linear in c.
    rows = np.concatenate([
        np.stack([one, a, b, 0.5 * a * a, a * b, 0.5 * b * b, h * h, a * h, b * h], axis=2),
        np.stack([zero, one, zero, a, b, zero, 2 * slope_a * h, h + slope_a * a, slope_a * b], axis=2),
        np.stack([zero, zero, one, zero, a, b, 2 * slope_b * h, slope_b * a, h + slope_b * b], axis=2)],
        axis=1)  # (Q, 12, 9)
    rhs = np.concatenate([h, slope_a, slope_b], axis=1)
    mask = np.tile(usable, 3).astype(np.float64)
    rows, rhs = rows * mask[..., None], rhs * mask
    normal_matrix = np.einsum("qri,qrj->qij", rows, rows) + penalty
    coefficients = solve_spd(normal_matrix, np.einsum("qri,qr->qi", rows, rhs))

    def surface(k, u, v):
        height, du, dv = quadric_height(coefficients[k], u, v)
        x = origin[k] + spread[k, None] * (u[:, None] * t1[k] + v[:, None] * t2[k] + height[:, None] * normal[k])
        return x, t1[k] + du[:, None] * normal[k], t2[k] + dv[:, None] * normal[k]

    def residual(k, u, v):
        x, ta, tb = surface(k, u, v)
        bisector = unit(eye[None] - x) + unit(points[k] - x)
        return np.stack([np.einsum("qd,qd->q", bisector, ta), np.einsum("qd,qd->q", bisector, tb)], axis=1)

    u, v = np.zeros(q), np.zeros(q)
    active = np.arange(q)
    step = 1e-6
    for _ in range(SURFACE_ITERATIONS):
        ua, va = u[active], v[active]
        f = residual(active, ua, va)
        ju = (residual(active, ua + step, va) - f) / step
        jv = (residual(active, ua, va + step) - f) / step
        det = ju[:, 0] * jv[:, 1] - jv[:, 0] * ju[:, 1]
        det = np.where(np.abs(det) > 1e-300, det, 1e-300)
        du = (f[:, 0] * jv[:, 1] - jv[:, 0] * f[:, 1]) / det
        dv = (ju[:, 0] * f[:, 1] - f[:, 0] * ju[:, 1]) / det
        u[active], v[active] = np.clip(ua - du, -4.0, 4.0), np.clip(va - dv, -4.0, 4.0)
        # A step below 1e-13 (in units of the images' spread) changes nothing further.
        active = active[~((np.abs(du) < 1e-13) & (np.abs(dv) < 1e-13))]
        if len(active) == 0:
            break
    every = np.arange(q)
    x, ta, tb = surface(every, u, v)
    fitted_normal = unit(cross(ta, tb))
    fitted_normal *= np.where(np.einsum("qd,qd->q", fitted_normal, normal) < 0, -1.0, 1.0)[:, None]
    ok = ((np.abs(residual(every, u, v)).max(axis=1) < 1e-8) & (u * u + v * v <= SURFACE_REACH ** 2)
          & np.isfinite(x).all(axis=1))
    return x, ok, fitted_normal


def sphere_prior(weight: float) -> np.ndarray:
    """(9, 9) penalty added to the fit's normal equations: ``weight`` times
    (c6 - (c3 + c5) / 4)^2 + c7^2 + c8^2, plus 1e-10 on the diagonal (as every fit here).

    It pulls the quadric's three terms toward the sphere that has the quadratic's mean
    curvature: a sphere |x - C|^2 = R^2 in any frame (a, b, h) reads h = (a^2 + b^2 + h^2
    - 2 a C_a - 2 b C_b + const) / 2 C_h, so c3 = c5 = 2 c6 and c7 = c8 = 0. A pull
    toward zero (the paraboloid) instead biased close views, whose nodes' images spread
    over a large part of the mirror, by 1.5 px on a sphere.
    """
    row = np.zeros(9)
    row[[3, 5, 6]] = -0.25, -0.25, 1.0
    return weight * (np.outer(row, row) + np.diag([0.0] * 7 + [1.0, 1.0])) + 1e-10 * np.eye(9)


FIT_PENALTY = sphere_prior(QUADRIC_RIDGE)


def law_normals(eyes, points, images):
    """The mirror's normal the law of reflection gives each image x of a point p seen
    from an eye n: the bisector of the directions from x to n and to p (``eyes`` and
    ``points`` broadcast against ``images``)."""
    return unit(unit(np.asarray(eyes, dtype=np.float64) - images) + unit(points - images))


def quadric_height(c, u, v):
    """Height h(u, v) of the fitted quadric (:func:`refine_on_local_surface`; c (Q, 9))
    and its slopes (h_u, h_v): the root of c6 h^2 - (1 - c7 u - c8 v) h + q(u, v) = 0
    near q, written 2q / (B + sqrt(B^2 - 4 c6 q)), which does not cancel when c6 is
    small; the slopes by implicit differentiation."""
    quadratic = c[:, 0] + c[:, 1] * u + c[:, 2] * v + 0.5 * c[:, 3] * u * u + c[:, 4] * u * v + 0.5 * c[:, 5] * v * v
    linear = 1.0 - c[:, 7] * u - c[:, 8] * v
    height = 2.0 * quadratic / (linear + np.sqrt(np.maximum(linear * linear - 4.0 * c[:, 6] * quadratic, 0.0)))
    along_h = linear - 2.0 * c[:, 6] * height
    du = (c[:, 1] + c[:, 3] * u + c[:, 4] * v + c[:, 7] * height) / along_h
    dv = (c[:, 2] + c[:, 4] * u + c[:, 5] * v + c[:, 8] * height) / along_h
    return height, du, dv
