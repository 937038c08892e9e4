# SPDX-License-Identifier: GPL-3.0-or-later
"""Path Jacobians and Hessians of reflection paths (Chen & Arvo 2000, section II).

A reflection path runs from the scene point p = y_0 over the reflector points y_1 ...
y_N (y_1 next to p, y_N the point the eye sees) to the eye y_{N+1}. By Fermat's
principle it makes the optical length stationary on the surfaces g_i(y) = 0; with
Lagrange multipliers (eq. 5) the path solves F(z; p) = 0, F the gradient over
z = (y_1, lambda_1, ..., y_N, lambda_N) of

    Lambda(z; p) = sum_i |y_{i+1} - y_i| + sum_i lambda_i g_i(y_i).

By the implicit function theorem (eq. 6) a step dp moves the path by dz = -A^-1 T dp,
A = dF/dz (4N x 4N), T = dF/dp: the path Jacobian applied to dp. Differentiating
F(z(p), p) = 0 once more gives the path Hessian applied to dp twice (eqs. 10-14):
A d2z = -Lambda'''[., w, w] with w = (dz, dp). The paper runs these as a recursion
from the eye back to p (eq. 7, ``SimpleJac`` / ``SimpleHess`` of section III-C.2),
which is the block elimination of A's block-tridiagonal system; here the whole
system of a path is solved at once, and only along the one direction dp that a
vertex needs (the Taylor step of eq. 1 uses H only as dp^T H dp), so a path costs
two 4N x 4N solves instead of the full third-order tensor.

Every surface is a quadric, g(y) = y^T Q y / 2 + b . y + c: exactly for the analytic
reflectors (sphere, ellipsoid), and the osculating quadric at the path's point for a
mesh (:mod:`.quadrics`). Its third derivatives vanish, so the only third derivatives
are those of the segment lengths: for l = |b - a|, u = (b - a) / l, P = I - u u^T,

    d3l / db3 [., D, D] = -(u (D^T P D) + 2 P D (u . D)) / l^2,   D = db - da,

with a sign flip for each derivative taken with respect to a. An orthographic view's
eye is at infinity: its segment has u = the view's backward axis and 1 / l = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Paths:
    """K reflection paths of N bounces, each bounce on a quadric, in Chen-Arvo's order."""

    scene_points: np.ndarray  # (K, 3) y_0, where the path ends in the scene
    reflector_points: np.ndarray  # (K, N, 3) y_1 (next to the scene point) ... y_N (seen by the eye)
    multipliers: np.ndarray  # (K, N) lambda_i
    hessians: np.ndarray  # (K, N, 3, 3) Q_i of each bounce's quadric
    linear: np.ndarray  # (K, N, 3) b_i
    constant: np.ndarray  # (K, N) c_i
    eye: np.ndarray  # (3,) the eye, or the backward axis when ``orthographic``
    orthographic: bool = False

    @property
    def bounces(self) -> int:
        return self.reflector_points.shape[1]

    def gradients(self, points=None) -> np.ndarray:
        """(K, N, 3) grad g_i at ``points`` (the path's reflector points by default)."""
        y = self.reflector_points if points is None else points
        return np.einsum("knij,knj->kni", self.hessians, y) + self.linear

    def values(self, points=None) -> np.ndarray:
        """(K, N) g_i at ``points``."""
        y = self.reflector_points if points is None else points
        return 0.5 * np.einsum("kni,knij,knj->kn", y, self.hessians, y) + np.einsum("kni,kni->kn", self.linear, y) \
            + self.constant

    def with_points(self, scene_points=None, reflector_points=None, multipliers=None) -> "Paths":
        return Paths(self.scene_points if scene_points is None else scene_points,
                     self.reflector_points if reflector_points is None else reflector_points,
                     self.multipliers if multipliers is None else multipliers,
                     self.hessians, self.linear, self.constant, self.eye, self.orthographic)


def _segments(paths: Paths):
    """Unit directions (K, N+1, 3) and inverse lengths (K, N+1) of the segments y_i -> y_{i+1}."""
    k = len(paths.scene_points)
    start = np.concatenate([paths.scene_points[:, None], paths.reflector_points], axis=1)
    if paths.orthographic:
        step = start[:, 1:] - start[:, :-1]
        inverse = np.zeros((k, paths.bounces + 1))
        length = np.linalg.norm(step, axis=2)
        inverse[:, :-1] = 1.0 / np.maximum(length, 1e-300)
        unit = np.empty_like(start)
        unit[:, :-1] = step * inverse[:, :-1, None]
        unit[:, -1] = paths.eye
        return unit, inverse
    end = np.concatenate([paths.reflector_points, np.broadcast_to(paths.eye, (k, 1, 3))], axis=1)
    step = end - start
    length = np.linalg.norm(step, axis=2)
    inverse = 1.0 / np.maximum(length, 1e-300)
    return step * inverse[:, :, None], inverse


def optimal_multipliers(paths: Paths) -> np.ndarray:
    """(K, N) the lambda_i that best solve F_y = 0 at the path's points (least squares):
    lambda_i grad g_i = u_{i,i+1} - u_{i-1,i}."""
    unit, _ = _segments(paths)
    turn = unit[:, 1:] - unit[:, :-1]
    gradient = paths.gradients()
    return np.einsum("kni,kni->kn", turn, gradient) / np.maximum(np.einsum("kni,kni->kn", gradient, gradient), 1e-300)


def system(paths: Paths):
    """The Lagrange system at the path: residual F (K, 4N), A = dF/dz (K, 4N, 4N), and
    the segments (unit directions, inverse lengths) it was built from."""
    k, n = len(paths.scene_points), paths.bounces
    unit, inverse = _segments(paths)
    projector = np.eye(3) - unit[..., :, None] * unit[..., None, :]
    bend = projector * inverse[..., None, None]  # (K, N+1, 3, 3) d2 l / db2
    gradient = paths.gradients()
    residual = np.zeros((k, n, 4))
    residual[:, :, :3] = unit[:, :-1] - unit[:, 1:] + paths.multipliers[..., None] * gradient
    residual[:, :, 3] = paths.values()
    a = np.zeros((k, n, 4, n, 4))
    for i in range(n):
        a[:, i, :3, i, :3] = bend[:, i] + bend[:, i + 1] + paths.multipliers[:, i, None, None] * paths.hessians[:, i]
        a[:, i, :3, i, 3] = gradient[:, i]
        a[:, i, 3, i, :3] = gradient[:, i]
        if i + 1 < n:
            a[:, i, :3, i + 1, :3] = -bend[:, i + 1]
            a[:, i + 1, :3, i, :3] = -bend[:, i + 1]
    return residual.reshape(k, 4 * n), a.reshape(k, 4 * n, 4 * n), unit, inverse


def _third_derivative(paths: Paths, unit, inverse, moves: np.ndarray, multiplier_moves: np.ndarray) -> np.ndarray:
    """Lambda'''[., w, w] on the z rows (K, 4N), w = (dz, dp): ``moves`` (K, N+2, 3) are
    dy_0 = dp, dy_1 ... dy_N, dy_{N+1} = 0; ``multiplier_moves`` (K, N) the d lambda_i."""
    k, n = len(paths.scene_points), paths.bounces
    across = moves[:, 1:] - moves[:, :-1]  # (K, N+1, 3) D of each segment
    along = np.einsum("ksi,ksi->ks", unit, across)
    bent = across - along[..., None] * unit  # P D
    v = -(unit * np.einsum("ksi,ksi->ks", across, bent)[..., None] + 2.0 * bent * along[..., None]) \
        * (inverse ** 2)[..., None]
    out = np.zeros((k, n, 4))
    out[:, :, :3] = v[:, :-1] - v[:, 1:]  # segment i -> i+1 pushes y_{i+1} by +v and y_i by -v
    dy = moves[:, 1:-1]
    q_dy = np.einsum("knij,knj->kni", paths.hessians, dy)
    out[:, :, :3] += 2.0 * multiplier_moves[..., None] * q_dy
    out[:, :, 3] = np.einsum("kni,kni->kn", dy, q_dy)
    return out.reshape(k, 4 * n)


@dataclass(frozen=True)
class Perturbation:
    """The Taylor step of eq. (1) along each path's dp: first- and second-order moves of
    every reflector point (K, N, 3)."""

    first: np.ndarray
    second: np.ndarray  # the full second-order term, (1/2) dp^T H dp

    def points(self, paths: Paths, order: int = 2) -> np.ndarray:
        """(K, N, 3) the perturbed reflector points, to first or second order."""
        return paths.reflector_points + self.first + (self.second if order >= 2 else 0.0)


def perturb(paths: Paths, targets: np.ndarray, order: int = 2) -> Perturbation:
    """The reflector points' moves when each path's scene point moves to ``targets`` (K, 3),
    to first or second ``order`` (the second term is zero at order 1)."""
    k, n = len(paths.scene_points), paths.bounces
    dp = np.asarray(targets, dtype=np.float64) - paths.scene_points
    _, a, unit, inverse = system(paths)
    # T dp: only y_1's rows depend on p, through the segment p -> y_1: -(d2l/dadb) dp = -P/l dp.
    t_dp = np.zeros((k, 4 * n))
    along = np.einsum("ki,ki->k", unit[:, 0], dp)
    t_dp[:, :3] = -(dp - along[:, None] * unit[:, 0]) * inverse[:, 0, None]
    dz = -_solve(a, t_dp)
    if order < 2:
        return Perturbation(dz.reshape(k, n, 4)[:, :, :3], np.zeros((k, n, 3)))
    moves = np.zeros((k, n + 2, 3))
    moves[:, 0] = dp
    moves[:, 1:-1] = dz.reshape(k, n, 4)[:, :, :3]
    d2z = -_solve(a, _third_derivative(paths, unit, inverse, moves, dz.reshape(k, n, 4)[:, :, 3]))
    return Perturbation(dz.reshape(k, n, 4)[:, :, :3], 0.5 * d2z.reshape(k, n, 4)[:, :, :3])


def _solve(a: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Batched solve; a singular system (a path at a caustic) gives NaN, not an error."""
    try:
        return np.linalg.solve(a, rhs[..., None])[..., 0]
    except np.linalg.LinAlgError:
        out = np.full_like(rhs, np.nan)
        ok = np.abs(np.linalg.det(a)) > 1e-300
        if ok.any():
            out[ok] = np.linalg.solve(a[ok], rhs[ok][..., None])[..., 0]
        return out


def newton(paths: Paths, iterations: int = 8, tolerance: float = 1e-10, osculate=None) -> tuple[Paths, np.ndarray]:
    """Solve F = 0 by Newton's method from the given paths (scene points and eye fixed):
    the exact paths on the quadrics, or with ``osculate`` (paths -> paths with each
    bounce's quadric osculating its surface at the current points) on any smooth
    implicit surfaces. Returns the solved paths and (K,) bool converged."""
    k, n = len(paths.scene_points), paths.bounces
    for _ in range(iterations):
        if osculate is not None:
            paths = osculate(paths)
        residual, a, _, _ = system(paths)
        step = _solve(a, residual).reshape(k, n, 4)
        step = np.nan_to_num(step)
        paths = paths.with_points(reflector_points=paths.reflector_points - step[:, :, :3],
                                  multipliers=paths.multipliers - step[:, :, 3])
    residual, _, _, _ = system(paths if osculate is None else osculate(paths))
    return paths, np.abs(residual).max(axis=1) < tolerance
