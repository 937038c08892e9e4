# SPDX-License-Identifier: GPL-3.0-or-later
"""Mirror pixels traced for the composite (drawing/traced_pixels.py): the viewport's
trace of a camera's unreliable cells, and the texture both it and a render draw from."""

import numpy as np

from curved_reflections.engine import DiffuseMesh, look_at_view, scene_bounds
from curved_reflections.engine.geometry import band_trace
from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.engine.methods.sbc import build_sample_based_camera
from curved_reflections.drawing.gpu_data import read_texture
from curved_reflections.drawing.traced_pixels import trace_doubtful, traced_rgba, traced_texture

WORLD = (0.1, 0.2, 0.9, 1.0)


def _scene():
    """A mirror ball between a red and a green wall, its camera at d = 2."""
    mirror = icosphere((0.0, 0.0, 0.0), 1.0, 3, name="Mirror")
    walls = []
    for name, x, colour in (("Red", -3.0, (1.0, 0.0, 0.0)), ("Green", 3.0, (0.0, 1.0, 0.0))):
        vertices = np.array([[x, -2.0, -2.0], [x, 2.0, -2.0], [x, 2.0, 2.0], [x, -2.0, 2.0]])
        walls.append(DiffuseMesh(name, vertices, np.array([[0, 1, 2], [0, 2, 3]]), np.tile([*colour, 1.0], (4, 1)),
                                 emissive=True))
    view = look_at_view((0.0, -6.0, 0.3), (0.0, 0.0, 0.0), fov_y_deg=30.0, width=64, height=48)
    camera = build_sample_based_camera([mirror], view, scene_bounds([mirror], walls, margin=1.0), downsample=2)
    return mirror, walls, camera


def test_the_unreliable_cells_mirror_pixels_are_traced_as_the_band_tracer_sees_them(monkeypatch):
    """Every pixel of the unreliable cells on a mirror (here every cell is), traced as
    a render's band is; none past the mirror's silhouette; nothing over the budget."""
    mirror, walls, camera = _scene()
    tracer = band_trace.BandTracer([mirror], walls)
    view = camera.ray_map.view
    monkeypatch.setattr(band_trace, "unreliable_cells",
                        lambda ray_map, *args: np.ones((ray_map.rows, ray_map.columns), dtype=bool))
    traced = trace_doubtful(tracer, camera, 1, WORLD, max_fraction=1.0)
    rows, columns = np.mgrid[0:view.height, 0:view.width]
    every = np.stack([columns.ravel(), rows.ravel()], axis=1)
    on_mirror = every[tracer.intersect(*view.pixel_rays(every + 0.5), mirrors_only=True).hit]
    np.testing.assert_array_equal(np.unique(traced.pixels, axis=0), np.unique(on_mirror, axis=0))
    np.testing.assert_array_equal(traced.rgba, traced_rgba(tracer, view, traced.pixels, 1, WORLD))
    assert (np.abs(traced.rgba[:, :3] - [1.0, 0.0, 0.0]).max(axis=1) < 1e-6).sum() > 10  # the red wall
    assert np.all(traced.rgba[:, 3] >= 1.0)  # 1 + the distance from the mirror
    assert trace_doubtful(tracer, camera, 1, WORLD, max_fraction=0.01) is None  # over the budget


def test_the_texture_holds_the_traced_pixels_and_zero_elsewhere(gpu_ready):
    pixels = np.array([[0, 0], [5, 2], [7, 3]])
    rgba = np.array([[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 2.5], [0.0, 0.0, 1.0, 1e30]], np.float32)
    image = read_texture(traced_texture(8, 4, pixels, rgba), 8, 4)
    np.testing.assert_array_equal(image[pixels[:, 1], pixels[:, 0]], rgba)
    assert np.count_nonzero(image.any(axis=2)) == 3
