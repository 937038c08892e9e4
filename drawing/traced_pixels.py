# SPDX-License-Identifier: GPL-3.0-or-later
"""Mirror pixels ray traced on the CPU, and their texture for the composite.

A sample-based camera cannot place a reflection everywhere: not in the last ray-map cell
before a footprint's edge, and not surely in the cells where it knows its own projection is
unreliable (``band_trace.unreliable_cells``: ray-list leaves, folds, mixed cells), where
a crumpled mirror (a subdivided monkey head) shows a point many times and the camera
answers some of those images only. There the pixels are traced exactly
(``band_trace.BandTracer``, shaded as the reflected meshes are) and the composite shows
the traced colour before a drawn one (``glsl/reflection_composite_frag.glsl``).

A render traces them for its frame (``ReflectionRenderer.trace_band``). The viewport
cannot wait for them, so :func:`trace_doubtful` runs on the live view's worker for a
camera's own view once it is drawn, and the :class:`TracedPixels` it returns are drawn
over that view only (from any other view the reflection has moved: the camera's answers
draw alone there, until that view's own camera lands and is traced in turn).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gpu
import numpy as np

from ..engine.geometry import band_trace
from ..engine.view import View


def traced_rgba(tracer, view: View, pixels: np.ndarray, max_order: int, world_color,
                surface_points: np.ndarray | None = None) -> np.ndarray:
    """(K, 4) float32 what the composite reads for integer ``pixels`` (K, 2) (x, y, rows
    bottom to top): the traced linear RGB through their centres, and as alpha, as a drawn
    reflection's, 1 + the distance from the mirror along the reflected ray (inf where the
    world shows: attenuation, SBC V-D). ``surface_points``: where the pre-pass saw the
    mirror on each pixel (``BandTracer.trace``)."""
    colors = tracer.trace(view, np.asarray(pixels) + 0.5, max_order, world_color, on_mirrors=True,
                          surface_points=surface_points)
    return np.concatenate([colors[:, :3], 1.0 + np.minimum(colors[:, 3:4], 1e30)], axis=1).astype(np.float32)


def traced_texture(width: int, height: int, pixels: np.ndarray, rgba: np.ndarray):
    """A (width x height) RGBA32F texture holding ``rgba`` at ``pixels``, zero (untraced)
    elsewhere."""
    image = np.zeros((height, width, 4), np.float32)
    image[pixels[:, 1], pixels[:, 0]] = rgba
    return gpu.types.GPUTexture((width, height), format='RGBA32F',
                                data=gpu.types.Buffer('FLOAT', image.size, image.reshape(-1)))


@dataclass
class TracedPixels:
    """The traced pixels of one view (its camera's unreliable cells), for the viewport."""

    view: View
    pixels: np.ndarray  # (K, 2) int x, y, rows bottom to top
    rgba: np.ndarray  # (K, 4) float32, as :func:`traced_rgba`
    _texture: object = field(default=None, repr=False)

    def texture(self):
        """Their texture, made on first use (main thread: it needs the GPU)."""
        if self._texture is None:
            self._texture = traced_texture(self.view.width, self.view.height, self.pixels, self.rgba)
        return self._texture


def trace_doubtful(tracer, camera, max_order: int, world_color, max_fraction: float) -> TracedPixels | None:
    """The mirror pixels of ``camera``'s view in the cells where it marks its projection
    unreliable, and in those it cannot reach (the last cell before a footprint's edge,
    between cells of different histories: ``band_trace.history_boundary``), traced with
    ``tracer`` (numpy only: the live view's worker runs it); None where there are none,
    or more than ``max_fraction`` of the view (a render's budget,
    ``reflection_draw.MAX_TRACED_FRACTION``)."""
    view = camera.ray_map.view
    rows, columns = np.nonzero(band_trace.unreliable_pixels(camera, view.width, view.height)
                               | band_trace.history_boundary(camera.ray_map, view.width, view.height, max_order))
    pixels = np.stack([columns, rows], axis=1)
    # Those on a mirror: the cells along a silhouette reach past it.
    pixels = pixels[tracer.intersect(*view.pixel_rays(pixels + 0.5), mirrors_only=True).hit]
    if len(pixels) == 0 or len(pixels) > max_fraction * view.width * view.height:
        return None
    return TracedPixels(view, pixels, traced_rgba(tracer, view, pixels, max_order, world_color))
