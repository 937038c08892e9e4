# SPDX-License-Identifier: GPL-3.0-or-later
"""The per-frame passes' reflected meshes (``drawing/reflected_meshes.py``): placed by
answer textures, kept on the visible footprint of their mirror, and dropped where their
reflector point is hidden from the eye by the mirror itself or where the eye's ray does
not reflect toward them."""

import numpy as np

from curved_reflections.engine import DiffuseMesh, Reflector, look_at_view
from curved_reflections.drawing.frame_pass import Frame, FramePass

EYE = np.array([0.0, 0.0, 5.0])
#: The diffuse patches' height: above the eye, behind the camera (out of the pre-pass).
HEIGHT = 12.0


def _view():
    return look_at_view(EYE, (0.0, 0.0, 0.0), fov_y_deg=35.0, width=80, height=80)


def _two_level_mirror(tilt_degrees: float = 0.0) -> Reflector:
    """One reflector of two squares facing +z: the lower one, z = 0 over [-1, 1]^2, and
    above its left half, at z = 0.5, the upper one, hiding that half from above. The
    lower square's (shading) normals lean ``tilt_degrees`` toward +x."""
    vertices = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0],
                         [-1, -1, 0.5], [0, -1, 0.5], [0, 1, 0.5], [-1, 1, 0.5]], dtype=np.float64)
    triangles = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    normals = np.tile([0.0, 0.0, 1.0], (8, 1))
    tilt = np.radians(tilt_degrees)
    normals[:4] = [np.sin(tilt), 0.0, np.cos(tilt)]
    return Reflector("Terrace", vertices, triangles, normals)


def _patch(name: str, x0: float, x1: float, colour, n: int = 8) -> DiffuseMesh:
    """A flat patch split into n x n vertices over x in [x0, x1], y in [-1, 1], z = HEIGHT."""
    xs, ys = np.meshgrid(np.linspace(x0, x1, n), np.linspace(-1.0, 1.0, n))
    vertices = np.c_[xs.ravel(), ys.ravel(), np.full(n * n, HEIGHT)]
    quads = [(j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i) for j in range(n - 1) for i in range(n - 1)]
    triangles = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    return DiffuseMesh(name, vertices, triangles, np.tile([*colour, 1.0], (n * n, 1)), emissive=True)


def _reflected_on_the_lower_square(vertices: np.ndarray) -> np.ndarray:
    """Where the eye sees each vertex reflected in the plane z = 0: toward its mirror image."""
    image = vertices * [1.0, 1.0, -1.0]
    t = EYE[2] / (EYE[2] - image[:, 2])
    return EYE + t[:, None] * (image - EYE)


def _drawn(hidden_fraction: float, reflection_cosine: float, tilt_degrees: float = 0.0, snap_px: float = 0.0,
           split: int = 8, mirrored: frozenset = frozenset()) -> np.ndarray:
    """The reflection target after drawing both patches (``split`` vertices a side) at
    their answers on the plane z = 0, the mirror's normals tilted by ``tilt_degrees``
    (the law of reflection then fails by twice that: as for an answer from another sheet
    of a curved mirror), the vertices snapped to a grid ``snap_px`` apart (0: not), the
    mirror declared to have one sheet when ``mirrored`` holds it (0)."""
    import gpu
    from mathutils import Matrix

    from curved_reflections.drawing import reflected_meshes
    from curved_reflections.drawing.gpu_data import data_texture, read_texture, saved_state
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    # Reflected at x in [-0.88, -0.29] (behind the upper square) and [0.59, 0.88] (seen).
    meshes = [_patch("Hidden", -3.0, -1.0, (1.0, 0.0, 0.0), split), _patch("Seen", 2.0, 3.0, (0.0, 1.0, 0.0), split)]
    view = _view()
    renderer = ReflectionRenderer([_two_level_mirror(tilt_degrees)], meshes, edge_fraction=None)
    g = renderer.geometry
    texels = np.zeros((len(g.vertices), 4), np.float32)
    texels[:, :3] = _reflected_on_the_lower_square(g.vertices) - g.shift
    texels[:, 3] = reflected_meshes.FOUND_CODE
    answers = data_texture(texels, renderer.meshes.width)
    targets = renderer.draw_passes(view, None)
    translate = np.eye(4)
    translate[:3, 3] = g.shift
    view_projection = Matrix((np.asarray(view.projection_matrix) @ np.asarray(view.view_matrix) @ translate).tolist())
    with saved_state(), targets.reflection.bind():
        gpu.state.viewport_set(0, 0, targets.width, targets.height)
        gpu.state.depth_test_set('LESS')
        gpu.state.depth_mask_set(True)
        setup = {**_bare_setup(renderer, view), "hidden_fraction": hidden_fraction,
                 "reflection_cosine": reflection_cosine, "snap_px": snap_px, "mirrored": mirrored}
        renderer.meshes.draw(view_projection, targets, setup, renderer._image, [(0, answers)])
    return read_texture(targets.reflection_colors, targets.width, targets.height)


def _bare_setup(renderer, view) -> dict:
    """The uniforms of a pass with the base class's tolerances over the renderer's geometry."""
    bare = FramePass()
    bare.geometry = renderer.geometry
    return bare.reflected_setup(Frame(view, None, None, None))


def _at(points, image):
    pixels, _ = _view().to_pixels(np.asarray(points, dtype=np.float64))
    return np.array([image[int(y), int(x)] for x, y in pixels])


HIDDEN_POINTS = [[-0.6, 0.0, 0.0], [-0.45, 0.2, 0.0]]
SEEN_POINTS = [[0.72, 0.0, 0.0], [0.66, -0.2, 0.0]]


def test_a_reflection_whose_mirror_point_is_hidden_by_the_mirror_is_not_drawn(gpu_ready):
    """Answers on the lower square's left half lie behind the upper square as the eye sees
    them (0.5 farther than the surface the pre-pass drew there): not drawn, while those on
    its visible right half are, in their own colour. With the test switched off (an
    unbounded tolerance, as for the morphing grids) the hidden ones are drawn over the
    upper square: the image of a point reflected behind the front of a mirror (a bump, a
    teapot's handle)."""
    from curved_reflections.drawing.frame_pass import FramePass

    image = _drawn(FramePass.hidden_fraction, FramePass.reflection_cosine)
    assert np.all(_at(HIDDEN_POINTS, image)[:, 3] == 0.0)
    seen = _at(SEEN_POINTS, image)
    assert np.all(seen[:, 3] > 0.5) and np.allclose(seen[:, :3], (0.0, 1.0, 0.0), atol=1e-6)
    drawn_hidden = _at(HIDDEN_POINTS, _drawn(float("inf"), FramePass.reflection_cosine))
    assert np.all(drawn_hidden[:, 3] > 0.5) and np.allclose(drawn_hidden[:, :3], (1.0, 0.0, 0.0), atol=1e-6)


def test_a_reflection_the_eye_ray_does_not_reflect_toward_is_not_drawn(gpu_ready):
    """The lower square's normals leaning 15 degrees: the eye's rays reflect 30 degrees off
    the patch its answers place there, so nothing is drawn; with the law-of-reflection
    test off (cosine -1) the patch shows. Leaning 5 degrees (10 off, within the test's
    20) it still shows: the test drops another sheet's answers, not an approximate one."""
    from curved_reflections.drawing.frame_pass import FramePass

    assert np.all(_at(SEEN_POINTS, _drawn(FramePass.hidden_fraction, FramePass.reflection_cosine, 15.0))[:, 3] == 0.0)
    assert np.all(_at(SEEN_POINTS, _drawn(FramePass.hidden_fraction, -1.0, 15.0))[:, 3] > 0.5)
    assert np.all(_at(SEEN_POINTS, _drawn(FramePass.hidden_fraction, FramePass.reflection_cosine, 5.0))[:, 3] > 0.5)


def test_the_fragment_tests_that_cannot_fail_are_compiled_out(gpu_ready):
    """A mirror with one sheet (``mirrored``: convex) is drawn without the
    law-of-reflection test, and an unbounded hidden tolerance (morphing's) without the
    hidden-point test; a mirror that may fold keeps both. Drawn with the normals leaning
    15 degrees, the test that would drop the patch is not there for the convex mirror."""
    from curved_reflections.drawing.frame_pass import FramePass
    from curved_reflections.drawing.methods.morph_pass import MorphPass
    from curved_reflections.drawing.reflected_meshes import fragment_tests

    finite = {"hidden_fraction": FramePass.hidden_fraction, "mirrored": frozenset({0}),
              "reflection_cosine": FramePass.reflection_cosine}
    assert fragment_tests(0, finite) == (False, True)
    assert fragment_tests(1, finite) == (True, True)
    assert fragment_tests(1, {**finite, "hidden_fraction": float("inf")}) == (True, False)
    # A tighter tolerance (a render's test of blended answers) can fail on a convex mirror.
    assert fragment_tests(0, {**finite, "reflection_cosine": MorphPass.rendered_reflection_cosine}) == (True, True)
    convex = _drawn(FramePass.hidden_fraction, FramePass.reflection_cosine, 15.0, mirrored=frozenset({0}))
    assert np.all(_at(SEEN_POINTS, convex)[:, 3] > 0.5)
    assert np.all(_at(HIDDEN_POINTS, convex)[:, 3] == 0.0)  # the hidden-point test still runs


def test_snapped_reflected_vertices_leave_no_hole_and_move_less_than_a_cell(gpu_ready):
    """The live view snaps reflected vertices to a grid (``reflected_meshes.SNAP_SHARE``):
    a patch split so finely that its reflected triangles are a fraction of a pixel
    across (most then collapse and are dropped) still covers its whole image, with no
    pixel missing inside it, and its edge moves by less than the grid's spacing."""
    from curved_reflections.drawing.frame_pass import FramePass

    def grown(mask, steps):
        for _ in range(steps):
            padded = np.pad(mask, 1)
            mask = np.any([padded[1 + di:padded.shape[0] - 1 + di, 1 + dj:padded.shape[1] - 1 + dj]
                           for di in (-1, 0, 1) for dj in (-1, 0, 1)], axis=0)
        return mask

    exact = _drawn(FramePass.hidden_fraction, FramePass.reflection_cosine, split=48)[..., 3] > 0.5
    assert exact.sum() > 60
    for snap_px in (1.0, 2.0):
        snapped = _drawn(FramePass.hidden_fraction, FramePass.reflection_cosine, snap_px=snap_px, split=48)
        drawn = snapped[..., 3] > 0.5
        inside = ~grown(~exact, int(np.ceil(snap_px)))
        assert inside.sum() > 10 and drawn[inside].all()
        assert not (drawn & ~grown(exact, int(np.ceil(snap_px)))).any()
        assert np.allclose(snapped[drawn][:, :3], (0.0, 1.0, 0.0), atol=1e-6)


def _face_coloured_box(x0: float, x1: float, z0: float, z1: float) -> DiffuseMesh:
    """A closed box over x in [x0, x1], y in [-0.5, 0.5], z in [z0, z1], its faces wound
    counter-clockwise seen from outside, each with its own vertices: the bottom (facing
    the mirror below) green, the top red, the sides blue."""
    corners = {"bottom": [(x0, -0.5, z0), (x0, 0.5, z0), (x1, 0.5, z0), (x1, -0.5, z0)],
               "top": [(x0, -0.5, z1), (x1, -0.5, z1), (x1, 0.5, z1), (x0, 0.5, z1)],
               "front": [(x0, -0.5, z0), (x1, -0.5, z0), (x1, -0.5, z1), (x0, -0.5, z1)],
               "back": [(x0, 0.5, z0), (x0, 0.5, z1), (x1, 0.5, z1), (x1, 0.5, z0)],
               "left": [(x0, -0.5, z0), (x0, -0.5, z1), (x0, 0.5, z1), (x0, 0.5, z0)],
               "right": [(x1, -0.5, z0), (x1, 0.5, z0), (x1, 0.5, z1), (x1, -0.5, z1)]}
    colour = {"bottom": (0.0, 1.0, 0.0), "top": (1.0, 0.0, 0.0)}
    vertices, triangles, colours = [], [], []
    for face, quad in corners.items():
        b = len(vertices)
        vertices += quad
        triangles += [(b, b + 1, b + 2), (b, b + 2, b + 3)]
        colours += [(*colour.get(face, (0.0, 0.0, 1.0)), 1.0)] * 4
    return DiffuseMesh("Box", np.array(vertices, np.float64), np.array(triangles), np.array(colours), emissive=True)


def _box_reflection(cull: bool, reversed_sense: bool = False) -> np.ndarray:
    """The box's reflection in the lower square (a flat mirror: every image mirrored),
    drawn with its far side culled or not; ``reversed_sense`` culls the faces the
    mirror's winding would keep instead (what a wrong sense would draw)."""
    import gpu
    from mathutils import Matrix

    from curved_reflections.drawing import reflected_meshes
    from curved_reflections.drawing.gpu_data import data_texture, read_texture, saved_state
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    renderer = ReflectionRenderer([_two_level_mirror()], [_face_coloured_box(2.0, 3.0, HEIGHT, HEIGHT + 1.0)],
                                  edge_fraction=None)
    g = renderer.geometry
    assert g.range_windings == (1,) and g.stats["closed_triangles"] == 12
    texels = np.zeros((len(g.vertices), 4), np.float32)
    texels[:, :3] = _reflected_on_the_lower_square(g.vertices) - g.shift
    texels[:, 3] = reflected_meshes.FOUND_CODE
    answers = data_texture(texels, renderer.meshes.width)
    view = _view()
    targets = renderer.draw_passes(view, None)
    translate = np.eye(4)
    translate[:3, 3] = g.shift
    view_projection = Matrix((np.asarray(view.projection_matrix) @ np.asarray(view.view_matrix) @ translate).tolist())
    setup = {**_bare_setup(renderer, view), "mirrored": frozenset({0} if cull else ())}
    culled_faces = reflected_meshes._culled_faces
    if reversed_sense:
        reflected_meshes._culled_faces = lambda winding: culled_faces(-winding)
    try:
        with saved_state(), targets.reflection.bind():
            gpu.state.viewport_set(0, 0, targets.width, targets.height)
            gpu.state.depth_test_set('LESS')
            gpu.state.depth_mask_set(True)
            renderer.meshes.draw(view_projection, targets, setup, renderer._image, [(0, answers)])
    finally:
        reflected_meshes._culled_faces = culled_faces
    return read_texture(targets.reflection_colors, targets.width, targets.height)


def test_the_far_side_of_a_closed_solid_is_culled_in_a_mirrored_image(gpu_ready):
    """A closed box above a flat mirror: the mirror shows its bottom (green), the face
    toward it, and the side facing the eye's axis (blue), never its top (red). Culled by
    winding, its far faces never reach the rasteriser, and the image is the one drawn
    without culling, pixel for pixel; culling the other sense removes the near faces,
    and the top shows instead."""
    plain, culled = _box_reflection(cull=False), _box_reflection(cull=True)
    drawn = plain[..., 3] > 0.5
    colours = plain[drawn][:, :3]
    assert drawn.sum() > 20
    assert np.mean(np.all(colours == (0.0, 1.0, 0.0), axis=1)) > 0.7 and not np.any(colours[:, 0] > 0.0)
    np.testing.assert_array_equal(culled, plain)
    wrong = _box_reflection(cull=True, reversed_sense=True)
    assert np.mean(wrong[drawn][:, 0] == 1.0) > 0.7
