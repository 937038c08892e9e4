# SPDX-License-Identifier: GPL-3.0-or-later
"""Our leaf model: a polynomial patch of the reflected-ray field, inverted by Newton.

The paper's leaf (SBC section IV) is a pinhole camera: one centre of projection and a
quadratic map from its image plane to the first reflector point. Reflected rays are
far from concurrent, so that model is accurate only over a few rays, and only near the
depths where it was fitted (tails and heads).

Here a leaf instead models the ray field itself over its patch of the ray map:
tail t(u, v) and direction r(u, v) are polynomials in the ray-map coordinates (u, v),
fitted by least squares to the leaf's rays. Projecting a point p means finding the
ray through it, i.e. solving

    t(u, v) + s r(u, v) = p

for (u, v, s) by Newton's method (three equations, three unknowns; the Jacobian
columns are t_u + s r_u, t_v + s r_v and r). The answer (u, v) *is* the ray-map
position, hence the desired-view pixel d (u + 0.5), at every depth s at once, which is
what the perturbation view of Chen-Arvo (2000) suggests: a smooth local expansion of
the ray field, not of the projection. Cells of ray-list leaves use the same solver
with a bilinear patch through their four corner rays (the paper's "interpolate the
unit frustum that contains the point").
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ...geometry.segments import segment_max, segment_mean, segment_min, segment_sum, solve_least_squares
from ...geometry.vectors import cross_rows, dot_rows

NEWTON_ITERATIONS = 8
#: Iterations run on every point before only the unconverged ones go on.
FIRST_ITERATIONS = 4
#: Of those, the first ones run in float32 (far from the root, where float64 buys nothing).
FLOAT32_ITERATIONS = 2
#: Newton stops when no chart coordinate moves more than this (charts span [-1, 1]).
STEP_TOLERANCE = 1e-7
#: Fractions of the tail-to-head segment where the fit error is measured.
ERROR_SAMPLE_FRACTIONS = np.array([0.0, 0.01, 0.05, 0.15, 0.35, 0.65, 1.0])
PROJECT_CHUNK = 8192
#: Fewest rays a camera-leaf patch is fitted to: the six coefficients of a quadratic.
MIN_PATCH_RAYS = 6


def quadratic_basis(u, v):
    """Basis 1, u, v, u^2, uv, v^2 and its u and v derivatives, each (n, 6)."""
    one, zero = np.ones_like(u), np.zeros_like(u)
    value = np.stack([one, u, v, u * u, u * v, v * v], axis=1)
    du = np.stack([zero, one, zero, 2 * u, v, zero], axis=1)
    dv = np.stack([zero, zero, one, zero, u, 2 * v], axis=1)
    return value, du, dv


@dataclass(frozen=True)
class RayPatches:
    """Per-leaf ray-field patches; row n is one leaf.

    Camera-leaf patches are charted on the plane of their tails: local coordinates
    (a, b) are tail positions projected on the two main axes of the tails, divided by
    ``scale``; tail, direction and ray-map cell are quadratics in (a, b). Near a
    silhouette the ray-map position has a square-root singularity as a function of the
    surface point, but tail, direction and cell are all smooth functions *of* the
    surface point, so the chart keeps leaves large right up to the reflector's edge.
    Ray-list cells (``bilinear``) are charted by the ray-map cell itself, (u, v) - lo.
    """

    origin: np.ndarray  # (n, 3) chart origin (bilinear: unused zeros)
    axes: np.ndarray  # (n, 2, 3) chart axes (bilinear: unused zeros)
    scale: np.ndarray  # (n,)
    tail: np.ndarray  # (n, k, 3)
    direction: np.ndarray  # (n, k, 3)
    cell: np.ndarray  # (n, k, 2) ray-map cell as a function of the chart (bilinear: unused)
    lo: np.ndarray  # (n, 2) member cells' bounds
    hi: np.ndarray  # (n, 2)
    bilinear: bool = False

    def take(self, rows: np.ndarray) -> "RayPatches":
        return RayPatches(*(getattr(self, f)[rows] for f in _ARRAY_FIELDS), self.bilinear)

    @property
    def nbytes(self) -> int:
        return int(sum(getattr(self, f).nbytes for f in _ARRAY_FIELDS))

    @functools.cached_property
    def centre_rays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Bilinear cells only: each cell's central ray (tail, unit direction) at (0.5, 0.5),
        and how far its corner rays' tails and directions stray from it (the cell's size
        at the tail, and its growth per unit of distance along the ray)."""
        t, d = self.tail, self.direction
        centre_tail = t[:, 0] + 0.5 * (t[:, 1] + t[:, 2]) + 0.25 * t[:, 4]
        centre_direction = d[:, 0] + 0.5 * (d[:, 1] + d[:, 2]) + 0.25 * d[:, 4]
        centre_direction = centre_direction / np.maximum(np.linalg.norm(centre_direction, axis=1), 1e-300)[:, None]
        corners = [t[:, 0], t[:, 0] + t[:, 1], t[:, 0] + t[:, 2], t[:, 0] + t[:, 1] + t[:, 2] + t[:, 4]]
        turns = [d[:, 0], d[:, 0] + d[:, 1], d[:, 0] + d[:, 2], d[:, 0] + d[:, 1] + d[:, 2] + d[:, 4]]
        size = np.max([np.linalg.norm(c - centre_tail, axis=1) for c in corners], axis=0)
        spread = np.max([np.linalg.norm(r / np.linalg.norm(r, axis=1)[:, None] - centre_direction, axis=1)
                         for r in turns], axis=0)
        return centre_tail, centre_direction, size, spread

    def cells_at(self, leaf, a, b) -> np.ndarray:
        """Ray-map cells at chart coordinates (a, b) of leaves."""
        if self.bilinear:
            return self.lo[leaf] + np.stack([a, b], axis=1)
        value, _, _ = quadratic_basis(a, b)
        return np.einsum("nk,nkd->nd", value, self.cell[leaf])


_ARRAY_FIELDS = ("origin", "axes", "scale", "tail", "direction", "cell", "lo", "hi")


def concatenate_patches(parts: list[RayPatches]) -> RayPatches:
    return RayPatches(*(np.concatenate([getattr(p, f) for p in parts]) for f in _ARRAY_FIELDS), parts[0].bilinear)


def fit_patches(cells: np.ndarray, tails: np.ndarray, directions: np.ndarray, node: np.ndarray,
                n_nodes: int, bilinear: bool = False) -> RayPatches:
    """Least-squares patches of the rays of each node (members as rows, ``node`` their node)."""
    cells = cells.astype(np.float64)
    lo, hi = segment_min(cells, node, n_nodes), segment_max(cells, node, n_nodes)
    if bilinear:
        origin, axes, scale = np.zeros((n_nodes, 3)), np.zeros((n_nodes, 2, 3)), np.ones(n_nodes)
        local = cells - lo[node]
        design, _, _ = quadratic_basis(local[:, 0], local[:, 1])
        design[:, [3, 5]] = 0.0  # bilinear: 1, u, v, uv in the quadratic layout
    else:
        origin = segment_mean(tails, node, n_nodes)
        offset = tails - origin[node]
        _, vectors = np.linalg.eigh(segment_sum(offset[:, :, None] * offset[:, None, :], node, n_nodes))
        axes = np.stack([vectors[:, :, 2], vectors[:, :, 1]], axis=1)
        local = np.einsum("mkd,md->mk", axes[node], offset)
        scale = np.maximum(segment_max(np.abs(local).max(axis=1), node, n_nodes), 1e-12)
        local /= scale[node, None]
        design, _, _ = quadratic_basis(local[:, 0], local[:, 1])
    coefficients = solve_least_squares(design, np.concatenate([tails, directions, cells], axis=1), node, n_nodes)
    return RayPatches(origin, axes, scale, coefficients[:, :, :3], coefficients[:, :, 3:6],
                      coefficients[:, :, 6:], lo, hi, bilinear)


def invert_patches(patches: RayPatches, leaf: np.ndarray, points: np.ndarray):
    """Ray-map cells (q, 2) and ray distances s (q,) of points, each in the patch ``leaf``.

    Also returns the final residual |t + s r - p| (q,), small where Newton converged.
    """
    cells = np.empty((len(points), 2))
    distance = np.empty(len(points))
    residual = np.empty(len(points))
    for start in range(0, len(points), PROJECT_CHUNK):
        chunk = slice(start, start + PROJECT_CHUNK)
        cells[chunk], distance[chunk], residual[chunk] = _newton(patches, leaf[chunk], points[chunk])
    return cells, distance, residual


def _newton(patches: RayPatches, leaf: np.ndarray, points: np.ndarray):
    u, v, s, _, miss = solve_charts(patches, leaf, points)
    return patches.cells_at(leaf, u, v), s, miss


def solve_charts(patches: RayPatches, leaf: np.ndarray, points: np.ndarray):
    """Newton on t(u, v) + s r(u, v) = p in each point's leaf patch: chart coordinates
    (u, v), distance s along the ray, the ray's tail (P, 3) and how far the point lies
    off the ray (P,). Coordinates are not limited to the leaf's chart."""
    # Structure of arrays: every coefficient component is one contiguous 1-D array, so
    # each step is a few dozen fused 1-D operations (no cross/einsum over tiny axes).
    # Tails are taken relative to each patch's constant term, so the float32 steps see
    # small numbers (as the GLSL twin does).
    c = np.concatenate([patches.tail[leaf], patches.direction[leaf]], axis=2)  # (q, term, component)
    origin = c[:, 0, :3].copy()
    c[:, 0, :3] = 0.0
    k = [[np.ascontiguousarray(c[:, term, d]) for d in range(6)] for term in range(6)]
    relative = points - origin
    p = [np.ascontiguousarray(relative[:, d]) for d in range(3)]
    start = 0.5 if patches.bilinear else 0.0
    u = np.full(len(points), start)
    v = np.full(len(points), start)
    ray = _ray(k, u, v)
    s = dot_rows([p[d] - ray[d] for d in range(3)], ray[3:]) / np.maximum(np.sqrt(dot_rows(ray[3:], ray[3:])), 1e-300)
    # The first steps, far from the root, run in float32 (twice the numbers per vector
    # instruction); float64 steps then polish to full precision, so the answer is the
    # float64 root. Most points converge in a few steps: after FIRST_ITERATIONS in all,
    # only the rest go on iterating.
    if FLOAT32_ITERATIONS:
        k32 = [[x.astype(np.float32) for x in term] for term in k]
        u32, v32, s32, _ = _newton_steps(k32, [x.astype(np.float32) for x in p], u.astype(np.float32),
                                         v.astype(np.float32), s.astype(np.float32), FLOAT32_ITERATIONS, check=False)
        u, v, s = u32.astype(np.float64), v32.astype(np.float64), s32.astype(np.float64)
    u, v, s, moving = _newton_steps(k, p, u, v, s, FIRST_ITERATIONS - FLOAT32_ITERATIONS)
    rest = np.flatnonzero(moving)
    if len(rest):
        sub_k = [[term[d][rest] for d in range(6)] for term in k]
        sub_u, sub_v, sub_s, _ = _newton_steps(sub_k, [x[rest] for x in p], u[rest], v[rest], s[rest],
                                               NEWTON_ITERATIONS - FIRST_ITERATIONS)
        u[rest], v[rest], s[rest] = sub_u, sub_v, sub_s
    ray = _ray(k, u, v)
    miss = [ray[d] + s * ray[d + 3] - p[d] for d in range(3)]
    return u, v, s, np.stack(ray[:3], axis=1) + origin, np.sqrt(dot_rows(miss, miss))


def _ray(k, u, v):
    """Tail (3 arrays) and direction (3 arrays) of the patch quadratic at (u, v)."""
    return [k[0][d] + u * (k[1][d] + u * k[3][d] + v * k[4][d]) + v * (k[2][d] + v * k[5][d]) for d in range(6)]


def _ray_and_derivatives(k, u, v):
    """Tail and direction (6 arrays) of the patch quadratic at (u, v) and their u and v
    derivatives, sharing the partial sums (14 array operations a component, not 20)."""
    ray, du, dv = [], [], []
    for d in range(6):
        u_k3, v_k4, v_k5 = u * k[3][d], v * k[4][d], v * k[5][d]
        along_u = k[1][d] + u_k3 + v_k4  # k1 + u k3 + v k4: u times it is the u part of the quadratic
        along_v = k[2][d] + v_k5
        ray.append(k[0][d] + u * along_u + v * along_v)
        du.append(along_u + u_k3)
        dv.append(along_v + u * k[4][d] + v_k5)
    return ray, du, dv


def _newton_steps(k, p, u, v, s, iterations: int, check: bool = True):
    """Newton on t(u, v) + s r(u, v) = p; returns u, v, s and which points still move
    (with ``check=False`` every iteration runs and all points count as moving). A point
    stops after its first step shorter than STEP_TOLERANCE, as each vertex of the GLSL
    twin does: its answer does not depend on which other points share the batch."""
    moving = np.ones(len(u), dtype=bool)
    tiny = np.finfo(u.dtype).tiny
    for _ in range(iterations):
        ray, du, dv = _ray_and_derivatives(k, u, v)
        r = ray[3:]
        a = [du[d] + s * du[d + 3] for d in range(3)]
        b = [dv[d] + s * dv[d + 3] for d in range(3)]
        f = [ray[d] + s * r[d] - p[d] for d in range(3)]
        # Cramer's rule on [a b r] step = f, with two cross products: det(f, b, r) = -b.(f x r),
        # det(a, f, r) = a.(f x r), det(a, b, f) = f.(a x b), det(a, b, r) = r.(a x b).
        ab, fr = cross_rows(a, b), cross_rows(f, r)
        det = dot_rows(r, ab)
        det = np.where(np.abs(det) > tiny, det, tiny)
        step_u, step_v = -dot_rows(b, fr) / det, dot_rows(a, fr) / det
        if not check:
            u, v, s = np.clip(u - step_u, -4.0, 4.0), np.clip(v - step_v, -4.0, 4.0), s - dot_rows(f, ab) / det
            continue
        u = np.where(moving, np.clip(u - step_u, -4.0, 4.0), u)
        v = np.where(moving, np.clip(v - step_v, -4.0, 4.0), v)
        s = np.where(moving, s - dot_rows(f, ab) / det, s)
        moving &= np.abs(step_u) + np.abs(step_v) >= STEP_TOLERANCE
        if not moving.any():
            break
    return u, v, s, moving


def project_patches(patches: RayPatches, leaf: np.ndarray, points: np.ndarray, margin: float = 0.5):
    """Cells, ray distance (NaN where Newton did not converge: no ray of the patch passes
    through the point) and an ``inside`` mask: converged and within the leaf's cells."""
    cells, distance, residual = invert_patches(patches, leaf, points)
    converged = residual < 1e-6 * (np.linalg.norm(points, axis=1) + 1.0)
    inside = (
        converged
        & np.all(cells >= patches.lo[leaf] - margin, axis=1)
        & np.all(cells <= patches.hi[leaf] + margin, axis=1)
    )
    return cells, np.where(converged, distance, np.nan), inside


class RayPatchLeaves:
    """Leaf-model adapter for the BSP builder: our ray-field patches."""

    name = "ray_patch"
    concatenate = staticmethod(concatenate_patches)
    splits_into_sheets = True
    #: Leaves accept half a cell beyond their rays and every answer is checked against
    #: the ray map, so rays are assigned by their half frustum (bsp.half_frustum_points).
    half_frustum = True

    def well_posed(self, patches: RayPatches, counts: np.ndarray) -> np.ndarray:
        """Enough rays, spread in two directions, to fix a quadratic between them.

        Errors are measured on the leaf's own rays; a quadratic through fewer, or through
        rays along one line, can pass through them all and still be wrong in between.
        """
        extent = patches.hi - patches.lo
        return (counts >= MIN_PATCH_RAYS) & (extent.min(axis=1) >= 1) & (extent.max(axis=1) >= 2)

    def fit(self, ray_map, rays, node, n_nodes) -> RayPatches:
        return fit_patches(ray_map.cell[rays], ray_map.tail[rays], ray_map.direction[rays], node, n_nodes)

    #: A leaf may excuse one band of depth along its rays, answered by its ray list (bsp._depth_bands).
    depth_bands = True

    def project(self, patches: RayPatches, leaf, points, ray_map):
        """Cells, the ``inside`` test and the distance along the ray of each point (NaN
        where Newton did not converge)."""
        cells, distance, inside = project_patches(patches, leaf, points)
        return cells, inside, distance

    def error_samples(self, ray_map, rays, fractions=ERROR_SAMPLE_FRACTIONS):
        """Points along each ray from tail to head: where points will really be projected.

        ``fractions`` of the tail-to-head segment, (K,) for every ray or (R, K) per ray;
        the samples are ray-major (sample k of ray i is row i * K + k)."""
        fractions = np.broadcast_to(fractions, (len(rays), np.shape(fractions)[-1]))
        owner = np.repeat(np.arange(len(rays)), fractions.shape[1])
        r = rays[owner]
        return owner, ray_map.tail[r] + (fractions.reshape(-1) * ray_map.head_distance[r])[:, None] * ray_map.direction[r]
