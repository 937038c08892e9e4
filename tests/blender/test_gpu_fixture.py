# SPDX-License-Identifier: GPL-3.0-or-later
"""The GPU fixture gives a working GPU: a custom shader draws, and its pixels read back."""

import numpy as np

SIZE = 32
# Clip-space corners of the triangle and their colours (red, green, blue).
CORNERS = np.array([[-0.8, -0.8], [0.8, -0.8], [0.0, 0.8]], dtype=np.float32)
COLORS = np.array([[1, 0, 0, 1], [0, 1, 0, 1], [0, 0, 1, 1]], dtype=np.float32)
BACKGROUND = (0.1, 0.2, 0.3, 1.0)


def _shaded_triangle_shader(gpu):
    interface = gpu.types.GPUStageInterfaceInfo("shaded_triangle_interface")
    interface.smooth('VEC4', "color_interp")
    info = gpu.types.GPUShaderCreateInfo()
    info.vertex_in(0, 'VEC2', "pos")
    info.vertex_in(1, 'VEC4', "color")
    info.vertex_out(interface)
    info.fragment_out(0, 'VEC4', "frag_color")
    info.vertex_source("void main() { color_interp = color; gl_Position = vec4(pos, 0.0, 1.0); }")
    info.fragment_source("void main() { frag_color = color_interp; }")
    return gpu.shader.create_from_info(info)


def _draw_triangle(gpu):
    from gpu_extras.batch import batch_for_shader

    shader = _shaded_triangle_shader(gpu)
    batch = batch_for_shader(shader, 'TRIS', {"pos": CORNERS, "color": COLORS})
    offscreen = gpu.types.GPUOffScreen(SIZE, SIZE, format='RGBA32F')
    try:
        with offscreen.bind():
            framebuffer = gpu.state.active_framebuffer_get()
            framebuffer.clear(color=BACKGROUND)
            batch.draw(shader)
            pixels = framebuffer.read_color(0, 0, SIZE, SIZE, 4, 0, 'FLOAT')
    finally:
        offscreen.free()
    pixels.dimensions = SIZE * SIZE * 4
    return np.array(pixels, dtype=np.float32).reshape(SIZE, SIZE, 4)  # [row from bottom, column]


def _barycentric(point):
    a, b, c = CORNERS.astype(np.float64)
    matrix = np.column_stack([b - a, c - a])
    u, v = np.linalg.solve(matrix, point - a)
    return np.array([1 - u - v, u, v])


def test_shaded_triangle_reads_back_interpolated_colours(gpu_ready):
    image = _draw_triangle(gpu_ready)
    checked_inside = checked_outside = 0
    for row in range(SIZE):
        for column in range(SIZE):
            centre = (np.array([column, row]) + 0.5) / SIZE * 2 - 1  # pixel centre in NDC
            weights = _barycentric(centre)
            if weights.min() > 0.05:  # well inside: the colour is the barycentric mix
                np.testing.assert_allclose(image[row, column], weights @ COLORS, atol=1e-4)
                checked_inside += 1
            elif weights.min() < -0.05:  # well outside: untouched background
                np.testing.assert_allclose(image[row, column], BACKGROUND, atol=1e-6)
                checked_outside += 1
    assert checked_inside > 100 and checked_outside > 100


def test_corners_show_their_own_colour(gpu_ready):
    image = _draw_triangle(gpu_ready)
    for corner, color in zip(CORNERS, COLORS):
        # One pixel inside each corner, toward the centroid.
        inner = corner + (CORNERS.mean(axis=0) - corner) * 0.15
        column, row = ((inner + 1) / 2 * SIZE).astype(int)
        dominant = int(np.argmax(image[row, column, :3]))
        assert dominant == int(np.argmax(color[:3]))
        assert image[row, column, dominant] > 0.8
