# SPDX-License-Identifier: GPL-3.0-or-later
"""Second-order groups of the sample-based camera against the exact second-order solver
(SBC paper III-B: histories (A, B) and (B, A) of the two-spheres demo's mirrors)."""

import numpy as np
import pytest

from curved_reflections.engine import Reflector, look_at_view
from curved_reflections.engine.methods.sbc import build_sample_based_camera
from curved_reflections.engine.geometry import shapes
from curved_reflections.tools.exact_paths import solve_second_order
from curved_reflections.engine.geometry.raytrace import ReflectorSet

#: The two-spheres demo's mirrors (blender/demo_scenes.py), built without bpy.
SPHERES = (("MirrorSphereA", [-1.05, 0.0, 1.0], 1.0), ("MirrorSphereB", [0.85, -0.25, 0.75], 0.75))
BOUNDS = (np.array([-3.0, -3.0, -0.1]), np.array([3.0, 3.0, 3.0]))


@pytest.fixture(scope="module")
def scene():
    reflectors = []
    for name, centre, radius in SPHERES:
        sphere = shapes.sphere(radius, 64, 32)
        reflectors.append(Reflector(name, sphere.vertices + centre, sphere.triangles, sphere.normals))
    reflector_set = ReflectorSet(reflectors)
    view = look_at_view([0.3, -6.0, 2.2], [-0.1, 0.0, 0.9], width=240, height=160, fov_y_deg=30)
    rng = np.random.default_rng(2)
    points = rng.uniform([-0.8, -1.6, 0.0], [0.8, 1.6, 2.2], (600, 3))
    outside = np.ones(len(points), dtype=bool)
    for _, centre, radius in SPHERES:
        outside &= np.linalg.norm(points - centre, axis=1) > radius + 0.02
    points = points[outside][:250]
    exact = solve_second_order(reflector_set, view, points)
    return reflector_set, view, points, exact.select(exact.visible)


@pytest.fixture(scope="module")
def whole(scene):
    """The scene's camera at Max Order 2, every group in it, and its projection of the points."""
    reflector_set, view, points, _ = scene
    sbc = build_sample_based_camera(reflector_set, view, BOUNDS, max_order=2, downsample=2)
    return sbc, sbc.project(points)


def test_second_order_projections_match_the_exact_solver(scene, whole):
    reflector_set, view, points, exact = scene
    # d = 2 on a 240 x 160 view: the second-order footprints (each sphere's image of the
    # other) are a few dozen rays across; at d = 4 only a dozen, and p95 reaches 0.9 px.
    sbc, projection = whole
    assert {(0, 1), (1, 0)} <= set(sbc.groups)
    errors, projected, false = [], 0, 0
    for history in ((0, 1), (1, 0)):
        mine = (exact.history[:, 0] == history[0]) & (exact.history[:, 1] == history[1])
        point, pixel = exact.point[mine], exact.pixel[mine]
        has_exact = np.zeros(len(points), dtype=bool)
        has_exact[point] = True
        for g in [g for g, h in enumerate(projection.groups) if tuple(h) == history]:
            valid = projection.valid[g]
            both = valid[point]
            errors.append(np.linalg.norm(projection.pixels[g, point[both]] - pixel[both], axis=1))
            projected += int(valid.sum())
            false += int((valid & ~has_exact).sum())
    error = np.concatenate(errors)
    assert len(error) > 100
    assert np.percentile(error, 95) <= 1.0 and np.percentile(error, 50) <= 0.25
    assert false <= 0.02 * projected


def test_a_camera_for_the_higher_orders_alone_projects_them_as_the_whole_camera(scene, whole):
    """Both balls' first orders drawn by another method (the iterative search): the camera
    leaves their groups out, and its second-order answers are the whole camera's."""
    reflector_set, view, points, _ = scene
    whole, theirs = whole
    higher = build_sample_based_camera(reflector_set, view, BOUNDS, max_order=2, downsample=2,
                                       first_order_left_out=frozenset({0, 1}))
    assert higher.first_order_left_out == {0, 1}
    assert {tuple(h) for h in higher.groups} == {h for h in map(tuple, whole.groups) if len(h) > 1} == {(0, 1), (1, 0)}
    assert higher.stats["n_sheets"] < whole.stats["n_sheets"]
    assert higher.stats["n_rays"] == whole.stats["n_rays"]  # the ray map is the same: it finds the second orders
    mine = higher.project(points)
    # The same sheets, in the same order (a history has one group per sheet).
    second = [k for k, h in enumerate(theirs.groups) if len(h) > 1]
    assert [tuple(theirs.groups[k]) for k in second] == [tuple(h) for h in mine.groups]
    for g, k in enumerate(second):
        np.testing.assert_array_equal(mine.valid[g], theirs.valid[k])
        assert mine.valid[g].sum() > 10
        np.testing.assert_allclose(mine.pixels[g][mine.valid[g]], theirs.pixels[k][theirs.valid[k]], atol=1e-9)
    only_first = build_sample_based_camera(reflector_set, view, BOUNDS, max_order=2, downsample=2,
                                           first_order_left_out=frozenset({0}))
    assert {tuple(h) for h in only_first.groups} == {(1,), (0, 1), (1, 0)}
