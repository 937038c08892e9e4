# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np
import pytest

from curved_reflections.engine import Reflector, SceneInputError, look_at_view
from curved_reflections.engine.geometry.raytrace import ReflectorSet, reflect, reflection_valid
from curved_reflections.engine.geometry.sphere import icosphere

CENTER = np.array([0.0, 0.0, 1.0])


def _sphere_set(subdivisions=5, radius=1.0):
    return ReflectorSet([icosphere(CENTER, radius, subdivisions)])


def _analytic_sphere_t(origins, directions, radius=1.0):
    oc = origins - CENTER
    b = np.einsum("ij,ij->i", oc, directions)
    c = np.einsum("ij,ij->i", oc, oc) - radius ** 2
    disc = b * b - c
    return np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)


def test_view_rays_hit_the_sphere_where_the_analytic_sphere_is():
    reflectors = _sphere_set()
    view = look_at_view([4, -3, 2], CENTER, width=160, height=120, fov_y_deg=40)
    origins, directions = view.pixel_rays(view.pixel_grid(1))
    hits = reflectors.intersect(origins, directions)
    exact_t = _analytic_sphere_t(origins, directions)
    both = hits.hit & np.isfinite(exact_t)
    assert both.sum() > 0.95 * np.isfinite(exact_t).sum()
    # Hits lie on the flat facets: inside the sphere, no deeper than the deepest facet plane.
    assert np.all(hits.t[both] >= exact_t[both] - 1e-9)
    deepest_plane = np.einsum("ij,ij->i", reflectors.face_normals, reflectors.v0 - CENTER).min()
    radius = np.linalg.norm(hits.position[both] - CENTER, axis=1)
    assert 1 - deepest_plane < 3e-4
    assert np.all((radius <= 1 + 1e-12) & (radius >= deepest_plane - 1e-12))
    # On a sphere the interpolated normal is exactly radial at every facet point.
    radial = hits.position[both] - CENTER
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    np.testing.assert_allclose(hits.normal[both], radial, atol=1e-12)
    assert np.all(hits.reflector[hits.hit] == 0) and np.all(hits.reflector[~hits.hit] == -1)


def test_nearest_hit_over_several_reflectors_and_occlusion():
    near = icosphere([0, -2, 1], 0.5, 3, name="Near")
    far = icosphere([0, 2, 1], 0.5, 3, name="Far")
    reflectors = ReflectorSet([far, near])
    origins = np.array([[0.0, -5, 1], [0.0, 5, 1], [3.0, 0, 1]])
    directions = np.array([[0.0, 1, 0], [0.0, -1, 0], [0.0, 1, 0]])
    hits = reflectors.intersect(origins, directions)
    assert hits.reflector.tolist() == [1, 0, -1]
    np.testing.assert_allclose(hits.t[:2], [2.5, 2.5], atol=2e-3)
    assert reflectors.occluded(origins[:1], directions[:1], [4.0]).tolist() == [True]
    assert reflectors.occluded(origins[:1], directions[:1], [2.0]).tolist() == [False]


def test_rings_hold_a_triangle_and_every_triangle_sharing_a_vertex_with_it():
    reflectors = _sphere_set(subdivisions=2)
    corners = reflectors.welded_triangles
    asked = np.array([0, 17, len(corners) - 1, 17])
    owner, member = reflectors.ring(asked)
    for row, t in enumerate(asked):
        shares = np.flatnonzero(np.isin(corners, corners[t]).any(axis=1))
        np.testing.assert_array_equal(np.sort(member[owner == row]), shares)  # each once
        assert t in shares and len(shares) in (12, 13)  # 13 around valence-6 corners, 12 next to a valence-5 one


def test_rays_near_a_known_triangle_hit_as_the_bvh_finds_and_the_others_fall_back_to_it():
    """``intersect_near`` gives the BVH's answer where the true hit lies in the guess's
    ring, and falls back to the BVH without a guess or with one far away."""
    reflectors = ReflectorSet([icosphere(CENTER, 1.0, 4), icosphere(CENTER + [0.0, -2.2, 0.0], 0.3, 3)])
    view = look_at_view([4, -3, 2], CENTER, width=80, height=60, fov_y_deg=40)
    origins, directions = view.pixel_rays(view.pixel_grid(1))
    exact = reflectors.intersect(origins, directions)
    assert exact.hit.sum() > 500 and (exact.reflector == 1).sum() > 20  # the small ball hides part of the big one
    rng = np.random.default_rng(3)
    # A guess one ring away from the true triangle; no guess for a tenth of the rays.
    guess = np.where(exact.hit, exact.triangle, -1)
    owner, member = reflectors.ring(np.maximum(guess, 0))
    first = np.searchsorted(owner, np.arange(len(guess)))
    neighbour = member[first + rng.integers(0, 6, len(guess))]
    guess = np.where((guess >= 0) & (rng.random(len(guess)) > 0.1), neighbour, -1)
    near = reflectors.intersect_near(origins, directions, guess)
    np.testing.assert_array_equal(near.triangle, exact.triangle)
    np.testing.assert_allclose(near.position[exact.hit], exact.position[exact.hit], atol=1e-12)
    np.testing.assert_allclose(near.normal[exact.hit], exact.normal[exact.hit], atol=1e-12)
    # Guessing where the ray leaves the big ball finds that hit, behind the nearest one:
    # the ring is all it sees (true_rays.py checks its final answer with ``intersect``).
    front = exact.reflector == 0
    exits = reflectors.intersect(exact.position[front] + 1e-6 * directions[front], directions[front])
    back = np.full(len(origins), -1)
    back[front] = exits.triangle
    far = reflectors.intersect_near(origins, directions, back)
    behind = front & (far.triangle == back)
    assert behind.sum() > 100 and np.all(far.t[behind] > exact.t[behind] + 0.05)


def test_back_faces_are_mirrors_too_with_normals_turned_to_the_ray():
    sheet = Reflector("Sheet", [[-1, -1, 0], [1, -1, 0], [0, 1, 0]], [[0, 1, 2]], np.tile([0, 0, 1.0], (3, 1)))
    hits = ReflectorSet([sheet]).intersect(np.array([[0, 0, -1.0], [0, 0, 1.0]]), np.array([[0, 0, 1.0], [0, 0, -1.0]]))
    np.testing.assert_allclose(hits.normal, [[0, 0, -1], [0, 0, 1]])
    np.testing.assert_allclose(hits.face_normal, [[0, 0, -1], [0, 0, 1]])


def test_reflected_rays_leave_from_the_surface_without_hitting_it_again():
    reflectors = _sphere_set(subdivisions=4)
    view = look_at_view([4, -3, 2], CENTER, width=64, height=48)
    origins, directions = view.pixel_rays(view.pixel_grid(1))
    hits = reflectors.intersect(origins, directions)
    h = hits.hit
    reflected = reflect(directions[h], hits.normal[h])
    valid = reflection_valid(directions[h], hits.normal[h], hits.face_normal[h])
    assert valid.mean() > 0.97
    again = reflectors.intersect(hits.position[h][valid], reflected[valid], source_triangles=hits.triangle[h][valid])
    assert not again.hit.any()  # a convex mirror never sees itself


def test_reflect_mirrors_about_the_normal():
    d = np.array([[1.0, 0, -1]]) / np.sqrt(2)
    np.testing.assert_allclose(reflect(d, np.array([[0, 0, 1.0]])), [[1 / np.sqrt(2), 0, 1 / np.sqrt(2)]])


def test_empty_reflector_list_is_a_clear_error():
    with pytest.raises(SceneInputError, match="no reflector"):
        ReflectorSet([])


def _two_nested_spheres():
    """A ball inside a larger ball: rays from outside cross four surfaces, the nearest hit
    is the outer front one, and a wrong guess (the inner ball, or the far side) lies behind it."""
    return ReflectorSet([icosphere(CENTER, 1.0, 4), icosphere(CENTER, 0.5, 3)])


def test_guessed_triangles_and_distances_find_exactly_the_nearest_hits():
    reflectors = _two_nested_spheres()
    rng = np.random.default_rng(3)
    origins = CENTER + rng.normal(size=(4000, 3)) * 0.2 + np.array([0.0, -4.0, 0.0])
    directions = CENTER + rng.normal(size=(4000, 3)) * 0.6 - origins
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    plain = reflectors.intersect(origins, directions)
    assert plain.hit.mean() > 0.5 and set(np.unique(plain.reflector[plain.hit])) == {0}
    # Guesses: the true triangle, a wrong one behind it (the inner ball's), none, and distances
    # too short (the BVH must look past them) or too long.
    inner = len(reflectors.reflectors[0].triangles) + rng.integers(0, len(reflectors.reflectors[1].triangles), 4000)
    near = np.select([np.arange(4000) % 3 == 0, np.arange(4000) % 3 == 1], [plain.triangle, inner], -1)
    guess_t = np.where(np.arange(4000) % 2 == 0, 0.5 * plain.t, 2.0 * plain.t)
    for hits in (reflectors.intersect(origins, directions, near_triangles=near),
                 reflectors.intersect(origins, directions, t_guess=guess_t),
                 reflectors.intersect(origins, directions, near_triangles=near, t_guess=guess_t)):
        np.testing.assert_array_equal(hits.triangle, plain.triangle)
        np.testing.assert_array_equal(hits.t, plain.t)


def test_a_guessed_ring_never_returns_the_source_triangle_of_a_reflected_ray():
    reflectors = _sphere_set(4)
    view = look_at_view([0, -4, 1], CENTER, width=64, height=48, fov_y_deg=40)
    origins, directions = view.pixel_rays(view.pixel_grid(1))
    first = reflectors.intersect(origins, directions)
    inside = first.hit
    # Rays reflected inward (into the ball) from its surface: the source's ring is the guess.
    into = -reflect(directions[inside], first.normal[inside])
    plain = reflectors.intersect(first.position[inside], into, source_triangles=first.triangle[inside])
    guessed = reflectors.intersect(first.position[inside], into, source_triangles=first.triangle[inside],
                                   near_triangles=first.triangle[inside])
    assert plain.hit.mean() > 0.9
    np.testing.assert_array_equal(guessed.triangle, plain.triangle)
    assert not np.any(guessed.triangle == first.triangle[inside])


def _mesh(vertices):
    from types import SimpleNamespace

    return SimpleNamespace(vertices=np.asarray(vertices, dtype=np.float64))


def test_a_closed_mirror_holding_no_diffuse_geometry_is_sealed_and_rays_meet_it_from_inside():
    """A closed mirror is sealed unless a diffuse vertex lies inside it deeper than
    SEAL_DEPTH (a floor touching it at its lowest point does not count); a ray meets a
    sealed mirror from inside where it travels along its outward normal there."""
    reflectors = ReflectorSet([icosphere((0.0, 0.0, 0.0), 1.0, 3), icosphere((5.0, 0.0, 0.0), 1.0, 3)])
    pole = reflectors.vertices[np.argmin(reflectors.vertices[:50, 2])]
    reflectors.seal_empty_interiors([_mesh([pole, pole + (3.0, 0.0, 0.0)]), _mesh([(5.2, 0.1, 0.0)])])
    np.testing.assert_array_equal(reflectors.sealed, [1, 0])  # the second holds a vertex 0.8 deep
    reflectors.seal_empty_interiors([])  # the meshes changed: sealed again from scratch
    np.testing.assert_array_equal(reflectors.sealed, [1, 1])

    origins = np.array([[0.0, 0.0, 0.0], [0.0, -3.0, 0.0], [5.0, 0.0, 0.0]])
    directions = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    hits = reflectors.intersect(origins, directions)
    assert hits.hit.all()
    np.testing.assert_array_equal(reflectors.from_inside(directions, hits.triangle), [True, False, True])
    assert not reflectors.from_inside(directions[:1], [-1]).any()  # no hit


def test_an_open_or_inward_wound_mirror_is_sealed_with_its_own_sense():
    sphere = icosphere((0.0, 0.0, 0.0), 1.0, 2)
    open_cap = Reflector("Cap", sphere.vertices, sphere.triangles[sphere.vertices[sphere.triangles].mean(axis=1)[:, 2] > 0],
                         sphere.normals)
    inward = Reflector("Inward", sphere.vertices, sphere.triangles[:, ::-1], sphere.normals)
    reflectors = ReflectorSet([open_cap, inward])
    reflectors.seal_empty_interiors([])
    np.testing.assert_array_equal(reflectors.sealed, [0, -1])
    hits = ReflectorSet([inward]).intersect(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]))
    reflectors.sealed[:] = (0, -1)
    triangle = hits.triangle + len(open_cap.triangles)
    assert reflectors.from_inside(np.array([[0.0, 0.0, 1.0]]), triangle)[0]


def test_the_seal_finds_points_inside_through_the_bvh_as_every_triangle_tested_does():
    """Inside a closed mirror or not (``ReflectorSet._inside``, the seal's test): the
    same answers as ``closed_surfaces.inside``, which tests every triangle, on points
    around a ball and a torus (a non-convex solid: points in its hole are outside) set
    side by side, each point asked of each mirror."""
    from curved_reflections.engine.geometry import closed_surfaces
    from curved_reflections.tools.surfaces import torus

    mirrors = [icosphere((0.0, 0.0, 0.0), 1.0, 3, "Ball"), torus((4.0, 0.0, 0.0), 1.2, 0.4, 48, 24)]
    reflectors = ReflectorSet(mirrors)
    points = np.random.default_rng(3).uniform((-1.5, -1.5, -1.5), (6.0, 1.5, 1.5), (3000, 3))
    for index, mirror in enumerate(mirrors):
        expected = closed_surfaces.inside(mirror.vertices, mirror.triangles, points)
        assert 100 < expected.sum() < len(points) - 100
        np.testing.assert_array_equal(reflectors._inside(index, points), expected)



def test_a_set_is_built_a_block_of_triangles_at_a_time():
    """Issue 46 item 4: the set's construction (welding, smooth pieces, corner rows, the
    BVH) holds little beyond the arrays it keeps. Measured with tracemalloc (numpy
    reports its arrays to it): 255 bytes a triangle at its peak on 82k triangles, and
    139 kept (the corner rows, pieces, owners, the tree; the face normals are made when
    asked for); 635 and 221 when it made (T, 3, 3) corner arrays and their copies at
    once (+488 MB for a million-triangle mirror)."""
    import tracemalloc

    mirror = icosphere(CENTER, 1.0, 6)
    tracemalloc.start()
    try:
        reflectors = ReflectorSet([mirror])
        kept, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    n = len(mirror.triangles)
    assert peak < 400 * n and kept < 180 * n
    # What the set no longer keeps is the same when asked for.
    e1, e2 = reflectors.e1, reflectors.e2
    face = np.cross(e1, e2)
    face /= np.linalg.norm(face, axis=1)[:, None]
    np.testing.assert_allclose(reflectors.face_normals[[0, 5, n - 1]], face[[0, 5, n - 1]], rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(reflectors.face_normals), face, rtol=0, atol=1e-15)
    assert reflectors.welded_triangles is reflectors.triangles  # nothing to weld on an icosphere
