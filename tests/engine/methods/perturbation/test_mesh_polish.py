# SPDX-License-Identifier: GPL-3.0-or-later
"""Newton's method on the mesh for the candidates the perturbation series cannot reach
(``engine/methods/perturbation/mesh_polish.py``), against the exact reference solver on
a bumpy mirror none of its constants were chosen on."""

import numpy as np

from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.engine.geometry.sphere import bumpy_icosphere
from curved_reflections.engine.methods.perturbation.mesh_polish import walk_to_roots
from curved_reflections.engine.reference.exact import solve_reflections
from curved_reflections.engine.view import look_at_view

CENTRE = np.array([0.3, -0.2, 0.1])


def _scene():
    mirror = ReflectorSet([bumpy_icosphere(CENTRE, 1.0, 4, 0.04, lobes=(4, 5))])
    view = look_at_view((2.9, 2.1, -1.4), CENTRE, fov_y_deg=40.0, width=400, height=300)
    rng = np.random.default_rng(8)
    direction = rng.normal(size=(300, 3))
    points = CENTRE + direction / np.linalg.norm(direction, axis=1)[:, None] * rng.uniform(1.6, 3.0, (300, 1))
    return mirror, view, points


def _two_triangles_away(mirror, triangles):
    """A triangle two edges from each of ``triangles``: across the edge opposite its first
    corner, then across an edge of that one that does not lead back."""
    across = mirror.edge_neighbours[triangles, 0]
    beyond = mirror.edge_neighbours[across]
    return beyond[np.arange(len(triangles)), np.argmax(beyond != triangles[:, None], axis=1)]


def test_a_start_two_triangles_away_walks_to_an_exact_reflection():
    """From two triangles away 94 % of the visible reflections are found (a start in the
    root's own triangle finds all, one away 98 %), each on one of the exact solver's
    roots of its point (a few on a neighbouring image of the same point). Roots seen
    from behind the mirror are refused: 32 % of all roots are found from their own
    triangle."""
    mirror, view, points = _scene()
    exact = solve_reflections(mirror, view, points)
    seen = exact.select(exact.visible)
    starts = _two_triangles_away(mirror, seen.triangle)
    assert (starts != seen.triangle).all()
    roots = walk_to_roots(mirror, view, points, seen.point, starts, np.full((len(starts), 2), 1.0 / 3.0))
    found = np.flatnonzero(np.isfinite(roots[:, 0]))
    assert len(found) >= 0.9 * len(starts), (len(found), len(starts))
    same_point = seen.point[found][:, None] == exact.point[None]
    apart = np.where(same_point, np.linalg.norm(roots[found][:, None] - exact.position[None], axis=2), np.inf)
    assert apart.min(axis=1).max() <= 1e-9 * mirror.scale
    own = walk_to_roots(mirror, view, points, exact.point, exact.triangle, np.full((len(exact.point), 2), 1.0 / 3.0))
    assert np.isfinite(own[exact.visible, 0]).all() and 0.2 < np.isfinite(own[:, 0]).mean() < 0.5


def test_a_start_far_from_any_reflection_finds_none_and_repeated_starts_agree():
    mirror, view, points = _scene()
    exact = solve_reflections(mirror, view, points)
    seen = exact.select(exact.visible)
    one = seen.point[:40]
    # The mirror's far side from each point: no path from the eye reflects there.
    away = (points[one] - CENTRE) / np.linalg.norm(points[one] - CENTRE, axis=1)[:, None]
    behind = mirror.intersect(np.tile(CENTRE, (40, 1)), -away)
    assert behind.hit.all()
    roots = walk_to_roots(mirror, view, points, one, behind.triangle, np.full((40, 2), 1.0 / 3.0))
    assert np.isnan(roots).all()
    twice = walk_to_roots(mirror, view, points, np.r_[seen.point[:20], seen.point[:20]],
                          np.r_[seen.triangle[:20], seen.triangle[:20]], np.full((40, 2), 0.2))
    np.testing.assert_array_equal(twice[:20], twice[20:])
    np.testing.assert_allclose(twice[:20], seen.position[:20], atol=1e-9 * mirror.scale)
