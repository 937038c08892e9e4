# SPDX-License-Identifier: GPL-3.0-or-later
"""The per-frame passes' reflected meshes (``gpu_shaders/reflected_meshes.py``): placed by
answer textures, kept on the visible footprint of their mirror, and dropped where their
reflector point is hidden from the eye by the mirror itself."""

import numpy as np

from curved_reflections.addon import DiffuseMesh, Reflector, look_at_view

#: Diffuse vertices far off to the side (out of the view, so that the pre-pass shows the
#: mirror under their reflections); each is answered on the mirror at its (x - OFFSET, y, 0).
OFFSET = 10.0


def _two_level_mirror() -> Reflector:
    """One reflector of two squares facing +z: the lower one, z = 0 over [-1, 1]^2, and
    above its left half, at z = 0.5, the upper one, hiding that half from above."""
    vertices = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0],
                         [-1, -1, 0.5], [0, -1, 0.5], [0, 1, 0.5], [-1, 1, 0.5]], dtype=np.float64)
    triangles = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    return Reflector("Terrace", vertices, triangles, np.tile([0.0, 0.0, 1.0], (8, 1)))


def _patch(name: str, x0: float, x1: float, colour) -> DiffuseMesh:
    """A finely split flat patch over x in [x0, x1] + OFFSET, y in [-0.4, 0.4], z = 3."""
    n = 8
    xs, ys = np.meshgrid(np.linspace(x0, x1, n) + OFFSET, np.linspace(-0.4, 0.4, n))
    vertices = np.c_[xs.ravel(), ys.ravel(), np.full(n * n, 3.0)]
    quads = [(j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i) for j in range(n - 1) for i in range(n - 1)]
    triangles = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    return DiffuseMesh(name, vertices, triangles, np.tile([*colour, 1.0], (n * n, 1)), emissive=True)


def _drawn(hidden_fraction: float) -> np.ndarray:
    """The reflection target's alpha after drawing both patches at their answers."""
    import gpu
    from mathutils import Matrix

    from curved_reflections.gpu_shaders import reflected_meshes
    from curved_reflections.gpu_shaders.gpu_data import data_texture, read_texture, saved_state
    from curved_reflections.gpu_shaders.reflection_draw import ReflectionRenderer

    mirror = _two_level_mirror()
    meshes = [_patch("Hidden", -0.8, -0.2, (1.0, 0.0, 0.0)), _patch("Seen", 0.2, 0.8, (0.0, 1.0, 0.0))]
    view = look_at_view((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov_y_deg=35.0, width=80, height=80)
    renderer = ReflectionRenderer([mirror], meshes, edge_fraction=None)
    g = renderer.geometry
    texels = np.zeros((len(g.vertices), 4), np.float32)
    texels[:, :3] = g.vertices * [1, 1, 0] - [OFFSET, 0, 0] - g.shift
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
        setup = {**renderer.reflected_setup(view, renderer.iterative), "hidden_fraction": hidden_fraction}
        renderer.meshes.draw(view_projection, targets.prepass_labels, setup, renderer._image, [(0, answers)])
    return read_texture(targets.reflection_colors, targets.width, targets.height)


def _pixels(view_points, image):
    view = look_at_view((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov_y_deg=35.0, width=80, height=80)
    pixels, _ = view.to_pixels(np.asarray(view_points, dtype=np.float64))
    return np.array([image[int(y), int(x)] for x, y in pixels])


def test_a_reflection_whose_mirror_point_is_hidden_by_the_mirror_is_not_drawn(gpu_ready):
    """Answers on the lower square's left half lie behind the upper square as the eye sees
    them (0.5 farther than the surface the pre-pass drew there): not drawn, while those on
    its visible right half are, in their own colour. With the test switched off (an
    unbounded tolerance, as for the morphing grids) the hidden ones are drawn over the
    upper square: the image of a point reflected behind the front of a mirror (a bump, a
    teapot's handle)."""
    hidden, seen = [[-0.5, 0.0, 0.0], [-0.35, 0.2, 0.0]], [[0.5, 0.0, 0.0], [0.35, -0.2, 0.0]]
    from curved_reflections.gpu_shaders.frame_pass import FramePass

    image = _drawn(FramePass.hidden_fraction)
    assert np.all(_pixels(hidden, image)[:, 3] == 0.0)
    seen_pixels = _pixels(seen, image)
    assert np.all(seen_pixels[:, 3] > 0.5) and np.allclose(seen_pixels[:, :3], (0.0, 1.0, 0.0), atol=1e-6)
    unbounded = _drawn(float("inf"))
    drawn_hidden = _pixels(hidden, unbounded)
    assert np.all(drawn_hidden[:, 3] > 0.5) and np.allclose(drawn_hidden[:, :3], (1.0, 0.0, 0.0), atol=1e-6)
