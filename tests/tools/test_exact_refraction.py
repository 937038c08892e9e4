# SPDX-License-Identifier: GPL-3.0-or-later
"""The exact reference solver of refracted images (tools/exact_refraction.py)
against a slab's closed form and a glass ball's symmetry."""

import numpy as np

from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.engine.glass import Glass, GlassSet
from curved_reflections.tools.exact_refraction import solve_refractions
from curved_reflections.engine.view import look_at_view
from curved_reflections.tools.surfaces import flat_box

N = 1.5


def _slab_angle(rho: float, above: float, below: float, thickness: float) -> float:
    """The eye ray's angle from the vertical that reaches a point ``rho`` across, ``above``
    the slab's top (the eye) and ``below`` its bottom (the point):
    rho = (above + below) tan(theta) + thickness tan(theta'), sin(theta) = N sin(theta')."""
    lo, hi = 0.0, np.pi / 2 - 1e-9
    for _ in range(200):
        theta = 0.5 * (lo + hi)
        reach = (above + below) * np.tan(theta) + thickness * np.tan(np.arcsin(np.sin(theta) / N))
        lo, hi = (theta, hi) if reach < rho else (lo, theta)
    return 0.5 * (lo + hi)


def test_points_under_a_slab_appear_where_the_closed_form_puts_them():
    """Under a glass slab every point has one image, on the eye ray whose angle solves the
    slab's closed form; the solver's pixel is within a thousandth of a pixel of it."""
    thickness = 0.4
    glass = GlassSet([Glass(flat_box("Slab", (-20, -20, -thickness / 2), (20, 20, thickness / 2)), N)])
    eye = np.array([0.0, 0.0, 3.0])
    view = look_at_view(eye, (0.3, 0.2, 0.0), fov_y_deg=50.0, width=160, height=120)
    rng = np.random.default_rng(7)
    points = np.c_[rng.uniform(-1.0, 1.5, 12), rng.uniform(-0.8, 1.2, 12), np.full(12, -1.0)]
    found = solve_refractions(glass, view, points)
    assert list(found.count_per_point(len(points))) == [1] * len(points)
    assert np.all((found.history[:, :2] == 0).all(axis=1) & (found.history[:, 2:] == -1).all(axis=1))
    expected = []
    for p in points[found.point]:
        rho, phi = np.hypot(*(p[:2] - eye[:2])), np.arctan2(*(p[:2] - eye[:2])[::-1])
        theta = _slab_angle(rho, eye[2] - thickness / 2, -thickness / 2 - p[2], thickness)
        direction = np.array([np.cos(phi) * np.sin(theta), np.sin(phi) * np.sin(theta), -np.cos(theta)])
        expected.append(view.to_pixels((eye + direction)[None])[0][0])
    assert np.abs(found.pixel - np.array(expected)).max() < 1e-3


def test_through_a_glass_ball_every_image_lies_on_its_traced_path_and_a_finer_grid_finds_no_more():
    """A point on the axis behind a glass ball appears at the ball's centre (symmetry).
    Points around it: every image's pixel, traced again, passes its point; the grid of
    the solver a pixel apart finds the same images as the one two pixels apart."""
    glass = GlassSet([Glass(icosphere((0.0, 0.0, 0.0), 1.0, 4, "Ball"), N)])
    view = look_at_view((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov_y_deg=30.0, width=120, height=120)
    rng = np.random.default_rng(3)
    points = np.concatenate([[[0.0, 0.0, -3.0]], np.c_[rng.uniform(-1.5, 1.5, (30, 2)), rng.uniform(-4, -2, 30)]])
    found = solve_refractions(glass, view, points)
    on_axis = found.point == 0
    assert on_axis.sum() == 1 and np.abs(found.pixel[on_axis] - 60.0).max() < 1e-3
    paths = glass.trace(*view.pixel_rays(found.pixel))
    offset = points[found.point] - paths.origin
    miss = np.linalg.norm(offset - np.einsum("ij,ij->i", offset, paths.direction)[:, None] * paths.direction, axis=1)
    assert miss.max() < 1e-6 and np.all(paths.interfaces == 2)
    assert (found.count_per_point(len(points)) > 0).sum() >= 15
    finer = solve_refractions(glass, view, points, stride=1.0)
    assert np.array_equal(finer.count_per_point(len(points)), found.count_per_point(len(points)))


def test_a_sample_based_camera_on_refracted_rays_places_the_exact_images():
    """The SBC paper's refraction (section VII, Fig. 20b): a camera built on the ray map
    of refracted rays (one ray per 2 x 2 pixels) projects points behind a glass ball
    within half a pixel of where the exact solver finds them (measured: p99 0.16 px);
    it answers 94 % of the exact images (the rest lie between its sheets and in the
    last cells of the ball's footprint, which a render traces)."""
    from curved_reflections.tools.glass_camera import build_glass_camera

    glass = GlassSet([Glass(icosphere((0.0, 0.0, 0.0), 1.0, 4, "Ball"), N)])
    view = look_at_view((0.3, -0.2, 5.0), (0.0, 0.0, 0.0), fov_y_deg=30.0, width=160, height=160)
    rng = np.random.default_rng(11)
    points = np.c_[rng.uniform(-1.5, 1.5, (400, 2)), rng.uniform(-4.0, -2.0, 400)]
    exact = solve_refractions(glass, view, points)
    assert len(exact.point) == 400  # one image each: every point is seen through the ball
    camera = build_glass_camera(glass, view, ((-5, -5, -5), (5, 5, 6)), downsample=2, accuracy_px=1.0)
    assert all(history == (0,) for history in camera.histories)
    found = camera.project(points)
    distance = np.linalg.norm(found.pixels[:, exact.point] - exact.pixel[None], axis=2)
    error = np.where(found.valid[:, exact.point], distance, np.inf).min(axis=0)
    answered = np.isfinite(error)
    assert answered.mean() > 0.9 and np.percentile(error[answered], 99) < 0.5
