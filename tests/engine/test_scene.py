# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np
import pytest

from curved_reflections.engine import DiffuseMesh, Reflector, SceneInputError, scene_bounds

TRIANGLE = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
UP = np.tile([0.0, 0.0, 2.0], (3, 1))


def test_reflector_normalises_normals_and_freezes_arrays():
    mirror = Reflector("Mirror", TRIANGLE, [[0, 1, 2]], UP)
    np.testing.assert_allclose(mirror.normals, np.tile([0, 0, 1.0], (3, 1)))
    with pytest.raises(ValueError):
        mirror.vertices[0, 0] = 5.0


@pytest.mark.parametrize("vertices, triangles, normals, problem", [
    (TRIANGLE, np.zeros((0, 3), int), UP, "has no faces"),
    (TRIANGLE, [[0, 1, 2]], np.zeros((3, 3)), "3 vertex normals have zero length"),
    (np.array([[0.0, 0, 0], [np.nan, 0, 0], [0, 1, 0]]), [[0, 1, 2]], UP, "NaN or infinite"),
    (TRIANGLE, [[0, 1, 3]], UP, "indices must lie in"),
    (TRIANGLE, [[0, 1, 2]], UP[:2], "one normal per vertex"),
    (np.zeros((3, 3)), [[0, 1, 2]], UP, "zero area"),
])
def test_bad_reflectors_name_the_object_and_the_problem(vertices, triangles, normals, problem):
    with pytest.raises(SceneInputError, match=problem) as error:
        Reflector("Kettle", vertices, triangles, normals)
    assert error.value.object_name == "Kettle"
    assert str(error.value).startswith("'Kettle'")


def test_unused_vertices_may_have_any_normal():
    vertices = np.vstack([TRIANGLE, [[5.0, 5, 5]]])
    normals = np.vstack([UP, [[0.0, 0, 0]]])
    assert len(Reflector("Mirror", vertices, [[0, 1, 2]], normals).vertices) == 4


def test_diffuse_mesh_pads_rgb_to_rgba_and_checks_shape():
    mesh = DiffuseMesh("Cube", TRIANGLE, [[0, 1, 2]], np.full((3, 3), 0.5))
    assert mesh.colors.shape == (3, 4) and np.all(mesh.colors[:, 3] == 1)
    with pytest.raises(SceneInputError, match="colors must be"):
        DiffuseMesh("Cube", TRIANGLE, [[0, 1, 2]], np.ones((2, 3)))


def test_scene_bounds_cover_everything_with_margin():
    mirror = Reflector("Mirror", TRIANGLE, [[0, 1, 2]], UP)
    cube = DiffuseMesh("Cube", TRIANGLE + 3, [[0, 1, 2]], np.ones((3, 3)))
    lo, hi = scene_bounds([mirror], [cube], margin=0.5)
    np.testing.assert_allclose(lo, [-0.5, -0.5, -0.5])
    np.testing.assert_allclose(hi, [4.5, 4.5, 3.5])
    with pytest.raises(SceneInputError, match="empty"):
        scene_bounds([])


def test_smooth_pieces_are_the_connected_components_of_any_mesh():
    """Random triangles over few vertices (many pieces of every size) and a long strip
    (one piece, 20k triangles end to end): the pieces a plain union-find gives."""
    from curved_reflections.engine.scene import smooth_pieces

    rng = np.random.default_rng(7)
    strip = np.array([[k, k + 1, k + 2] for k in range(20_000)])
    np.testing.assert_array_equal(smooth_pieces(strip, 20_002), np.zeros(20_000))
    triangles = rng.integers(0, 3000, (1200, 3))
    parent = list(range(3000))

    def root(v):
        while parent[v] != v:
            v = parent[v]
        return v

    for a, b, c in triangles:
        for u in (b, c):
            ra, ru = root(a), root(u)
            parent[max(ra, ru)] = min(ra, ru)
    expected = np.array([root(a) for a, _, _ in triangles])
    pieces = smooth_pieces(triangles, 3000)
    # The same partition, numbered in order of first triangle.
    _, first, inverse = np.unique(expected, return_index=True, return_inverse=True)
    renumber = np.empty(len(first), dtype=np.int64)
    renumber[np.argsort(first, kind="stable")] = np.arange(len(first))
    np.testing.assert_array_equal(pieces, renumber[inverse])
    assert 20 < pieces.max() < 1200


def test_smooth_pieces_follow_shared_vertices_not_positions():
    """Two quads meeting along an edge are one piece where they share its vertices and
    two where the edge is sharp (its vertices split, same positions)."""
    from curved_reflections.engine.geometry import shapes
    from curved_reflections.engine.scene import smooth_pieces

    shared = np.array([[0, 1, 2], [1, 3, 2], [2, 3, 4], [3, 5, 4]])
    np.testing.assert_array_equal(smooth_pieces(shared, 6), [0, 0, 0, 0])
    split = np.array([[0, 1, 2], [1, 3, 2], [6, 7, 4], [7, 5, 4]])  # 6, 7 copy 2, 3
    np.testing.assert_array_equal(smooth_pieces(split, 8), [0, 0, 1, 1])
    # The teapot: body, base, lid, knob, spout and handle meet at creases.
    teapot = shapes.teapot(32)
    pieces = smooth_pieces(teapot.triangles, len(teapot.vertices))
    assert pieces.max() + 1 == 6 and pieces[0] == 0
