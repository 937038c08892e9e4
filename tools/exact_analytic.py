# SPDX-License-Identifier: GPL-3.0-or-later
"""The exact reference on declared exact surfaces (spheres, ellipsoids).

``engine/reference/exact.py`` and ``exact_paths.py`` solve the reflection law on the mesh
(flat triangles, interpolated normals): the yard stick of every method on meshes. A
reflector declared an exact surface
(``engine.methods.perturbation.quadrics.AnalyticSurface``) reflects off the surface itself,
which the mesh only approximates; measured against the mesh, a method that uses the true
surface would be charged with the tessellation's error. Here each of the mesh's solutions
(found, with its visibility, by the mesh solvers) is polished onto the true surface by
Newton's method on the Lagrange system of Chen & Arvo (2000, eq. 5;
``path_derivatives.newton``, each bounce's quadric osculating the surface at the current
point: exact for spheres and ellipsoids, refreshed every step on a superquadric), which
converges quadratically from the mesh's nearby answer. Visibility stays the mesh's. A test
and benchmark reference, not shipped.
"""

from __future__ import annotations

import numpy as np

from ..engine.methods.perturbation.path_derivatives import Paths, newton, optimal_multipliers
from ..engine.view import View

#: Newton steps of the polish (quadratic convergence from the mesh's answer; a
#: superquadric's osculating quadric is refreshed at each).
POLISH_ITERATIONS = 12


def polish_on_surfaces(surfaces: dict, view: View, points: np.ndarray, reflector_points: np.ndarray,
                       histories: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact paths on the surfaces, from the mesh's: ``points`` (S, 3) the scene points,
    ``reflector_points`` (S, N, 3) and ``histories`` (S, N) the mesh paths' bounces in
    the eye's order (first the point the eye sees), every bounce's reflector in
    ``surfaces`` ({reflector index: AnalyticSurface}). Returns the polished reflector
    points (S, N, 3), the pixels where the first appears (S, 2) and (S,) bool converged."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    reflector_points = np.asarray(reflector_points, dtype=np.float64).reshape(len(points), -1, 3)
    histories = np.asarray(histories).reshape(len(points), -1)
    n = histories.shape[1]
    reverse = slice(None, None, -1)  # Chen-Arvo order: y_1 next to the scene point
    owners = histories[:, reverse]

    def osculate(paths: Paths) -> Paths:
        hessian, linear = np.zeros((len(points), n, 3, 3)), np.zeros((len(points), n, 3))
        constant = np.zeros((len(points), n))
        for index, surface in surfaces.items():
            on = owners == index
            if on.any():
                rows = surface.osculating(paths.reflector_points[on])
                hessian[on], linear[on], constant[on] = rows.hessian, rows.linear, rows.constant
        return Paths(paths.scene_points, paths.reflector_points, paths.multipliers, hessian, linear, constant,
                     paths.eye, paths.orthographic)

    paths = osculate(Paths(points, reflector_points[:, reverse], np.zeros((len(points), n)),
                           np.zeros((len(points), n, 3, 3)), np.zeros((len(points), n, 3)), np.zeros((len(points), n)),
                           view.eye if view.is_perspective else view.backward, not view.is_perspective))
    paths = paths.with_points(multipliers=optimal_multipliers(paths))
    solved, converged = newton(paths, iterations=POLISH_ITERATIONS, osculate=osculate)
    polished = solved.reflector_points[:, reverse]
    pixels, _ = view.to_pixels(polished[:, 0]) if len(points) else (np.zeros((0, 2)), None)
    return polished, pixels, converged
