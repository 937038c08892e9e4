# SPDX-License-Identifier: GPL-3.0-or-later
"""The desired view: Blender's view and window matrices plus the image size.

Conventions (docs/overview.md): ``view_matrix`` maps world to camera space, the camera looking
down -Z (``RegionView3D.view_matrix``); ``projection_matrix`` maps camera space to
OpenGL clip space (``RegionView3D.window_matrix``). Pixel coordinates have x right,
y up, the origin at the bottom-left corner of the image and pixel centres at k + 0.5,
as ``gl_FragCoord``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import SceneInputError


#: Views whose matrices differ by less than this (each entry) are the same view: the
#: live view builds no new camera for them, and a camera's reflected triangles are
#: drawn at its projected pixels.
VIEW_TOLERANCE = 1e-6


def _homogeneous(points: np.ndarray) -> np.ndarray:
    return np.concatenate([points, np.ones((len(points), 1))], axis=1)


@dataclass(frozen=True)
class View:
    """A pinhole (perspective) or orthographic view of ``width`` x ``height`` pixels."""

    view_matrix: np.ndarray
    projection_matrix: np.ndarray
    width: int
    height: int
    name: str = "view"

    def __post_init__(self):
        for attr in ("view_matrix", "projection_matrix"):
            matrix = np.array(getattr(self, attr), dtype=np.float64)
            if matrix.shape != (4, 4) or not np.isfinite(matrix).all():
                raise SceneInputError(self.name, f"{attr} must be a finite 4x4 matrix")
            if abs(np.linalg.det(matrix)) < 1e-300:
                raise SceneInputError(self.name, f"{attr} is singular")
            matrix.setflags(write=False)
            object.__setattr__(self, attr, matrix)
        if int(self.width) < 1 or int(self.height) < 1:
            raise SceneInputError(self.name, f"image size must be positive, got {self.width}x{self.height}")
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        view_projection = self.projection_matrix @ self.view_matrix
        object.__setattr__(self, "_view_projection", view_projection)
        object.__setattr__(self, "_inverse_view_projection", np.linalg.inv(view_projection))
        object.__setattr__(self, "_camera_to_world", np.linalg.inv(self.view_matrix))

    def same_as(self, other: "View") -> bool:
        """Whether ``other`` is this view: the same size, and matrices within
        :data:`VIEW_TOLERANCE`."""
        return self is other or ((self.width, self.height) == (other.width, other.height)
                                 and np.abs(self.view_matrix - other.view_matrix).max() <= VIEW_TOLERANCE
                                 and np.abs(self.projection_matrix - other.projection_matrix).max()
                                 <= VIEW_TOLERANCE)

    @property
    def is_perspective(self) -> bool:
        """OpenGL perspective matrices have a last row (0, 0, -1, 0)."""
        return abs(self.projection_matrix[3, 3]) < 1e-12

    @property
    def eye(self) -> np.ndarray:
        """World position of the centre of projection (perspective views only)."""
        if not self.is_perspective:
            raise ValueError(f"{self.name!r}: an orthographic view has no eye point")
        return self._camera_to_world[:3, 3].copy()

    @property
    def backward(self) -> np.ndarray:
        """Unit world direction of the camera's +Z axis (from the scene toward the viewer)."""
        axis = self._camera_to_world[:3, 2]
        return axis / np.linalg.norm(axis)

    def clip(self, points: np.ndarray) -> np.ndarray:
        """Clip-space coordinates (P, 4) of world points (P, 3)."""
        return _homogeneous(np.asarray(points, dtype=np.float64)) @ self._view_projection.T

    def to_pixels(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (P, 2) and NDC depth (P,) of world points.

        Points at or behind the eye plane (clip w <= 0) get NaN.
        """
        clip = self.clip(points)
        w = clip[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            ndc = clip[:, :3] / np.where(w > 0, w, np.nan)[:, None]
        pixels = np.empty((len(ndc), 2))
        pixels[:, 0] = (ndc[:, 0] * 0.5 + 0.5) * self.width
        pixels[:, 1] = (ndc[:, 1] * 0.5 + 0.5) * self.height
        return pixels, ndc[:, 2]

    def in_view(self, points: np.ndarray) -> np.ndarray:
        """(P,) bool: the point lies inside the view frustum (image and depth range)."""
        pixels, depth = self.to_pixels(points)
        with np.errstate(invalid="ignore"):
            return (
                (pixels[:, 0] >= 0) & (pixels[:, 0] <= self.width)
                & (pixels[:, 1] >= 0) & (pixels[:, 1] <= self.height)
                & (depth >= -1) & (depth <= 1)
            )

    def pixel_rays(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World rays through pixel positions (K, 2): origins on the near plane, unit directions."""
        pixels = np.asarray(pixels, dtype=np.float64)
        ndc_xy = np.empty_like(pixels)
        ndc_xy[:, 0] = pixels[:, 0] / self.width * 2.0 - 1.0
        ndc_xy[:, 1] = pixels[:, 1] / self.height * 2.0 - 1.0
        near = np.concatenate([ndc_xy, -np.ones((len(pixels), 1)), np.ones((len(pixels), 1))], axis=1)
        far = near.copy()
        far[:, 2] = 1.0
        near_world = near @ self._inverse_view_projection.T
        far_world = far @ self._inverse_view_projection.T
        origins = near_world[:, :3] / near_world[:, 3:4]
        ends = far_world[:, :3] / far_world[:, 3:4]
        directions = ends - origins
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        return origins, directions

    def window_points(self, pixels: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """World points (K, 3) at pixel positions (K, 2) and window depths (K,) in [0, 1]
        (a depth buffer's values: OpenGL's default depth range), NaN where the depth is
        1 (the far plane: nothing drawn there)."""
        pixels = np.asarray(pixels, dtype=np.float64)
        depth = np.asarray(depth, dtype=np.float64)
        ndc = np.column_stack([pixels[:, 0] / self.width * 2.0 - 1.0, pixels[:, 1] / self.height * 2.0 - 1.0,
                               2.0 * depth - 1.0, np.ones(len(pixels))])
        world = ndc @ self._inverse_view_projection.T
        points = world[:, :3] / world[:, 3:4]
        points[depth >= 1.0] = np.nan
        return points

    def pixel_grid(self, downsample: int = 1) -> np.ndarray:
        """Centres of the down-sampled pixels, (H/d * W/d, 2), row-major from the bottom row.

        A down-sampled pixel covers d x d image pixels; its centre is at d * (k + 0.5).
        """
        d = int(downsample)
        if d < 1:
            raise ValueError(f"downsample must be >= 1, got {downsample}")
        xs = (np.arange(self.width // d) + 0.5) * d
        ys = (np.arange(self.height // d) + 0.5) * d
        gx, gy = np.meshgrid(xs, ys)
        return np.stack([gx.ravel(), gy.ravel()], axis=1)

    def directions_to_eye(self, points: np.ndarray) -> np.ndarray:
        """Unit vectors (P, 3) from world points toward the viewer.

        Perspective: toward the eye point. Orthographic: the constant backward axis.
        """
        points = np.asarray(points, dtype=np.float64)
        if not self.is_perspective:
            return np.broadcast_to(self.backward, points.shape).copy()
        to_eye = self.eye - points
        return to_eye / np.linalg.norm(to_eye, axis=1, keepdims=True)

    def pixel_size_at(self, points: np.ndarray) -> np.ndarray:
        """World length (P,) that one pixel spans at each point's distance."""
        clip = self.clip(points)
        scale = 2.0 / (self.projection_matrix[0, 0] * self.width)
        return np.abs(clip[:, 3]) * scale if self.is_perspective else np.full(len(clip), scale)


def look_at_view(eye, target, up=(0.0, 0.0, 1.0), *, fov_y_deg: float = 40.0,
                 width: int = 320, height: int = 240, near: float = 0.1, far: float = 100.0,
                 name: str = "view") -> View:
    """A perspective :class:`View` looking from ``eye`` at ``target`` (for tests and scripts)."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    if np.linalg.norm(right) < 1e-9:
        right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = right, true_up, -forward
    view[:3, 3] = -view[:3, :3] @ eye
    f = 1.0 / np.tan(np.radians(fov_y_deg) / 2)
    aspect = width / height
    projection = np.zeros((4, 4))
    projection[0, 0] = f / aspect
    projection[1, 1] = f
    projection[2, 2] = (far + near) / (near - far)
    projection[2, 3] = 2 * far * near / (near - far)
    projection[3, 2] = -1.0
    return View(view, projection, width, height, name=name)
