# SPDX-License-Identifier: GPL-3.0-or-later
"""A sample-based camera projecting on the CPU (drawing/methods/camera_source.py):
the reflected triangles it gives are the GPU pass's, so the live view's worker makes a
landing camera's and the main thread only uploads them."""

import numpy as np

from curved_reflections.engine import DiffuseMesh, look_at_view, scene_bounds
from curved_reflections.engine.frame_settings import FrameSettings
from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.engine.methods.sbc import build_sample_based_camera


def _cube(centre, size, colour):
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float64)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    triangles = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    return DiffuseMesh("Cube", (corners - 0.5) * size + centre, triangles, np.tile([*colour, 1.0], (8, 1)),
                       emissive=True)


def _square(name, y, size, colour):
    h = size / 2
    vertices = np.array([[-h, y, -h], [h, y, -h], [h, y, h], [-h, y, h]])
    return DiffuseMesh(name, vertices, np.array([[0, 1, 2], [0, 2, 3]]), np.tile([*colour, 1.0], (4, 1)),
                       emissive=True)


def test_the_cpu_projection_gives_the_gpu_passes_reflected_triangles(gpu_ready):
    from curved_reflections.drawing.methods.camera_source import CameraSource
    from curved_reflections.drawing.methods.sbc_gpu import SBCTextures
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    mirrors = [icosphere((-1.1, 0.0, 0.0), 1.0, 3, name="Left"), icosphere((1.1, 0.0, 0.0), 1.0, 3, name="Right")]
    meshes = [_cube((0.0, -2.2, 0.0), 0.8, (1.0, 0.0, 0.0)), _square("Wall", 3.0, 6.0, (0.0, 1.0, 0.0))]
    view = look_at_view((0.0, -7.0, 1.0), (0.0, 0.0, 0.0), fov_y_deg=35.0, width=96, height=64)
    sbc = build_sample_based_camera(mirrors, view, scene_bounds(mirrors, meshes, margin=1.0), max_order=2,
                                    downsample=2)
    assert any(len(history) == 2 for history in sbc.groups)  # second-order sheets too
    camera_pass = ReflectionRenderer(mirrors, meshes, settings=FrameSettings(polish_camera=False)).camera_pass
    maker = camera_pass.maker
    gpu = maker.triangles(SBCTextures(sbc), view, sbc, vertex_batch=maker.vertex_points())
    cpu = maker.triangles(CameraSource(sbc), view, sbc)
    assert maker.counts["projections"] == 0 and camera_pass.last is None  # nothing kept, nothing drawn

    assert cpu.triangles == gpu.triangles > 100 and cpu.runs == gpu.runs
    assert cpu.mixed_triangles == gpu.mixed_triangles > 0
    assert cpu.stats["projected_vertices"] == gpu.stats["projected_vertices"]
    for name in ("world_depth", "pixel_reflector", "color", "normal_lit", "uv"):
        np.testing.assert_allclose(cpu.arrays[name], gpu.arrays[name], atol=2e-3, err_msg=name)
    np.testing.assert_allclose(cpu.arrays["eye_distance"], gpu.arrays["eye_distance"], atol=2e-3)
