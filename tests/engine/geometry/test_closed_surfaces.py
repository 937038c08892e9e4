# SPDX-License-Identifier: GPL-3.0-or-later
"""Closed solids among the diffuse meshes (``engine/geometry/closed_surfaces.py``): which
are watertight and consistently wound, which way, and whether a mirror lies inside."""

from types import SimpleNamespace

import numpy as np

from curved_reflections.engine.geometry import closed_surfaces
from curved_reflections.engine.geometry.sphere import icosphere


def _cube(split: bool = True):
    """The unit cube, counter-clockwise seen from outside; ``split``: each face its own
    four vertices (as captured at sharp edges), else eight shared corners."""
    quads = [((0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0)), ((0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)),
             ((0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)), ((0, 1, 0), (0, 1, 1), (1, 1, 1), (1, 1, 0)),
             ((0, 0, 0), (0, 0, 1), (0, 1, 1), (0, 1, 0)), ((1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1))]
    vertices, triangles = [], []
    for quad in quads:
        base = len(vertices)
        vertices += quad
        triangles += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    vertices, triangles = np.array(vertices, np.float64), np.array(triangles)
    if not split:
        vertices, welded = np.unique(vertices, axis=0, return_inverse=True)
        triangles = welded.reshape(-1)[triangles]
    return vertices, triangles


def test_a_closed_mesh_wound_outward_is_plus_one_and_inward_minus_one():
    for split in (True, False):
        vertices, triangles = _cube(split)
        assert closed_surfaces.winding(vertices, triangles) == 1
        assert closed_surfaces.winding(vertices, triangles[:, ::-1]) == -1
        assert closed_surfaces.winding(-vertices, triangles) == -1  # a mirroring transform
    sphere = icosphere(np.zeros(3), 1.0, 2, "ball")
    assert closed_surfaces.winding(sphere.vertices, sphere.triangles) == 1


def test_a_mesh_that_is_not_a_closed_consistent_solid_is_zero():
    vertices, triangles = _cube()
    assert closed_surfaces.winding(vertices, triangles[:-2]) == 0  # a face missing
    flipped_face = triangles.copy()
    flipped_face[:2] = flipped_face[:2, ::-1]
    assert closed_surfaces.winding(vertices, flipped_face) == 0  # one face wound against the rest
    assert closed_surfaces.winding(vertices, np.r_[triangles, triangles[:1]]) == 0  # an edge of three faces
    flat = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float64)
    assert closed_surfaces.winding(flat, np.array([[0, 1, 2], [1, 3, 2], [0, 2, 1], [1, 2, 3]])) == 0  # no volume


def test_inside_a_closed_mesh():
    vertices, triangles = _cube()
    points = np.array([[0.5, 0.5, 0.5], [0.99, 0.01, 0.5], [1.5, 0.5, 0.5], [-0.01, 0.5, 0.5], [0.5, 0.5, 3.0]])
    np.testing.assert_array_equal(closed_surfaces.inside(vertices, triangles, points),
                                  [True, True, False, False, False])


def test_a_solid_a_mirror_lies_in_is_not_culled():
    """A mirror ball in a closed room shows the room's far walls: from inside, the
    triangles facing away are the ones that show."""
    vertices, triangles = _cube()
    room = (vertices - 0.5) * 10.0
    ball = icosphere(np.zeros(3), 1.0, 2, "ball").vertices
    assert closed_surfaces.cullable_winding(room, triangles, [ball]) == 0
    assert closed_surfaces.cullable_winding(room, triangles, [ball + (20.0, 0.0, 0.0)]) == 1
    assert closed_surfaces.cullable_winding(room, triangles[:, ::-1], [ball + (3.0, 20.0, 0.0)]) == -1


def test_triangles_turned_away_from_the_points_they_are_seen_from():
    """Seen from a point outside the cube (each corner from its own point, as each vertex
    of a reflection from its point on the mirror), whatever its winding, the faces turned
    away are found and the ones facing it kept; with corners not known (a mixed
    triangle's unprojected ones), the known corners decide; open meshes never."""
    vertices, triangles = _cube()
    seen_from = np.array([0.6, -2.0, 4.0])
    faces = vertices.reshape(6, 4, 3).mean(axis=1).repeat(2, axis=0)  # each triangle's face centre (split cube)
    facing = np.einsum("ij,ij->i", faces - 0.5, seen_from - faces) > 0  # outward normals: from (0.5, 0.5, 0.5)
    for winding in (1, -1):
        corners = triangles if winding > 0 else triangles[:, ::-1]
        eyes = seen_from - vertices[corners]
        known = np.ones(corners.shape, bool)
        away = closed_surfaces.turned_away(vertices, corners, np.full(len(corners), winding), eyes, known)
        np.testing.assert_array_equal(away, ~facing)
        known[:, 1:] = False
        np.testing.assert_array_equal(
            closed_surfaces.turned_away(vertices, corners, np.full(len(corners), winding), eyes, known), away)
        assert not closed_surfaces.turned_away(vertices, corners, np.full(len(corners), winding), eyes,
                                               np.zeros_like(known)).any()
    assert 0 < away.sum() < len(triangles)
    back = int(np.flatnonzero(away)[0])
    eyes = seen_from - vertices[triangles]
    eyes[back, 0] = (vertices[triangles[back, 0]] - 0.5) * 10.0  # one corner sees it from outside its face
    assert not closed_surfaces.turned_away(vertices, triangles, np.ones(len(triangles), int), eyes,
                                           np.ones(triangles.shape, bool))[back]
    assert not closed_surfaces.turned_away(vertices, triangles, np.zeros(len(triangles), int),
                                           seen_from - vertices[triangles], np.ones(triangles.shape, bool)).any()


def test_convex_mirrors_are_tested_once_for_every_pass_that_asks(monkeypatch):
    """A ball is convex and a dented one is not; the renderer's camera projections and
    its morphing pass share one ``ConvexMirrors``, which tests each mirror once."""
    ball = icosphere((0.0, 0.0, 0.0), 1.0, 2, name="Ball")
    dented = icosphere((3.0, 0.0, 0.0), 1.0, 2, name="Dented")
    vertices = dented.vertices.copy()
    vertices[0] = dented.vertices.mean(axis=0) + 0.5 * (vertices[0] - dented.vertices.mean(axis=0))
    dented = SimpleNamespace(vertices=vertices, triangles=dented.triangles)
    tested = []
    real = closed_surfaces.bounds_convex_body
    monkeypatch.setattr(closed_surfaces, "bounds_convex_body", lambda mesh: tested.append(mesh) or real(mesh))
    convex = closed_surfaces.ConvexMirrors([ball, dented])
    assert convex.indices == {0} and convex.indices == {0}
    assert len(tested) == 2
