# SPDX-License-Identifier: GPL-3.0-or-later
"""The iterative search's numpy side (engine/methods/iterative): the star-shaped check,
the cube map, and the search measured against the exact reference solver."""

import numpy as np
import pytest

from curved_reflections.engine.reference.exact import solve_reflections
from curved_reflections.engine.methods.iterative import (IterativeReflector, check_star_shaped, prepare_iterative,
                                                         search_reflections)
from curved_reflections.engine.methods.iterative import search as search_module
from curved_reflections.engine.geometry.closed_surfaces import is_convex
from curved_reflections.engine.methods.iterative.reflector_map import face_coordinates, texel_directions
from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.engine.scene import Reflector
from curved_reflections.engine.geometry.sphere import bumpy_icosphere, icosphere
from curved_reflections.tools.surfaces import ellipsoid
from curved_reflections.engine.view import View, look_at_view

CENTRE = np.array([0.3, -0.2, 0.1])


def _bumpy(amplitude=0.05, subdivisions=4):
    return bumpy_icosphere(CENTRE, 1.0, subdivisions, amplitude)


def _ellipsoid(subdivisions=4):
    return ellipsoid((0.0, 0.0, 0.0), (1.2, 0.7, 0.5), subdivisions, name="Egg")


def _torus(major=1.0, minor=0.35, segments=48, rings=24):
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, segments, endpoint=False),
                       np.linspace(0, 2 * np.pi, rings, endpoint=False), indexing="ij")
    normals = np.stack([np.cos(u) * np.cos(v), np.sin(u) * np.cos(v), np.sin(v)], axis=-1).reshape(-1, 3)
    centres = np.stack([np.cos(u), np.sin(u), 0 * u], axis=-1).reshape(-1, 3) * major
    index = np.arange(segments * rings).reshape(segments, rings)
    a, b = index, np.roll(index, -1, axis=0)
    c, d = np.roll(index, -1, axis=1), np.roll(np.roll(index, -1, axis=0), -1, axis=1)
    triangles = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    return Reflector("Ring", centres + minor * normals, triangles, normals)


def _outside_points(reflector, count, seed, spread=3.0):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-spread, spread, (4 * count, 3)) + reflector.vertices.mean(axis=0)
    radius = np.linalg.norm(reflector.vertices - reflector.vertices.mean(axis=0), axis=1).max()
    return points[np.linalg.norm(points - reflector.vertices.mean(axis=0), axis=1) > 1.15 * radius][:count]


def test_star_shaped_detection():
    for reflector in (icosphere(CENTRE, 1.0, 3), _ellipsoid(3), _bumpy(0.05, 3)):
        shape = check_star_shaped(reflector)
        assert shape.star_shaped and shape.reason == "", reflector.name
        assert shape.crossings == 0 and shape.hidden_share == 0 and shape.min_cosine > 0.5
    ring = check_star_shaped(_torus())
    assert not ring.star_shaped
    assert ring.reason.startswith("'Ring' is not star-shaped")


def test_cube_map_layout_and_lookups():
    directions = texel_directions(8).reshape(6, 10, 10, 3)
    face, u, v = face_coordinates(directions[:, 1:-1, 1:-1].reshape(-1, 3))
    assert (face == np.repeat(np.arange(6), 64)).all()  # inner texels belong to their face
    assert np.abs(u).max() < 1 and np.abs(v).max() < 1
    sphere = icosphere(CENTRE, 1.0, 4)
    shape, bake = prepare_iterative(sphere, 32)
    rmap = bake.reflector_map
    assert bake.crossings == 0 and bake.coverage == 1.0 and rmap.convex
    d = np.random.default_rng(0).normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    radius, normal, valid = rmap.surface(d)
    assert valid.all()
    np.testing.assert_allclose(radius, 1.0, atol=2e-3)  # the facets lie within 1.5e-3 of the sphere
    assert np.einsum("ij,ij->i", normal, d).min() > 0.9995
    assert rmap.inside(CENTRE + 0.5 * d).all() and not rmap.inside(CENTRE + 1.5 * d).any()


def test_convexity_from_edges_and_vertex_angles():
    sphere = icosphere(CENTRE, 1.0, 3)
    assert is_convex(sphere.vertices, sphere.triangles, CENTRE)
    assert is_convex(_ellipsoid(3).vertices, _ellipsoid(3).triangles, (0, 0, 0))
    bumpy = _bumpy(0.05, 3)
    assert not is_convex(bumpy.vertices, bumpy.triangles, CENTRE)
    upper = sphere.triangles[sphere.vertices[sphere.triangles].mean(axis=1)[:, 2] > CENTRE[2]]
    assert not is_convex(sphere.vertices, upper, CENTRE - (0, 0, 0.5))  # open: counted as not convex


def _pixel_errors(reflector, rmap, view, points):
    """(errors of our answers against the nearest exact visible reflection, coverage of
    the exact visible reflections, our answers without one)."""
    found = IterativeReflector(0, reflector.name, rmap).project(view, points)
    exact = solve_reflections(ReflectorSet([reflector]), view, points)
    visible = exact.visible
    ours = np.flatnonzero(found.valid[0])
    errors, covered = [], np.zeros(len(points), dtype=bool)
    for point in ours:
        candidates = exact.pixel[visible & (exact.point == point)]
        if len(candidates):
            errors.append(np.linalg.norm(candidates - found.pixels[0, point], axis=1).min())
            covered[point] = errors[-1] <= 1.0
    wanted = np.unique(exact.point[visible])
    return np.array(errors), covered[wanted].mean(), len(ours) - len(errors)


@pytest.mark.parametrize("make, eye", [
    (lambda: icosphere(CENTRE, 1.0, 4), (3.5, -2.0, 1.5)),
    (lambda: _ellipsoid(4), (-1.0, 3.2, 2.0)),
])
def test_search_agrees_with_the_exact_solver(make, eye):
    reflector = make()
    shape, bake = prepare_iterative(reflector, 48)
    view = look_at_view(eye, reflector.vertices.mean(axis=0), width=320, height=240)
    errors, coverage, unmatched = _pixel_errors(reflector, bake.reflector_map, view,
                                                _outside_points(reflector, 300, 1))
    assert coverage >= 0.99
    assert np.percentile(errors, 99) <= 0.5
    assert unmatched <= 2


def test_search_on_a_bumpy_sphere_finds_its_reflections():
    reflector = _bumpy(0.05, 4)
    shape, bake = prepare_iterative(reflector, 48)
    assert not bake.reflector_map.convex
    view = look_at_view((3.5, -2.0, 1.5), CENTRE, width=320, height=240)
    errors, coverage, unmatched = _pixel_errors(reflector, bake.reflector_map, view,
                                                _outside_points(reflector, 300, 2))
    assert coverage >= 0.95
    assert np.percentile(errors, 95) <= 0.5


def test_flipped_images_alternate_across_a_fold():
    """Where a bump folds the reflection, a point has three images: two direct, one
    flipped, beyond the caustic (``search.flipped_images``), as Morse theory has it
    (direct minus flipped is one). Every image of the exact solver, resumed from, is
    found again with that parity; a single image is never flipped, nor any on a sphere."""
    reflector = _bumpy(0.05, 4)
    shape, bake = prepare_iterative(reflector, 48)
    view = look_at_view((3.5, -2.0, 1.5), CENTRE, width=320, height=240)
    points = _outside_points(reflector, 600, 2)
    exact = solve_reflections(ReflectorSet([reflector]), view, points)
    exact = exact.select(exact.visible)
    found = search_reflections(bake.reflector_map, view, points[exact.point], 1.0, previous=exact.position)
    same = found.found & (np.linalg.norm(found.reflector_points - exact.position, axis=1) < 0.02)
    assert same.mean() >= 0.97
    parities = {}
    for point in np.unique(exact.point):
        rows = np.flatnonzero(exact.point == point)
        if same[rows].all():
            parities.setdefault(len(rows), []).append(int(found.flipped[rows].sum()))
    assert len(parities[3]) >= 10 and set(parities[3]) == {1}
    assert set(parities[1]) == {0}
    sphere = icosphere(CENTRE, 1.0, 4)
    sphere_points = _outside_points(sphere, 300, 3)
    plain = search_reflections(prepare_iterative(sphere, 48)[1].reflector_map, view, sphere_points, 1.0)
    assert plain.found.sum() > 100 and not plain.flipped.any()


def test_degenerate_points_and_views():
    sphere = icosphere(CENTRE, 1.0, 3)
    shape, bake = prepare_iterative(sphere, 24)
    rmap = bake.reflector_map
    points = np.array([CENTRE, CENTRE + (0.5, 0, 0), [np.nan, 0, 0], [np.inf, 1, 1], CENTRE + (0, -3, 0)])
    view = look_at_view(CENTRE + (0, 3, 0.2), CENTRE, width=64, height=48)
    result = search_reflections(rmap, view, points)
    assert list(result.status[:4]) == [search_module.INSIDE, search_module.INSIDE, search_module.NO_SURFACE,
                                       search_module.NO_SURFACE]
    assert np.isfinite(result.reflector_points[result.found]).all()
    inside = look_at_view(CENTRE + (0.1, 0.1, 0), CENTRE + (0, 3, 0), width=64, height=48)
    assert (search_reflections(rmap, inside, points[4:]).status == search_module.INSIDE).all()
    # Orthographic: the direction toward the viewer stands for the eye.
    projection = np.diag([0.4, 0.4 * 64 / 48, -0.02, 1.0])
    projection[2, 3] = -1.0
    orthographic = View(look_at_view(CENTRE + (0, 3, 0.2), CENTRE).view_matrix, projection, 64, 48)
    result = search_reflections(rmap, orthographic, _outside_points(sphere, 200, 3))
    assert result.found.mean() > 0.5 and np.isfinite(result.reflector_points[result.found]).all()


def test_a_mirror_seen_nearly_edge_on_from_every_centre_is_left_to_the_camera():
    """Deep bumps (amplitude 0.3) are still met once by every ray from the centre, but
    their flanks are seen nearly edge-on (the map's radius too steep for its texels and
    for the search, as on fused metaballs): not star-shaped enough, with the cosine in
    the reason; shallower ones stay searched."""
    deep = check_star_shaped(_bumpy(0.3, 4))
    assert not deep.star_shaped and deep.crossings == 0 and deep.hidden_share == 0
    assert "nearly edge-on" in deep.reason and f"{deep.min_cosine:.2f}" in deep.reason
    assert check_star_shaped(_bumpy(0.15, 4)).star_shaped


def test_an_open_mirror_is_not_star_shaped():
    """The Chen-Arvo vase, open at both ends: seen whole from its axis, but its inner side
    shows through the openings and has no place in a map of one radius per direction."""
    from curved_reflections.engine.geometry import shapes

    vase = shapes.vase(48, 32)
    shape = check_star_shaped(Reflector("Vase", vase.vertices, vase.triangles, vase.normals))
    assert not shape.star_shaped and shape.reason.startswith("'Vase' is")
    # Seen from its axis, where nothing of it is hidden, it is open.
    from curved_reflections.engine.methods.iterative.reflector_map import bake_reflector_map
    from curved_reflections.engine.methods.iterative.star import verdict

    vase = Reflector("Vase", vase.vertices, vase.triangles, vase.normals)
    bake = bake_reflector_map(ReflectorSet([vase]), (0.0, 0.0, 1.6), 16)
    assert bake.crossings == 0 and bake.coverage < 1
    assert verdict("Vase", (0.0, 0.0, 1.6), bake, 0.0).reason.startswith("'Vase' is open:")
