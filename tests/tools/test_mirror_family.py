# SPDX-License-Identifier: GPL-3.0-or-later
"""The held-out family's mirrors (``tools/mirror_family.py``): closed meshes (or the one
seam intended), the stated bump and dent depths, the contact gaps."""

import numpy as np
import pytest

from curved_reflections.engine.geometry import shapes
from curved_reflections.tools import mirror_family as family


def _edge_counts(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(undirected edges, how many faces use each) and whether the directed edges are unique."""
    directed = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    edges, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    return edges, counts, len(np.unique(directed, axis=0)) == len(directed)


@pytest.mark.parametrize("shape", [family.bumpy_ball(0.12), family.dented_sphere(), family.hammered_sphere(),
                                   family.torus(), family.sphere(0.6)], ids=["bumpy", "dented", "hammered",
                                                                              "torus", "sphere"])
def test_the_mirrors_are_closed_and_wound_outward(shape):
    _, counts, consistent = _edge_counts(shape.triangles)
    assert (counts == 2).all() and consistent
    v, t = shape.vertices, shape.triangles
    face = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    assert (np.einsum("ij,ij->i", face, shape.normals[t].sum(axis=1)) > 0).all()
    assert np.allclose(np.linalg.norm(shape.normals, axis=1), 1.0)


def test_every_member_has_a_mirror_and_a_half():
    for name in family.TUNING + family.HELD_OUT:
        parts = family.member(name)
        assert any(p.mirror for p in parts) and family.half_of(name) in ("tuning", "held-out")
    assert len(family.TUNING) == len(family.HELD_OUT) == 6 and not set(family.TUNING) & set(family.HELD_OUT)


@pytest.mark.parametrize("amplitude, lobes", [(0.12, (5, 4)), (0.18, (3, 6)), (0.10, (4, 3))])
def test_bumps_reach_the_stated_share_of_the_radius(amplitude, lobes):
    radius = np.linalg.norm(family.bumpy_ball(amplitude, lobes).vertices, axis=1)
    assert amplitude * 0.97 <= radius.max() - 1.0 <= amplitude + 1e-12
    assert amplitude * 0.97 <= 1.0 - radius.min() <= amplitude + 1e-12


def _depth_at(shape, centre, width) -> float:
    """The deepest radial depression of the vertices within ``width`` of ``centre``."""
    d = shape.vertices / np.linalg.norm(shape.vertices, axis=1, keepdims=True)
    near = d @ centre > np.cos(width)
    return float(1.0 - np.linalg.norm(shape.vertices[near], axis=1).min())


def test_the_dents_are_15_percent_deep():
    shape = family.dented_sphere()
    for centre in family.unit_directions(family.DENTS):
        assert 0.149 <= _depth_at(shape, centre, family.DENT_WIDTH) <= 0.1502
    radius = np.linalg.norm(shape.vertices, axis=1)
    assert radius.max() <= 1.0 + 1e-12 and radius.min() >= 0.85 - 1e-3


def test_the_hammered_sphere_has_over_30_dents_4_to_6_percent_deep():
    centres, depths = family.hammer_dents()
    assert len(centres) >= 30 and ((depths >= 0.04) & (depths <= 0.06)).all()
    angles = np.arccos(np.clip(centres @ centres.T, -1, 1))[np.triu_indices(len(centres), 1)]
    assert angles.min() >= family.HAMMER_SEPARATION
    shape = family.hammered_sphere()
    for centre, depth in zip(centres, depths):
        assert 0.93 * depth <= _depth_at(shape, centre, family.HAMMER_WIDTH) <= depth + 1e-4


def test_the_car_shell_is_closed_but_for_its_crease_whose_normals_are_split():
    shape = family.car_shell()
    edges, counts, consistent = _edge_counts(shape.triangles)
    above, below = family.crease_rings()
    boundary = np.unique(edges[counts == 1])
    assert consistent and set(counts) <= {1, 2}
    assert set(boundary) == set(above) | set(below)
    assert np.allclose(shape.vertices[above], shape.vertices[below])  # the seam's sides coincide
    turn = np.degrees(np.arccos(np.einsum("ij,ij->i", shape.normals[above], shape.normals[below])))
    assert turn.min() > 15.0  # a crease, not a smooth seam
    extent = np.ptp(shape.vertices, axis=0)
    assert np.allclose(extent / extent[0], (1.0, 0.5, 0.3), atol=0.05)  # squashed (2, 1, 0.6)
    assert (np.einsum("ij,ij->i", shape.normals, shape.vertices) > 0).all()


def test_the_teapot_is_the_demos():
    pot, demo = family.teapot(), shapes.teapot()
    assert np.allclose(pot.vertices - pot.vertices.mean(axis=0), demo.vertices - demo.vertices.mean(axis=0))
    assert np.array_equal(pot.triangles, demo.triangles)


def _box_surface(cube: shapes.Shape, count: int = 41) -> np.ndarray:
    """Points on the box's faces (its quads, bilinear)."""
    s = np.linspace(0.0, 1.0, count)
    u, v = (a.ravel()[:, None] for a in np.meshgrid(s, s))
    points = []
    for quad in cube.quads:
        a, b, c, d = cube.vertices[quad]
        points.append((1 - u) * (1 - v) * a + u * (1 - v) * b + u * v * c + (1 - u) * v * d)
    return np.concatenate(points)


def test_the_cube_is_2_percent_of_the_radius_from_the_ball():
    ball, cube = (p.shape for p in family.member("ball_cube_contact"))
    gap = np.linalg.norm(_box_surface(cube), axis=1).min() - 1.0
    assert gap == pytest.approx(0.02, abs=1e-9)
    assert np.linalg.norm(ball.vertices, axis=1).max() <= 1.0 + 1e-12


def test_the_cylinder_is_4_percent_of_the_radius_from_the_bumpy_ball():
    ball, cylinder = (p.shape for p in family.member("bumpy_cylinder_contact"))
    axis = cylinder.vertices[:, :2].mean(axis=0)
    radius = np.linalg.norm(cylinder.vertices[:, :2] - axis, axis=1).max()
    # Points on the ball's triangles, not its vertices alone.
    w = np.random.default_rng(0).dirichlet((1, 1, 1), size=(8,))
    corners = ball.vertices[ball.triangles]
    points = np.einsum("kj,tjd->tkd", w, corners).reshape(-1, 3)
    points = np.concatenate([points, ball.vertices])
    gap = np.linalg.norm(points[:, :2] - axis, axis=1).min() - radius
    assert gap == pytest.approx(0.04, abs=2e-3)
    assert cylinder.vertices[:, 2].min() == pytest.approx(-family.FLOOR_BELOW)
    assert cylinder.vertices[:, 2].max() > ball.vertices[:, 2].max()


def test_the_balloon_capsules_fuse_into_one_body():
    capsules = family.balloon_capsules()
    assert 4 <= len(capsules) <= 5
    assert np.allclose([np.linalg.norm(c.direction) for c in capsules], 1.0)
    joined, queue = {0}, [0]
    while queue:
        i = queue.pop()
        for j, other in enumerate(capsules):
            reach = 0.6 * (capsules[i].radius + other.radius)  # the surfaces overlap, not just the fields
            if j not in joined and family.segment_distance(capsules[i].ends(), other.ends()) < reach:
                joined.add(j)
                queue.append(j)
    assert joined == set(range(len(capsules)))


@pytest.mark.parametrize("name", ["two_balls", "bumpy_and_ellipsoid"])
def test_the_two_mirrors_face_each_other_apart(name):
    left, right = (p.shape for p in family.member(name))
    assert left.vertices[:, 0].max() < right.vertices[:, 0].min()  # a gap between them along X
    assert right.vertices[:, 0].min() - left.vertices[:, 0].max() > 0.2
