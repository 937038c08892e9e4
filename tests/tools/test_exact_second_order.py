# SPDX-License-Identifier: GPL-3.0-or-later
"""The second-order exact solver: plane-mirror pair (closed form) and two spheres (dense trace)."""

import numpy as np
import pytest

from curved_reflections.engine import Reflector, look_at_view
from curved_reflections.tools.exact_paths import solve_second_order
from curved_reflections.engine.methods.sbc.raymap import trace_ray_map
from curved_reflections.engine.geometry.raytrace import ReflectorSet, reflect
from curved_reflections.engine.geometry.sphere import icosphere

WEDGE = np.radians(70.0)
#: Plane mirror B: through the y axis at 70 degrees to mirror A (the plane z = 0), facing into the wedge.
B_UP = np.array([np.cos(WEDGE), 0.0, np.sin(WEDGE)])
B_NORMAL = np.array([np.sin(WEDGE), 0.0, -np.cos(WEDGE)])
EXTENT = 3.0
#: The mirrors start this far from the wedge's edge, so that no facet of one touches the
#: other (the tracer never lets a ray hit the one-ring of the facet it leaves).
START = 0.3
MARGIN = 0.05


def _plane(name, origin, axis_a, axis_b, normal, n=6):
    """An n x n grid of quads spanning origin + [0, EXTENT] axis_a + [-EXTENT/2, EXTENT/2] axis_b."""
    s, t = np.meshgrid(np.linspace(0, EXTENT, n + 1), np.linspace(-EXTENT / 2, EXTENT / 2, n + 1), indexing="ij")
    vertices = origin + s.reshape(-1, 1) * axis_a + t.reshape(-1, 1) * axis_b
    index = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    triangles = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    if np.cross(axis_a, axis_b) @ normal < 0:
        triangles = triangles[:, ::-1]  # wound counter-clockwise seen from the normals' side
    return Reflector(name, vertices, triangles, np.tile(normal, (len(vertices), 1)))


def _mirror(points, normal):
    """Mirror image in a plane through the origin."""
    return points - 2 * (points @ normal)[:, None] * normal


def _in_plane_extent(x, axis_a, margin):
    s, t = x @ axis_a, x[:, 1]
    return (s > START + margin) & (s < START + EXTENT - margin) & (np.abs(t) < EXTENT / 2 - margin)


def _crossing(start, end, normal):
    """Where the segment start -> end crosses a plane through the origin, and its parameter."""
    a, b = start @ normal, end @ normal
    t = a / (a - b)
    return start + t[:, None] * (end - start), t


def test_plane_pair_matches_the_double_mirror_image_to_1e_9_px():
    a_normal, x_axis, y_axis = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    reflectors = ReflectorSet([_plane("A", START * x_axis, x_axis, y_axis, a_normal),
                               _plane("B", START * B_UP, B_UP, y_axis, B_NORMAL)])
    eye = np.array([5.0 * np.cos(0.6), -4.0, 5.0 * np.sin(0.6)])
    view = look_at_view(eye, [0.8, 0.0, 0.7], width=320, height=240, fov_y_deg=60)
    rng = np.random.default_rng(5)
    angle, radius = rng.uniform(0.1, WEDGE - 0.1, 400), rng.uniform(0.4, 2.5, 400)
    points = np.stack([radius * np.cos(angle), rng.uniform(-1.2, 1.2, 400), radius * np.sin(angle)], axis=1)
    found = solve_second_order(reflectors, view, points)
    visible = found.select(found.visible)
    assert np.all(found.history[:, 0] != found.history[:, 1])

    compared = 0
    for first, second, n1, n2, axis1, axis2 in ((0, 1, a_normal, B_NORMAL, x_axis, B_UP),
                                               (1, 0, B_NORMAL, a_normal, B_UP, x_axis)):
        # Unfolded path: eye -> image of p in n2 then n1; x1 and x2 where it crosses the mirrors.
        image = _mirror(_mirror(points, n2), n1)
        x1, t1 = _crossing(np.broadcast_to(eye, points.shape), image, n1)
        x2, t2 = _crossing(x1, _mirror(points, n2), n2)
        crosses = (t1 > 0) & (t1 < 1) & (t2 > 0) & (t2 < 1) & view.in_view(x1)
        to_x1 = x1 - eye
        crosses &= ~reflectors.occluded(np.broadcast_to(eye, points.shape),
                                        to_x1 / np.linalg.norm(to_x1, axis=1, keepdims=True),
                                        np.linalg.norm(to_x1, axis=1) * (1 - 1e-6))
        # Paths within MARGIN of a mirror's edge may go either way; they are left out.
        ok = crosses & _in_plane_extent(x1, axis1, MARGIN) & _in_plane_extent(x2, axis2, MARGIN)
        maybe = crosses & _in_plane_extent(x1, axis1, -MARGIN) & _in_plane_extent(x2, axis2, -MARGIN)
        mask = (visible.history[:, 0] == first) & (visible.history[:, 1] == second)
        found_points = set(visible.point[mask].tolist())
        assert set(np.flatnonzero(ok).tolist()) <= found_points
        assert found_points <= set(np.flatnonzero(maybe).tolist())
        assert len(found_points) == int(mask.sum())  # one path per point and history
        expected_pixel, _ = view.to_pixels(x1)
        rows = np.flatnonzero(mask)
        rows = rows[ok[visible.point[rows]]]
        p = visible.point[rows]
        assert np.abs(visible.pixel[rows] - expected_pixel[p]).max() < 1e-9
        assert np.abs(visible.first[rows] - x1[p]).max() < 1e-9
        assert np.abs(visible.second[rows] - x2[p]).max() < 1e-9
        compared += len(rows)
    assert compared > 100


@pytest.fixture(scope="module")
def two_spheres():
    return ReflectorSet([icosphere(centre, radius, 4, name) for (centre, radius), name in zip(SPHERES, "AB")])


@pytest.fixture(scope="module")
def sphere_view():
    return look_at_view([0.3, -6.0, 2.2], [-0.1, 0.0, 0.9], width=240, height=160, fov_y_deg=30)


SPHERES = (([-1.05, 0.0, 1.0], 1.0), ([0.85, -0.25, 0.75], 0.75))


def _points_near_the_gap(n, seed):
    """Points around the gap between the spheres, outside both (with a margin)."""
    rng = np.random.default_rng(seed)
    points = rng.uniform([-0.8, -1.6, 0.0], [0.8, 1.6, 2.2], (3 * n, 3))
    outside = np.ones(len(points), dtype=bool)
    for centre, radius in SPHERES:
        outside &= np.linalg.norm(points - centre, axis=1) > radius + 0.02
    return points[outside][:n]


@pytest.fixture(scope="module")
def gap_paths(two_spheres, sphere_view):
    """200 points around the gap and every second-order path the solver finds for them:
    solved once for the tests that check those paths (read only)."""
    points = _points_near_the_gap(200, seed=4)
    return points, solve_second_order(two_spheres, sphere_view, points)


def test_sphere_pair_paths_obey_the_reflection_law_when_traced(two_spheres, sphere_view, gap_paths):
    """Trace the view ray through each solution's pixel, reflect twice: it passes through p."""
    points, found = gap_paths  # 366 visible paths, both histories
    visible = found.select(found.visible)
    assert len(visible.point) > 60
    assert {tuple(h) for h in visible.history} == {(0, 1), (1, 0)}
    origins, directions = sphere_view.pixel_rays(visible.pixel)
    first = two_spheres.intersect(origins, directions)
    assert np.array_equal(first.triangle, visible.triangle[:, 0])
    assert np.abs(first.position - visible.first).max() < 1e-9
    across = reflect(directions, first.normal)
    second = two_spheres.intersect(first.position, across, np.inf, first.triangle)
    assert np.array_equal(second.triangle, visible.triangle[:, 1])
    leaving = reflect(across, second.normal)
    offset = points[visible.point] - second.position
    along = np.einsum("ij,ij->i", offset, leaving)
    miss = np.linalg.norm(offset - along[:, None] * leaving, axis=1)
    assert (along > 0).all() and miss.max() < 1e-8


def _dense_images(ray_map, group, points):
    """Sub-pixel image of each point in one group of a full-resolution ray map, NaN where none.

    The ray passing closest to the point, then a least-squares linear fit of the miss
    vector over that ray and its four neighbours solved for zero miss.
    """
    grid = ray_map.group_grid(group)
    rays = np.flatnonzero(ray_map.group == group)
    tail, direction = ray_map.tail[rays], ray_map.direction[rays]
    offset = points[:, None, :] - tail[None]
    along = np.einsum("prd,rd->pr", offset, direction)
    miss = np.linalg.norm(offset - along[..., None] * direction[None], axis=2)
    reach = np.where(ray_map.blocked[rays], ray_map.head_distance[rays], np.inf)
    miss = np.where((along > 0) & (along < reach[None]), miss, np.inf)
    best = rays[np.argmin(miss, axis=1)]
    result = np.full((len(points), 2), np.nan)
    steps = np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1]])
    for k, ray in enumerate(best):
        cells = ray_map.cell[ray] + steps
        if np.any(cells < 0) or np.any(cells[:, 0] >= ray_map.columns) or np.any(cells[:, 1] >= ray_map.rows):
            continue
        stencil = grid[cells[:, 1], cells[:, 0]]
        if np.any(stencil < 0):
            continue
        d = ray_map.direction[ray]
        basis = np.linalg.svd(np.eye(3) - np.outer(d, d))[0][:, :2]
        off = points[k] - ray_map.tail[stencil]
        along_stencil = np.einsum("sd,sd->s", off, ray_map.direction[stencil])
        if np.any(ray_map.blocked[stencil] & (along_stencil >= ray_map.head_distance[stencil])):
            continue  # at the rim of another mirror's shadow
        perpendicular = off - along_stencil[:, None] * ray_map.direction[stencil]
        design = np.concatenate([np.ones((5, 1)), steps], axis=1)
        coefficients = np.linalg.lstsq(design, perpendicular @ basis, rcond=None)[0]
        shift = np.linalg.solve(coefficients[1:].T, -coefficients[0])
        if np.abs(shift).max() > 2.0:
            continue
        result[k] = ray_map.cell_pixels(ray_map.cell[ray] + shift)
    return result


def _traced_miss(reflector_set, view, pixels, points, history):
    """(K, 3) miss vector of each point from the ray traced through a pixel and reflected
    twice, NaN where that ray's history differs."""
    origins, directions = view.pixel_rays(pixels)
    first = reflector_set.intersect(origins, directions)
    across = reflect(directions, first.normal)
    second = reflector_set.intersect(first.position, across, np.inf, first.triangle)
    leaving = reflect(across, second.normal)
    offset = points - second.position
    miss = offset - np.einsum("ij,ij->i", offset, leaving)[:, None] * leaving
    same = (first.reflector == history[0]) & (second.reflector == history[1])
    return np.where(same[:, None], miss, np.nan)


def _refined_by_tracing(reflector_set, view, pixels, points, history, iterations=8):
    """Sub-pixel images refined by Newton's method on traced rays (finite-difference Jacobian)."""
    q = pixels.copy()
    h = 1e-4
    for _ in range(iterations):
        miss = _traced_miss(reflector_set, view, q, points, history)
        du = (_traced_miss(reflector_set, view, q + [h, 0], points, history) - miss) / h
        dv = (_traced_miss(reflector_set, view, q + [0, h], points, history) - miss) / h
        jacobian = np.stack([du, dv], axis=2)
        normal = np.einsum("kdi,kdj->kij", jacobian, jacobian)  # least squares: (J^T J) step = J^T miss
        q = q - np.linalg.solve(normal, np.einsum("kdi,kd->ki", jacobian, miss)[:, :, None])[:, :, 0]
    final = _traced_miss(reflector_set, view, q, points, history)
    return np.where((np.linalg.norm(final, axis=1) < 1e-9)[:, None], q, np.nan)


def test_sphere_pair_matches_a_dense_second_order_trace(two_spheres, sphere_view, gap_paths):
    points, found = gap_paths
    visible = found.select(found.visible)
    bounds = (np.array([-3.0, -3.0, -0.5]), np.array([3.0, 3.0, 3.0]))
    ray_map = trace_ray_map(two_spheres, sphere_view, bounds, downsample=1, max_order=2)
    errors, traced_total, well_inside, well_inside_traced = [], 0, 0, 0
    for history in ((0, 1), (1, 0)):
        dense = _dense_images(ray_map, ray_map.histories.index(history), points)
        traced = np.flatnonzero(np.isfinite(dense[:, 0]))
        dense[traced] = _refined_by_tracing(two_spheres, sphere_view, dense[traced], points[traced], history)
        assert np.isfinite(dense[traced]).all()
        mine = (visible.history[:, 0] == history[0]) & (visible.history[:, 1] == history[1])
        exact_pixel = np.full((len(points), 2), np.nan)
        exact_pixel[visible.point[mine]] = visible.pixel[mine]
        # Every point the dense trace sees has an exact path of the same history, close by.
        assert np.isfinite(exact_pixel[traced, 0]).all()
        errors.append(np.linalg.norm(exact_pixel[traced] - dense[traced], axis=1))
        traced_total += len(traced)
        # Exact images whose 5 x 5 pixels all belong to the group are seen by the trace.
        inner = _eroded(ray_map.group_grid(ray_map.histories.index(history)) >= 0, 2)
        cells = np.floor(visible.pixel[mine]).astype(np.int64)
        inside = inner[cells[:, 1], cells[:, 0]]
        # ... unless one of the 3 x 3 rays around it meets another mirror before the point
        # (the rim of that mirror's shadow, where the trace's stencil is skipped).
        grid = ray_map.group_grid(ray_map.histories.index(history))
        shifts = np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1]), axis=-1).reshape(-1, 2)
        around = np.clip(cells[:, None, :] + shifts, 0, np.array([ray_map.columns, ray_map.rows]) - 1)
        rays = np.maximum(grid[around[..., 1], around[..., 0]], 0)
        along = np.einsum("krd,krd->kr", points[visible.point[mine]][:, None] - ray_map.tail[rays],
                          ray_map.direction[rays])
        inside &= ~np.any(ray_map.blocked[rays] & (along >= ray_map.head_distance[rays]), axis=1)
        well_inside += int(inside.sum())
        well_inside_traced += int(np.isfinite(dense[visible.point[mine][inside], 0]).sum())
    error = np.concatenate(errors)
    assert traced_total > 50
    # Both are exact on the same surface: they agree to rounding.
    assert error.max() < 1e-5
    # And the dense trace sees the exact solutions away from its footprint's rim (the few
    # others lie where another mirror's shadow begins, which the stencil test skips).
    assert well_inside > 10 and well_inside_traced >= 0.9 * well_inside


def _eroded(mask, radius):
    rows, columns = mask.shape
    padded = np.pad(mask, radius, constant_values=False)
    inner = np.ones_like(mask)
    for dj in range(-radius, radius + 1):
        for di in range(-radius, radius + 1):
            inner &= padded[radius + dj:radius + dj + rows, radius + di:radius + di + columns]
    return inner
