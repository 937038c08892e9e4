# SPDX-License-Identifier: GPL-3.0-or-later
"""The iterative search (Roger & Holzschuch 2006, engine/methods/iterative) on the test
reflectors of engine/geometry/sphere.py and tools/surfaces.py: which reflectors are
star-shaped, what the cube map returns, how close the search comes to the exact reference
solver (engine/reference/exact.py) in perspective and orthographic views, and what it says
of points and eyes it cannot answer for. Complements test_iterative_search.py (other
reflectors, views and points).

Meshes stay at 5,120 triangles and maps at faces of 32-48 texels: the whole file runs
in seconds on two cores.
"""

import numpy as np
import pytest

from curved_reflections.engine.geometry import shapes
from curved_reflections.engine.reference.exact import solve_reflections
from curved_reflections.engine.methods.iterative import (IterativeReflector, check_star_shaped, prepare_iterative,
                                                         search_reflections)
from curved_reflections.engine.methods.iterative.search import FOUND, INSIDE, NO_SURFACE
from curved_reflections.engine.projection import NOT_PROJECTED, SEARCH_ANSWER
from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.engine.scene import Reflector, vertex_normals
from curved_reflections.engine.geometry.sphere import bumpy_icosphere, icosphere
from curved_reflections.tools.surfaces import ellipsoid, torus
from curved_reflections.engine.view import View, look_at_view

O = np.array([-0.4, 0.25, 0.6])
RADII = (1.0, 0.6, 0.4)
FACE = 48


def _sphere(subdivisions=4):
    return icosphere(O, 1.0, subdivisions, name="Ball")


def _ellipsoid(subdivisions=4):
    return ellipsoid(O, RADII, subdivisions, name="Egg")


def _bumpy(subdivisions=4, amplitude=0.05):
    return bumpy_icosphere(O, 1.0, subdivisions, amplitude, name="Knobbly")


@pytest.fixture(scope="module")
def bakes():
    """Maps (faces of 48) of the three star-shaped reflectors, baked once."""
    made = {}
    for reflector in (_sphere(), _ellipsoid(), _bumpy()):
        shape, bake = prepare_iterative(reflector, FACE)
        assert shape.star_shaped, shape.reason
        made[reflector.name] = (reflector, bake.reflector_map)
    return made


def _points_outside(count, seed, spread=3.0, clearance=1.1):
    """``count`` points uniform in a cube of half side ``spread`` around O, farther than
    ``clearance`` (unit radius) from it: outside every test reflector."""
    rng = np.random.default_rng(seed)
    points = O + rng.uniform(-spread, spread, (6 * count, 3))
    return points[np.linalg.norm(points - O, axis=1) > clearance][:count]


def _orthographic(eye, target, half_height, width, height, near=0.0, far=20.0) -> View:
    """An orthographic view looking from ``eye`` at ``target``: the OpenGL ortho matrix
    of a box ``half_height`` high (square pixels) between ``near`` and ``far``."""
    projection = np.zeros((4, 4))
    projection[0, 0] = 1.0 / (half_height * width / height)
    projection[1, 1] = 1.0 / half_height
    projection[2, 2] = -2.0 / (far - near)
    projection[2, 3] = -(far + near) / (far - near)
    projection[3, 3] = 1.0
    return View(look_at_view(eye, target).view_matrix, projection, width, height, name="ortho")


def _compare(reflector, rmap, view, points):
    """Our answers against the exact visible reflections: (pixel errors of our answers
    that have one, coverage of the points that have one, share of our answers with none
    within 1 px, the cosine between the map normal and the direction to the eye at each
    of those)."""
    ours = IterativeReflector(0, reflector.name, rmap).project(view, points)
    exact = solve_reflections(ReflectorSet([reflector]), view, points)
    visible = exact.visible
    answered = np.flatnonzero(ours.valid[0])
    errors, near = [], np.zeros(len(points), dtype=bool)
    for point in answered:
        pixels = exact.pixel[visible & (exact.point == point)]
        if len(pixels):
            errors.append(np.linalg.norm(pixels - ours.pixels[0, point], axis=1).min())
            near[point] = errors[-1] <= 1.0
    wanted = np.unique(exact.point[visible])
    assert len(wanted) >= 0.2 * len(points)  # the comparison has something to compare
    false = answered[~near[answered]]
    position = ours.reflector_points[0, false]
    _, normal, _ = rmap.surface(normalize(position - rmap.centre))
    facing = np.einsum("ij,ij->i", normal, view.directions_to_eye(position))
    return np.array(errors), near[wanted].mean(), len(false) / len(answered), facing


def normalize(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


# --- The test reflectors -------------------------------------------------------------

def test_builders_give_the_surfaces_they_name():
    bumpy = _bumpy(3)
    d = icosphere((0, 0, 0), 1.0, 3).vertices
    theta, phi = np.arccos(np.clip(d[:, 2], -1, 1)), np.arctan2(d[:, 1], d[:, 0])
    np.testing.assert_allclose(np.linalg.norm(bumpy.vertices - O, axis=1),
                               1.0 + 0.05 * np.sin(5 * phi) * np.sin(4 * theta), atol=1e-12)
    np.testing.assert_allclose(bumpy.normals, vertex_normals(bumpy.vertices, bumpy.triangles), atol=1e-12)

    egg = _ellipsoid(3)
    local = egg.vertices - O
    np.testing.assert_allclose(((local / RADII) ** 2).sum(axis=1), 1.0, atol=1e-12)
    gradient = local / np.square(RADII)
    np.testing.assert_allclose(egg.normals, gradient / np.linalg.norm(gradient, axis=1, keepdims=True), atol=1e-12)

    ring = torus(O, 1.0, 0.3, 40, 16, name="Ring")
    local = ring.vertices - O
    across = np.linalg.norm(local[:, :2], axis=1)
    np.testing.assert_allclose((across - 1.0) ** 2 + local[:, 2] ** 2, 0.09, atol=1e-12)
    centre_line = np.concatenate([local[:, :2] / across[:, None], np.zeros((len(local), 1))], axis=1)
    np.testing.assert_allclose(ring.normals, (local - centre_line) / 0.3, atol=1e-12)
    corners = ring.vertices[ring.triangles]
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert (np.einsum("ij,ij->i", face, ring.normals[ring.triangles].sum(axis=1)) > 0).all()  # wound outward
    edges = np.sort(np.concatenate([ring.triangles[:, [0, 1]], ring.triangles[:, [1, 2]], ring.triangles[:, [2, 0]]]),
                    axis=1)
    _, count = np.unique(edges, axis=0, return_counts=True)
    assert (count == 2).all() and len(ring.vertices) - len(count) + len(ring.triangles) == 0  # closed, genus 1


# --- Star-shaped or not --------------------------------------------------------------

@pytest.mark.parametrize("make", [lambda: _sphere(3), lambda: _ellipsoid(3), lambda: _bumpy(3)],
                         ids=["sphere", "ellipsoid", "bumpy"])
def test_star_shaped_reflectors_are_accepted(make):
    reflector = make()
    shape = check_star_shaped(reflector)
    assert shape.star_shaped and shape.reason == ""
    assert shape.crossings == 0 and shape.hidden_share == 0.0 and shape.min_cosine > 0.3
    assert np.linalg.norm(shape.centre - O) < 0.1  # the candidates are centroids


def _teapot():
    pot = shapes.teapot(32)
    return Reflector("Teapot", pot.vertices, pot.triangles, pot.normals)


def _two_balls():
    a, b = icosphere(O - (3, 0, 0), 1.0, 2), icosphere(O + (3, 0, 0), 1.0, 2)
    return Reflector("Twins", np.concatenate([a.vertices, b.vertices]),
                     np.concatenate([a.triangles, b.triangles + len(a.vertices)]),
                     np.concatenate([a.normals, b.normals]))


@pytest.mark.parametrize("make, name", [(lambda: torus(O, 1.0, 0.35, 48, 24, name="Doughnut"), "Doughnut"),
                                        (_teapot, "Teapot"), (_two_balls, "Twins")],
                         ids=["torus", "teapot", "two spheres"])
def test_other_reflectors_are_refused_by_name(make, name):
    reflector = make()
    shape = check_star_shaped(reflector)
    assert not shape.star_shaped
    assert shape.reason.startswith(f"{name!r} is not star-shaped")
    assert shape.crossings > 0 or shape.hidden_share > 0
    refused, bake = prepare_iterative(reflector, 16)
    assert bake is None and not refused.star_shaped and refused.reason == shape.reason


# --- The cube map --------------------------------------------------------------------

def test_map_of_a_sphere_gives_its_radius_normal_and_inside():
    shape, bake = prepare_iterative(_sphere(4), 32)
    rmap = bake.reflector_map
    assert bake.coverage == 1.0 and bake.crossings == 0 and rmap.convex
    d = np.random.default_rng(5).normal(size=(2000, 3))
    # Cube-face centres, edges and corners: where the face borders take over.
    d = np.concatenate([d, np.eye(3), -np.eye(3), [[1, 1, 0], [0, -1, 1], [-1, 0, -1], [1, 1, 1], [-1, 1, -1]]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    radius, normal, valid = rmap.surface(d)
    assert valid.all()
    # Radius 1 less the facets' sag (at most 1.2e-3 at 4 subdivisions); the map centre is O to 1e-3.
    np.testing.assert_allclose(radius, 1.0, atol=2e-3)
    assert np.einsum("ij,ij->i", normal, d).min() > 0.9995
    np.testing.assert_allclose(np.linalg.norm(normal, axis=1), 1.0, atol=1e-9)
    centre = rmap.centre
    assert rmap.inside(centre + 0.5 * d).all()
    assert not rmap.inside(centre + 1.5 * d).any()
    assert rmap.inside(centre + 0.98 * d).all() and not rmap.inside(centre + 1.02 * d).any()


def test_map_of_an_ellipsoid_follows_the_ellipsoid(bakes):
    reflector, rmap = bakes["Egg"]
    assert rmap.convex and np.linalg.norm(rmap.centre - O) < 1e-6  # its centroids are its centre
    d = np.random.default_rng(6).normal(size=(2000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    radius, normal, valid = rmap.surface(d)
    assert valid.all()
    exact = 1.0 / np.sqrt(((d / RADII) ** 2).sum(axis=1))
    assert np.abs(radius - exact).max() < 4e-3 and np.abs(radius - exact).mean() < 1e-3
    gradient = (d * exact[:, None]) / np.square(RADII)
    gradient /= np.linalg.norm(gradient, axis=1, keepdims=True)
    assert np.einsum("ij,ij->i", normal, gradient).min() > 0.999


# --- The search against the exact solver ---------------------------------------------

@pytest.mark.parametrize("name, eye, seed", [("Ball", (3.0, -2.2, 1.8), 11), ("Egg", (-1.6, 2.9, 2.1), 12)])
def test_search_finds_every_reflection_on_convex_mirrors(bakes, name, eye, seed):
    reflector, rmap = bakes[name]
    view = look_at_view(eye, O, width=320, height=240)
    errors, coverage, false, facing = _compare(reflector, rmap, view, _points_outside(300, seed))
    assert coverage >= 0.99
    assert np.percentile(errors, 99) <= 0.5
    # Answers the exact solver does not see graze the silhouette (within 3 degrees), where
    # the map's normals, smoothed over a texel, and the mesh's facets disagree.
    assert false <= 0.01 and (facing < 0.05).all()


def test_search_finds_most_reflections_on_a_bumpy_sphere(bakes):
    reflector, rmap = bakes["Knobbly"]
    assert not rmap.convex
    view = look_at_view((2.6, 2.8, -1.2), O, width=320, height=240)
    errors, coverage, false, _ = _compare(reflector, rmap, view, _points_outside(300, 13))
    assert coverage >= 0.95
    assert np.percentile(errors, 90) <= 0.5
    # At faces of 48 the map smooths the bumps over 2.5-degree texels: some answers sit
    # on a root the mesh does not have, or have a reflected ray a neighbouring facet
    # blocks within a texel of P (measured: 4.4 %; 0.9-1.1 % at faces of 128, bench_iterative).
    assert false <= 0.06


@pytest.mark.parametrize("name", ["Ball", "Egg"])
def test_search_in_an_orthographic_view(bakes, name):
    reflector, rmap = bakes[name]
    view = _orthographic(O + (2.5, -3.0, 1.0), O, 1.6, 320, 240)
    errors, coverage, false, facing = _compare(reflector, rmap, view, _points_outside(300, 14))
    assert coverage >= 0.99
    assert np.percentile(errors, 99) <= 0.5
    # Parallel eye rays put more points behind the mirror, whose reflections lie on its
    # silhouette: there, as above, the map and the facets may disagree on visibility.
    assert false <= 0.02 and (facing < 0.05).all()


# --- What it cannot answer -----------------------------------------------------------

def test_points_it_cannot_answer_for(bakes):
    reflector, rmap = bakes["Ball"]
    centre = rmap.centre
    eye = centre + (0.0, -3.0, 0.4)
    toward_eye = (eye - centre) / np.linalg.norm(eye - centre)
    points = np.array([
        centre,  # 0: exactly at O
        centre + (0.5, 0.0, 0.0),  # 1, 2: inside
        centre + (0.0, 0.3, -0.6),
        [np.nan, 0.0, 0.0],  # 3, 4, 5: not a point
        [np.inf, 1.0, 1.0],
        [np.nan, np.nan, np.nan],
        centre + 2.0 * toward_eye,  # 6: between the eye and O, on their line: seen head-on
        centre - 2.0 * toward_eye,  # 7: straight behind the mirror
        centre + (2.0, 0.5, 0.3),  # 8: an ordinary point
    ])
    for view in (look_at_view(eye, centre, width=160, height=120),
                 _orthographic(eye, centre, 1.5, 160, 120)):
        with np.errstate(all="raise"):  # no NaN or division by zero on the way
            result = search_reflections(rmap, view, points)
        assert result.status.shape == (len(points),) and result.reflector_points.shape == (len(points), 3)
        assert list(result.status[:6]) == [INSIDE] * 3 + [NO_SURFACE] * 3
        assert np.isnan(result.reflector_points[result.status != FOUND]).all()
        assert np.isfinite(result.reflector_points[result.found]).all()
        assert result.status[6] == FOUND  # the mirror point facing the eye, within 1 px
        error = np.linalg.norm(result.reflector_points[6] - (centre + toward_eye))
        assert error < 2e-3 + view.pixel_size_at(result.reflector_points[6:7])[0]
        assert result.status[7] != FOUND and result.status[8] == FOUND
        projection = IterativeReflector(0, reflector.name, rmap).project(view, points)
        assert (projection.valid[0] == (result.found & view.in_view(np.nan_to_num(result.reflector_points)))).all()
        assert np.isnan(projection.pixels[0, ~projection.valid[0]]).all()
        assert np.isfinite(projection.pixels[0, projection.valid[0]]).all()
        assert (projection.leaf_kind[0] == np.where(projection.valid[0], SEARCH_ANSWER, NOT_PROJECTED)).all()


@pytest.mark.parametrize("name", ["Ball", "Knobbly"])
def test_an_eye_inside_the_mirror_sees_no_reflection(bakes, name):
    reflector, rmap = bakes[name]
    points = np.concatenate([_points_outside(50, 15), [[np.nan, 1.0, 0.0]]])
    for eye in (rmap.centre, rmap.centre + (0.2, -0.3, 0.1)):
        view = look_at_view(eye, eye + (0.0, 3.0, 0.0), width=64, height=48)
        result = search_reflections(rmap, view, points)
        assert (result.status[:-1] == INSIDE).all() and result.status[-1] == NO_SURFACE
        assert np.isnan(result.reflector_points).all()
        assert not IterativeReflector(0, name, rmap).project(view, points).valid.any()


def test_no_points_and_points_on_the_surface(bakes):
    reflector, rmap = bakes["Knobbly"]
    view = look_at_view(O + (3.0, 1.0, 0.5), O, width=64, height=48)
    empty = search_reflections(rmap, view, np.zeros((0, 3)))
    assert empty.status.shape == (0,) and empty.reflector_points.shape == (0, 3)
    on_surface = search_reflections(rmap, view, reflector.vertices[::37])  # no exception, no NaN answer
    assert np.isfinite(on_surface.reflector_points[on_surface.found]).all()


@pytest.mark.xfail(strict=True, reason=(
    "search.py: the search stops when a step moves P by < 0.1 px, but then demands a residual "
    "sine < 1e-3; for a point V within ~1 % of the radius above the mirror the direction P->V turns "
    "~1/|V - P| radians per unit of P, so the stopped answer (right to 0.03 px) fails the sine test "
    "(NOT_CONVERGED, no restart on a convex mirror); the 1e-3 finite-difference step is also as "
    "long as |V - P| there"))
def test_points_just_above_the_mirror_are_answered(bakes):
    reflector, rmap = bakes["Ball"]
    view = look_at_view(O + (3.0, -2.2, 1.8), O, width=320, height=240)
    d = np.random.default_rng(16).normal(size=(2000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = d[d @ normalize((view.eye - O)[None])[0] > 0.3][:200]
    heights = np.linspace(0.003, 0.01, len(d))  # above the sphere; the facets sag 1.2e-3 below it
    errors, coverage, false, _ = _compare(reflector, rmap, view, O + d * (1.0 + heights)[:, None])
    assert coverage >= 0.95 and np.percentile(errors, 99) <= 0.5
