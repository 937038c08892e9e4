# SPDX-License-Identifier: GPL-3.0-or-later
"""The paper's leaf model: a pinhole camera per leaf (SBC paper, section IV).

For a set of rays with tails t and unit directions d:

- the centre of projection o is the least-squares point on all rays, from
  o x d = t x d, i.e. sum (I - d d^T) o = sum (I - d d^T) t;
- the image plane is the least-squares plane of the tails (normal = the direction of
  least variance, turned along the mean ray direction);
- a point projects through o onto that plane, to plane coordinates (u', v');
- a quadratic f(u', v') maps plane coordinates to the first reflector point, fitted by
  least squares to f(tail projection) = q and f(head projection) = q for every ray;
- the frustum is the rectangle in (u', v') holding the tails' and heads' projections,
  and only points on the image-plane side of o are inside.

Kept as the baseline our ray-patch leaf (ray_patch.py) is measured against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .ray_patch import quadratic_basis
from ...geometry.segments import segment_max, segment_mean, segment_min, segment_sum, solve_least_squares
from ...geometry.spd_solve import solve_spd
from ...geometry.vectors import cross


@dataclass(frozen=True)
class PinholeCameras:
    """Per-leaf pinhole cameras; row n is one leaf."""

    centre_of_projection: np.ndarray  # (n, 3)
    plane_origin: np.ndarray  # (n, 3)
    plane_axes: np.ndarray  # (n, 3, 3): u axis, v axis, normal (pointing away from o)
    plane_scale: np.ndarray  # (n,)
    mapping: np.ndarray  # (n, 6, 3) quadratic (u', v') -> first reflector point
    lo: np.ndarray  # (n, 2) frustum rectangle in plane coordinates
    hi: np.ndarray  # (n, 2)

    def take(self, rows: np.ndarray) -> "PinholeCameras":
        return PinholeCameras(*(getattr(self, f)[rows] for f in self.__dataclass_fields__))

    @property
    def nbytes(self) -> int:
        return int(sum(getattr(self, f).nbytes for f in self.__dataclass_fields__))


def concatenate_cameras(parts: list[PinholeCameras]) -> PinholeCameras:
    return PinholeCameras(*(np.concatenate([getattr(p, f) for p in parts]) for f in PinholeCameras.__dataclass_fields__))


def fit_cameras(tails, directions, heads, first_points, node, n_nodes) -> PinholeCameras:
    """Fit one pinhole camera per node to its member rays (rows)."""
    projector = np.eye(3)[None] - directions[:, :, None] * directions[:, None, :]
    lhs = segment_sum(projector, node, n_nodes) + 1e-12 * np.eye(3)
    rhs = segment_sum(np.einsum("mij,mj->mi", projector, tails), node, n_nodes)
    centre = solve_spd(lhs, rhs)

    origin = segment_mean(tails, node, n_nodes)
    offset = tails - origin[node]
    covariance = segment_sum(offset[:, :, None] * offset[:, None, :], node, n_nodes)
    _, vectors = np.linalg.eigh(covariance)  # ascending eigenvalues
    normal = vectors[:, :, 0]
    mean_direction = segment_mean(directions, node, n_nodes)
    normal *= np.where(np.einsum("nd,nd->n", normal, mean_direction) < 0, -1.0, 1.0)[:, None]
    u_axis = vectors[:, :, 2]
    axes = np.stack([u_axis, cross(normal, u_axis), normal], axis=1)
    scale = np.maximum(np.sqrt(segment_max(np.einsum("md,md->m", offset, offset), node, n_nodes)), 1e-12)
    partial = PinholeCameras(centre, origin, axes, scale, np.zeros((n_nodes, 6, 3)),
                             np.zeros((n_nodes, 2)), np.zeros((n_nodes, 2)))

    both_node = np.concatenate([node, node])
    plane_uv, _ = _plane_coordinates(partial, both_node, np.concatenate([tails, heads]))
    design, _, _ = quadratic_basis(plane_uv[:, 0], plane_uv[:, 1])
    mapping = solve_least_squares(design, np.concatenate([first_points, first_points]), both_node, n_nodes)
    finite = np.where(np.isfinite(plane_uv), plane_uv, 0.0)
    return PinholeCameras(centre, origin, axes, scale, mapping,
                          segment_min(finite, both_node, n_nodes), segment_max(finite, both_node, n_nodes))


def _plane_coordinates(cameras: PinholeCameras, leaf, points):
    """Plane coordinates (q, 2) of points projected through o, and the ray parameter lambda."""
    o = cameras.centre_of_projection[leaf]
    axes = cameras.plane_axes[leaf]
    normal = axes[:, 2]
    towards = points - o
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.einsum("nd,nd->n", normal, cameras.plane_origin[leaf] - o) / np.einsum("nd,nd->n", normal, towards)
    on_plane = o + lam[:, None] * towards - cameras.plane_origin[leaf]
    uv = np.einsum("nkd,nd->nk", axes[:, :2], on_plane) / cameras.plane_scale[leaf, None]
    return uv, lam


def project_cameras(cameras: PinholeCameras, leaf, points):
    """First reflector points (q, 3) and the frustum test (q,) of points in leaf cameras."""
    uv, lam = _plane_coordinates(cameras, leaf, points)
    with np.errstate(invalid="ignore"):
        inside = ((lam > 0)
                  & np.all(uv >= cameras.lo[leaf], axis=1) & np.all(uv <= cameras.hi[leaf], axis=1))
    design, _, _ = quadratic_basis(np.nan_to_num(uv[:, 0]), np.nan_to_num(uv[:, 1]))
    return np.einsum("nk,nkd->nd", design, cameras.mapping[leaf]), inside


class PinholeLeaves:
    """Leaf-model adapter for the BSP builder: the paper's pinhole cameras.

    As in the paper, the fit error is measured at the tails and heads only.
    """

    name = "pinhole"
    concatenate = staticmethod(concatenate_cameras)
    #: The baseline is built as the paper builds it: one tree per reflection group.
    splits_into_sheets = False
    half_frustum = False  # the paper's unit frustum
    depth_bands = False  # the paper's leaves answer every depth or none

    def well_posed(self, cameras: PinholeCameras, counts: np.ndarray) -> np.ndarray:
        """Every camera is usable, as in the paper (its error decides)."""
        return np.ones(len(counts), dtype=bool)

    def fit(self, ray_map, rays, node, n_nodes) -> PinholeCameras:
        return fit_cameras(ray_map.tail[rays], ray_map.direction[rays], ray_map.head[rays],
                           ray_map.first_point[rays], node, n_nodes)

    def project(self, cameras: PinholeCameras, leaf, points, ray_map):
        first_points, inside = project_cameras(cameras, leaf, points)
        pixels, _ = ray_map.view.to_pixels(first_points)
        return pixels / ray_map.downsample - 0.5, inside & np.all(np.isfinite(pixels), axis=1), None

    def error_samples(self, ray_map, rays):
        owner = np.concatenate([np.arange(len(rays)), np.arange(len(rays))])
        return owner, np.concatenate([ray_map.tail[rays], ray_map.head[rays]])
