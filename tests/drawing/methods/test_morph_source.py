# SPDX-License-Identifier: GPL-3.0-or-later
"""Morphing grids drawn by the reflection renderer (drawing/methods/morph_source.py and
the numpy reference tools/numpy_morph_source.py, SBC paper VI).

A mirror sphere with a red square beside it and a large green one behind that (out of
the camera's sight), seen from inside the sphere's grid: the morphed reflection lands
where the runtime camera's does, the nodes' projections on the GPU give the numpy
engine's first reflector points, and sources combine sheet by sheet.
"""

import numpy as np
import pytest

from curved_reflections.engine import DiffuseMesh, look_at_view, scene_bounds
from curved_reflections.engine.methods.sbc import build_sample_based_camera
from curved_reflections.engine.methods.morphing import morph_grid as G
from curved_reflections.engine.methods.morphing import morphing as M
from curved_reflections.engine.reference.exact import solve_reflections
from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.engine.geometry.sphere import icosphere

RED, GREEN, BLUE = np.eye(3)
SETTINGS = G.MorphSettings(grid=(7, 7, 7), margin=0.8, face_resolution=48)


def _square(name, x, size, colour):
    h = size / 2
    vertices = np.array([[x, -h, -h], [x, h, -h], [x, h, h], [x, -h, h]])
    return DiffuseMesh(name, vertices, np.array([[0, 1, 2], [0, 2, 3]]), np.tile([*colour, 1.0], (4, 1)),
                       emissive=True)


@pytest.fixture(scope="module")
def scene(gpu_ready):
    mirror = icosphere((0.0, 0.0, 0.0), 1.0, 4, name="Mirror")
    meshes = [_square("Near", 2.5, 1.0, RED), _square("Far", 4.0, 4.0, GREEN)]
    view = look_at_view((0.4, -2.3, 0.3), (0.0, 0.0, 0.0), fov_y_deg=50.0, width=96, height=96)
    grid = M.grid_on_demand(mirror, SETTINGS)
    bounds = scene_bounds([mirror], meshes, margin=1.0)
    sbc = build_sample_based_camera([mirror], view, bounds, downsample=2)
    return mirror, meshes, view, grid, sbc


def _render(scene, source=None, camera=None):
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    mirror, meshes, view, _, _ = scene
    renderer = ReflectionRenderer([mirror], meshes)
    return renderer.render(view, camera, world_color=(*BLUE, 1.0), trace=False, source=source), renderer


def _mask(image, colour):
    return np.abs(image[..., :3] - colour).max(axis=2) < 1e-3


def test_gpu_face_images_are_the_numpy_engines(scene):
    """Each cube face of a node projects on the GPU (GLSL twin of SampleBasedCamera.project)
    to the numpy engine's first reflector points: same points projected, to float32 accuracy."""
    from curved_reflections.drawing.methods.morph_source import GPUFaceImages

    _, _, view, grid, _ = scene
    _, nodes, _, _ = grid.check_view(view)
    faces = [sbc for sbc in grid.nodes[int(nodes[0])].faces if sbc is not None]
    points = np.random.default_rng(3).uniform(-4.0, 4.0, (4000, 3))
    points = points[np.linalg.norm(points, axis=1) > 1.1]
    gpu_faces = GPUFaceImages()
    compared = 0
    for sbc in faces:
        expected, found = M.project_face(sbc, points), gpu_faces(sbc, points)
        both = np.isfinite(expected[..., 0]) & np.isfinite(found[..., 0])
        assert (np.isfinite(expected[..., 0]) != np.isfinite(found[..., 0])).sum() <= max(2, 0.002 * both.sum())
        assert np.abs(expected[both] - found[both]).max() < 1e-3
        compared += both.sum()
    assert compared > 1000 and gpu_faces.packs == len(faces)
    gpu_faces(faces[0], points[:10])
    assert gpu_faces.packs == len(faces)  # packed once, reused


def test_morphed_reflection_lands_where_the_exact_reflection_is(scene):
    """The red square's corners, drawn from the grid, sit within a pixel or two of their
    exact reflections (a coarse test grid: 48 px faces), and the squares' reflections
    cover what the runtime camera's do."""
    from curved_reflections.tools.numpy_morph_source import MorphSource

    mirror, meshes, view, grid, sbc = scene
    morphed, renderer = _render(scene, MorphSource([(grid, np.eye(4))], view))
    runtime, _ = _render(scene, camera=sbc)
    # Morphing's coverage thins at grazing angles (docs/benchmarks/morphing.md): the large
    # square, reflected out to the mirror's rim, keeps about 80 % of its pixels there.
    for colour, recall in ((RED, 0.9), (GREEN, 0.75)):
        ours, theirs = _mask(morphed, colour), _mask(runtime, colour)
        assert theirs.sum() > 100
        assert (ours & theirs).sum() >= 0.9 * ours.sum()
        assert (ours & theirs).sum() >= recall * theirs.sum()
    corners = meshes[0].vertices
    exact = solve_reflections(ReflectorSet([mirror]), view, corners)
    blended = grid.project(corners, view)
    assert blended.valid[0].all()
    seen = exact.seen_by_eye & exact.in_view
    errors = [np.linalg.norm(exact.pixel[seen & (exact.point == k)] - blended.pixels[0, k], axis=1).min()
              for k in range(len(corners))]
    assert max(errors) < 1.0
    assert renderer.stats["projected_vertices"] > 0
