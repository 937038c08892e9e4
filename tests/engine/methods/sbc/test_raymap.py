# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np

from curved_reflections.engine import look_at_view
from curved_reflections.engine.methods.sbc import raymap
from curved_reflections.engine.methods.sbc.raymap import box_exit_distance, reflect_primary_hits, trace_ray_map
from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.engine.geometry.sphere import icosphere

BOUNDS = ([-4.0, -4.0, -1.0], [4.0, 4.0, 4.0])


def test_first_order_rays_obey_the_reflection_law_on_a_sphere():
    center = np.array([0.0, 0.0, 1.0])
    reflectors = ReflectorSet([icosphere(center, 1.0, 4)])
    view = look_at_view([5, -4, 2.5], center, width=120, height=80)
    ray_map = trace_ray_map(reflectors, view, BOUNDS, downsample=2)
    assert ray_map.histories == [(0,)] and ray_map.columns == 60 and ray_map.rows == 40
    np.testing.assert_array_equal(ray_map.tail, ray_map.first_point)
    normal = ray_map.tail - center
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    to_eye = view.directions_to_eye(ray_map.tail)
    # Angle of incidence equals angle of reflection, in the plane of the normal.
    np.testing.assert_allclose(np.einsum("ij,ij->i", to_eye, normal),
                               np.einsum("ij,ij->i", ray_map.direction, normal), atol=1e-9)
    np.testing.assert_allclose(np.cross(to_eye + ray_map.direction, normal), 0, atol=1e-9)
    # Heads lie on the scene box; first points project to their cells' pixel centres.
    head = ray_map.head
    on_face = np.isclose(head, BOUNDS[0], atol=1e-9) | np.isclose(head, BOUNDS[1], atol=1e-9)
    assert on_face.any(axis=1).all()
    pixels, _ = view.to_pixels(ray_map.first_point)
    np.testing.assert_allclose(pixels, ray_map.cell_pixels(ray_map.cell), atol=1e-6)


def test_two_spheres_give_histories_up_to_the_max_order_and_clip_heads():
    a, b = icosphere([0, -1.1, 1], 1.0, 3, name="A"), icosphere([0, 1.1, 1], 1.0, 3, name="B")
    reflectors = ReflectorSet([a, b])
    view = look_at_view([6, -1, 2.5], [0, 0, 1], width=160, height=100)
    ray_map = trace_ray_map(reflectors, view, BOUNDS, downsample=2, max_order=2)
    assert ray_map.histories == [(0,), (1,), (0, 1), (1, 0)]
    second = ray_map.order == 2
    assert second.any()
    # A first-order ray that goes on to the other sphere ends there, where the second starts.
    first_then = np.flatnonzero((ray_map.order == 1) & np.isin(ray_map.cell[:, 0] * 1000 + ray_map.cell[:, 1],
                                                               ray_map.cell[second, 0] * 1000 + ray_map.cell[second, 1]))
    key = {tuple(c): k for k, c in zip(np.flatnonzero(second), ray_map.cell[second])}
    follow = np.array([key[tuple(ray_map.cell[k])] for k in first_then])
    np.testing.assert_allclose(ray_map.head[first_then], ray_map.tail[follow], atol=1e-9)
    assert ray_map.blocked[first_then].all()
    free = ~ray_map.blocked
    on_box = np.isclose(ray_map.head[free], BOUNDS[0], atol=1e-9) | np.isclose(ray_map.head[free], BOUNDS[1], atol=1e-9)
    assert free.any() and on_box.any(axis=1).all()
    np.testing.assert_array_equal(ray_map.first_point[follow], ray_map.first_point[first_then])
    # Each sphere is one smooth piece: surface histories follow the reflection histories.
    assert ray_map.surfaces == [(0,), (1,), (0, 1), (1, 0)]
    np.testing.assert_array_equal(ray_map.surface, ray_map.group)


def test_surface_histories_follow_the_smooth_pieces_of_a_mirror():
    """A teapot's rays are numbered by the piece they reflect off (body, lid, spout...);
    one reflection history, several surface histories, each ray's surface its tail's piece."""
    from curved_reflections.engine import Reflector
    from curved_reflections.engine.geometry import shapes

    teapot = shapes.teapot(32)
    reflectors = ReflectorSet([Reflector("Teapot", teapot.vertices, teapot.triangles, teapot.normals)])
    view = look_at_view([4.5, -3.0, 2.6], [0.3, 0, 0.8], width=160, height=120)
    ray_map = trace_ray_map(reflectors, view, BOUNDS, downsample=2)
    assert ray_map.histories == [(0,)] and len(ray_map.surfaces) >= 4
    np.testing.assert_array_equal([ray_map.surfaces[k][0] for k in ray_map.surface],
                                  reflectors.piece[ray_map.triangle])
    body = ray_map.group_grid(0, [0])
    everything = ray_map.group_grid(0)
    assert 0 < (body >= 0).sum() < (everything >= 0).sum()
    np.testing.assert_array_equal(body[body >= 0], everything[body >= 0])


def test_box_exit_distance():
    d = box_exit_distance(np.array([[0.0, 0, 0], [0, 0, 0]]), np.array([[1.0, 0, 0], [0, 0.6, 0.8]]),
                          [-1, -2, -3], [2, 2, 2])
    np.testing.assert_allclose(d, [2.0, 2.5])


def test_view_rays_missing_the_bounding_sphere_are_not_traced_and_change_nothing(monkeypatch):
    """trace_ray_map traces only view rays whose line meets the reflectors' bounding sphere;
    the ray map equals the one from tracing every ray, up to the second order."""
    a, b = icosphere([0, -1.1, 1], 1.0, 3, name="A"), icosphere([0, 1.1, 1], 1.0, 3, name="B")
    reflectors = ReflectorSet([a, b])
    view = look_at_view([7, -3, 4], [0, 0, 1], width=160, height=120, fov_y_deg=60)
    traced = []
    intersect = reflectors.intersect

    def counting(origins, directions, *args, **kwargs):
        traced.append(len(origins))
        return intersect(origins, directions, *args, **kwargs)

    monkeypatch.setattr(reflectors, "intersect", counting)
    culled = trace_ray_map(reflectors, view, BOUNDS, downsample=2, max_order=2)
    monkeypatch.undo()
    origins, directions = view.pixel_rays(view.pixel_grid(2))
    hits = reflectors.intersect(origins, directions)
    full = reflect_primary_hits(reflectors, view, BOUNDS, 2, 2, hits.hit, hits.triangle, hits.t, origins,
                                directions, hits.normal, hits.face_normal)
    assert traced[0] < 0.6 * len(origins) and 0 < hits.hit.sum() <= traced[0]
    assert culled.histories == full.histories and culled.n_rays == full.n_rays > 200
    for name in ("cell", "order", "group", "first_point", "first_depth", "tail", "direction", "head_distance",
                 "triangle", "blocked"):
        np.testing.assert_array_equal(getattr(culled, name), getattr(full, name), err_msg=name)
    assert raymap.SPHERE_CULL_MARGIN > 0


def test_rays_that_start_inside_a_sealed_mirror_end_there():
    """The view's clip start inside a mirror ball that holds nothing: its view rays meet
    the ball from inside, where they would bounce without end and show no object; the
    ray map has none of them. Unsealed (something inside), they are traced as before."""
    center = np.array([0.0, 0.0, 1.0])
    reflectors = ReflectorSet([icosphere(center, 1.0, 3)])
    view = look_at_view(center + (0.0, -1.05, 0.0), center + (0.0, 1.0, 0.0), width=40, height=30,
                        near=0.1)
    traced = trace_ray_map(reflectors, view, BOUNDS, downsample=2, max_order=2)
    assert traced.n_rays > 300
    reflectors.seal_empty_interiors([])
    assert reflectors.sealed[0] == 1
    assert trace_ray_map(reflectors, view, BOUNDS, downsample=2, max_order=2).n_rays == 0
