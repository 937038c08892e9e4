# SPDX-License-Identifier: GPL-3.0-or-later
"""Seed paths: exact reflection paths traced from the eye through chosen pixels.

Chen & Arvo (2000), section III-B.1: a sparse set of view rays is traced through the
reflectors (every n-th pixel and scan line; n = 8 to 32 in the paper), and every
reflection path up to the highest order wanted is kept with its reflection points and
the reflectors it met; the paths of each history (reflector sequence) are the samples
that the perturbation step interpolates from. Here the regular grid is the start; the
projector adds seeds through single pixels where the path Hessian says a step from the
grid is not accurate enough (``projector.py``).

A hit on a reflector declared analytic (:class:`.quadrics.AnalyticSurface`) is moved
along its ray onto the true surface and reflected about the true normal; elsewhere the
mesh's interpolated normal reflects (the surface model of ``engine/reference/exact.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...geometry.raytrace import ReflectorSet, reflect, reflection_valid
from ...view import View
from .path_derivatives import Paths, optimal_multipliers
from .quadrics import QuadricRows, osculating_quadrics


@dataclass(frozen=True)
class SeedPaths:
    """Traced reflection paths of one order: R paths, bounces in the eye's order."""

    pixels: np.ndarray  # (R, 2) the view pixel each path starts from
    ray: np.ndarray  # (R,) index of that pixel in the traced list
    histories: np.ndarray  # (R, order) reflector index of each bounce
    points: np.ndarray  # (R, order, 3) reflection points, first the one the eye sees
    triangles: np.ndarray  # (R, order)
    barycentric: np.ndarray  # (R, order, 3)
    outgoing: np.ndarray  # (R, 3) unit direction leaving the last bounce
    head: np.ndarray  # (R,) distance along it to the next reflector (inf: none)

    @property
    def order(self) -> int:
        return self.histories.shape[1]

    def select(self, rows) -> "SeedPaths":
        return SeedPaths(*(getattr(self, f)[rows] for f in self.__dataclass_fields__))


def trace_seed_paths(reflector_set: ReflectorSet, view: View, pixels: np.ndarray, max_order: int,
                     analytic: dict | None = None) -> list:
    """The reflection paths of the view rays through ``pixels`` (P, 2): one
    :class:`SeedPaths` per order 1 ... ``max_order`` (paths that reflect that often)."""
    analytic = analytic or {}
    pixels = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    origins, directions = view.pixel_rays(pixels)
    alive = np.arange(len(pixels))
    source = None
    points, triangles, barycentric, history = [], [], [], []
    out = []
    hits = reflector_set.intersect(origins, directions, np.inf, source)
    for order in range(1, max_order + 1):
        keep = np.flatnonzero(hits.hit)
        position, normal = hits.position[keep], hits.normal[keep]
        reflector = hits.reflector[keep]
        _snap_to_analytic(analytic, reflector, origins[keep], directions[keep], hits.t[keep], position, normal)
        valid = reflection_valid(directions[keep], normal, hits.face_normal[keep])
        keep, position, normal, reflector = keep[valid], position[valid], normal[valid], reflector[valid]
        alive, directions = alive[keep], directions[keep]
        points = [p[keep] for p in points] + [position]
        triangles = [t[keep] for t in triangles] + [hits.triangle[keep]]
        barycentric = [b[keep] for b in barycentric] + [hits.barycentric[keep]]
        history = [h[keep] for h in history] + [reflector]
        directions = reflect(directions, normal)
        origins, source = position, hits.triangle[keep]
        hits = reflector_set.intersect(origins, directions, np.inf, source)
        out.append(SeedPaths(pixels[alive], alive, np.stack(history, axis=1), np.stack(points, axis=1),
                             np.stack(triangles, axis=1), np.stack(barycentric, axis=1), directions, hits.t))
    return out


def _snap_to_analytic(analytic: dict, reflector, origins, directions, t, position, normal) -> None:
    """Move hits on analytic reflectors onto the true surface, normal from its gradient
    (turned toward the ray's origin), in place."""
    for index, surface in analytic.items():
        rows = np.flatnonzero(reflector == index)
        if len(rows) == 0:
            continue
        exact_t = surface.intersect(origins[rows], directions[rows], t[rows])
        exact_t = np.where(np.isfinite(exact_t), exact_t, t[rows])
        position[rows] = origins[rows] + exact_t[:, None] * directions[rows]
        n = surface.normals(position[rows])
        facing = np.sign(np.einsum("ij,ij->i", n, directions[rows]))
        normal[rows] = -n * np.where(facing == 0, 1.0, facing)[:, None]


def seed_quadrics(reflector_set: ReflectorSet, seeds: SeedPaths, analytic: dict | None = None) -> list:
    """Per bounce (eye's order), the quadric each seed path bounces off (QuadricRows)."""
    analytic = analytic or {}
    rows = []
    for k in range(seeds.order):
        quadrics = osculating_quadrics(reflector_set, seeds.triangles[:, k], seeds.barycentric[:, k])
        hessian, linear, constant = (np.array(a) for a in (quadrics.hessian, quadrics.linear, quadrics.constant))
        for index, surface in analytic.items():
            on = seeds.histories[:, k] == index
            if on.any():
                exact = surface.osculating(seeds.points[on, k])
                hessian[on], linear[on], constant[on] = exact.hessian, exact.linear, exact.constant
        rows.append(QuadricRows(hessian, linear, constant))
    return rows


def seed_paths_to(seeds: SeedPaths, quadrics: list, view: View, scene_points: np.ndarray) -> Paths:
    """Chen-Arvo :class:`Paths` of the seeds (reversed: y_1 is the last bounce) ending at
    ``scene_points`` (R, 3), points on each seed's outgoing ray."""
    order = seeds.order
    reverse = slice(None, None, -1)
    paths = Paths(
        scene_points=np.asarray(scene_points, dtype=np.float64),
        reflector_points=seeds.points[:, reverse],
        multipliers=np.zeros((len(seeds.points), order)),
        hessians=np.stack([q.hessian for q in quadrics], axis=1)[:, reverse],
        linear=np.stack([q.linear for q in quadrics], axis=1)[:, reverse],
        constant=np.stack([q.constant for q in quadrics], axis=1)[:, reverse],
        eye=view.eye if view.is_perspective else view.backward,
        orthographic=not view.is_perspective,
    )
    return paths.with_points(multipliers=optimal_multipliers(paths))
