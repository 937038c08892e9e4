# SPDX-License-Identifier: GPL-3.0-or-later
"""How finely mixed triangles are subdivided (SBC paper V-B): sub-triangles of about
MIXED_SUB_PX, the triangle's size on screen estimated from the magnification of the
fully projected triangles around it, or of its sheet (the 90th percentile: a fold's
extreme magnification is a small part of a sheet) where it has none."""

from types import SimpleNamespace

import numpy as np

from curved_reflections.drawing.methods.sbc_triangles import MIXED_SUBDIVISIONS, CameraTriangleMaker


def _right_triangle(x):
    return [[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.0]]


def _sheet(fold_ratio: float):
    """Thirty fully projected unit triangles, 29 seen at 2 px per unit and one, next to a
    fold, at ``fold_ratio``; and, apart from them all, a mixed triangle with one corner
    projected. Returns the projections object and the sheet's points (1, V, 4)."""
    vertices = np.array([corner for x in range(31) for corner in _right_triangle(3.0 * x)])
    triangles = np.arange(len(vertices)).reshape(-1, 3)
    points = np.zeros((1, len(vertices), 4))
    ratio = np.where(np.arange(len(vertices)) // 3 == 4, fold_ratio, 2.0)
    points[0, :, :2] = vertices[:, :2] * ratio[:, None]
    points[0, :, 3] = 1.0
    points[0, -2:, 3] = 0.0  # the mixed triangle: only its first corner projects
    geometry = SimpleNamespace(vertices=vertices, triangles=triangles, ranges=[(0, 0, len(triangles))], range_windings=(0,))
    return CameraTriangleMaker(geometry, per_frame_reflectors=(), counts={}), points


def test_a_mixed_triangle_with_no_projected_neighbour_is_sized_by_its_sheets_typical_magnification():
    projections, points = _sheet(fold_ratio=1000.0)
    (image, n, corners, group, order), = projections._mixed_instances(points, [0], order=1)
    np.testing.assert_array_equal(corners, [[90, 91, 92]])
    # 2 px per unit times its longest edge (sqrt 2): 2.8 px, four sub-triangles of about a
    # pixel along an edge; the fold's 1000 px per unit would have asked for the cap.
    assert n == 4 < MIXED_SUBDIVISIONS



def test_only_convex_mirrors_cull_the_far_sides_of_closed_solids():
    """A convex mirror's first-order sheets leave out the triangles a solid turns away
    from it; a non-convex mirror (a sheet can hold a solid's far side without its near
    side) keeps them."""
    from curved_reflections.engine.geometry.closed_surfaces import ConvexMirrors
    from curved_reflections.engine.geometry.sphere import icosphere

    ball = icosphere((0.0, 0.0, 0.0), 1.0, 2, name="Ball")
    sphere = icosphere((3.0, 0.0, 0.0), 1.0, 2, name="Dented")
    vertices = sphere.vertices.copy()
    vertices[0] = vertices[0] * 0.5 + np.array([1.5, 0.0, 0.0])  # pushed in toward its centre
    dented = SimpleNamespace(vertices=vertices, triangles=sphere.triangles)
    projections, _ = _sheet(fold_ratio=2.0)
    convex = ConvexMirrors([ball, dented])
    assert CameraTriangleMaker(projections.geometry, (), {}, convex_mirrors=convex).convex_reflectors == {0}
