# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np
import pytest

from curved_reflections.engine import SceneInputError, View, look_at_view


def test_point_on_optical_axis_projects_to_image_centre():
    view = look_at_view([0, -5, 0], [0, 0, 0], width=320, height=240)
    pixels, depth = view.to_pixels(np.array([[0.0, 0.0, 0.0]]))
    np.testing.assert_allclose(pixels[0], [160.0, 120.0], atol=1e-9)
    assert -1 < depth[0] < 1


def test_pixel_convention_x_right_y_up_origin_bottom_left():
    view = look_at_view([0, -5, 0], [0, 0, 0], up=(0, 0, 1), width=320, height=240)
    pixels, _ = view.to_pixels(np.array([[1.0, 0, 0], [0, 0, 1.0]]))
    assert pixels[0, 0] > 160 and abs(pixels[0, 1] - 120) < 1e-9  # world +X is screen right
    assert pixels[1, 1] > 120 and abs(pixels[1, 0] - 160) < 1e-9  # world +Z is screen up


def test_pixel_rays_pass_through_their_pixels():
    view = look_at_view([3, -4, 2], [0, 0, 0.5], width=200, height=100)
    rng = np.random.default_rng(0)
    pixels = rng.uniform([0, 0], [200, 100], (500, 2))
    origins, directions = view.pixel_rays(pixels)
    reprojected, _ = view.to_pixels(origins + 3.7 * directions)
    np.testing.assert_allclose(reprojected, pixels, atol=1e-8)
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0)


def test_window_points_undo_the_projection_to_pixels_and_depth():
    view = look_at_view([3, -4, 2], [0, 0, 0.5], width=200, height=100)
    points = np.random.default_rng(1).uniform(-1.0, 1.0, (300, 3))
    pixels, depth = view.to_pixels(points)
    window = 0.5 * depth + 0.5  # a depth buffer's [0, 1]
    np.testing.assert_allclose(view.window_points(pixels, window), points, atol=1e-9)
    # float32 depth, as read back from the GPU: about 1e-4 of the distance here
    rounded = view.window_points(pixels, window.astype(np.float32))
    assert np.max(np.linalg.norm(rounded - points, axis=1)) < 1e-3
    assert np.isnan(view.window_points(pixels[:2], np.ones(2))).all()  # the cleared far plane


def test_pixel_grid_centres_of_downsampled_pixels():
    view = look_at_view([0, -5, 0], [0, 0, 0], width=8, height=4)
    grid = view.pixel_grid(2)
    assert grid.shape == (8, 2)
    np.testing.assert_allclose(grid[:4, 0], [1, 3, 5, 7])
    np.testing.assert_allclose(grid[::4, 1], [1, 3])


def test_orthographic_view_has_parallel_rays_and_no_eye():
    projection = np.diag([0.5, 0.5, -0.1, 1.0])
    projection[2, 3] = -1.0
    view = View(np.eye(4), projection, 100, 100)
    assert not view.is_perspective
    _, directions = view.pixel_rays(np.array([[10.0, 10.0], [90.0, 50.0]]))
    np.testing.assert_allclose(directions, [[0, 0, -1], [0, 0, -1]], atol=1e-12)
    np.testing.assert_allclose(view.directions_to_eye(np.zeros((2, 3))), [[0, 0, 1], [0, 0, 1]])
    with pytest.raises(ValueError, match="orthographic"):
        view.eye


def test_points_behind_the_eye_are_not_in_view():
    view = look_at_view([0, -5, 0], [0, 0, 0])
    inside = view.in_view(np.array([[0.0, 0, 0], [0, -10, 0], [50, 0, 0]]))
    assert inside.tolist() == [True, False, False]


@pytest.mark.parametrize("matrix, message", [
    (np.full((4, 4), np.nan), "finite"),
    (np.zeros((4, 4)), "singular"),
    (np.eye(3), "4x4"),
])
def test_bad_matrices_are_clear_errors(matrix, message):
    with pytest.raises(SceneInputError, match=message) as error:
        View(matrix, np.eye(4), 10, 10, name="Camera.001")
    assert error.value.object_name == "Camera.001"


def test_one_view_equality_rule_same_size_and_matrices_within_the_tolerance():
    from curved_reflections.engine.view import VIEW_TOLERANCE

    view = look_at_view((0.0, -5.0, 1.0), (0.0, 0.0, 1.0), width=64, height=48)
    nudged = View(view.view_matrix + 0.5 * VIEW_TOLERANCE, view.projection_matrix, 64, 48)
    moved = View(view.view_matrix + 4.0 * VIEW_TOLERANCE, view.projection_matrix, 64, 48)
    resized = View(view.view_matrix, view.projection_matrix, 64, 49)
    assert view.same_as(view) and view.same_as(nudged) and nudged.same_as(view)
    assert not view.same_as(moved) and not view.same_as(resized)
