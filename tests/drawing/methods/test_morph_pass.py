# SPDX-License-Identifier: GPL-3.0-or-later
"""Reflection morphing every frame on the GPU (drawing/methods/morph_pass.py, glsl/morph_blend.glsl).

A mirror sphere with a grid of 7 x 7 x 7 nodes (48-pixel cube faces, nodes built on
demand): the GPU blend agrees with the numpy engine's ``MorphingGrid.project`` on a
cloud of points (same answers, within 0.05 px); node images are projected once and
kept, so a view in another tetrahedron whose nodes are on the GPU projects nothing; the
memory budget drops the least recently used nodes; and the renderer draws a reflection
from the grid where the runtime camera draws it.
"""

import numpy as np
import pytest

from curved_reflections.engine import DiffuseMesh, look_at_view, scene_bounds
from curved_reflections.engine.methods.sbc import build_sample_based_camera
from curved_reflections.engine.methods.morphing import morphing as M
from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.drawing.methods.morph_pass import MorphPass

from test_morph_source import BLUE, GREEN, RED, SETTINGS, _square


def _cloud(n=3000, seed=1):
    points = np.random.default_rng(seed).uniform(-4.0, 4.0, (3 * n, 3))
    points = points[np.linalg.norm(points, axis=1) > 1.2][:n]
    return DiffuseMesh("Cloud", points, np.arange(n).reshape(-1, 3), np.ones((n, 4)), emissive=True)


@pytest.fixture(scope="module")
def mirror(gpu_ready):
    from curved_reflections.drawing.methods.morph_source import GPUFaceImages

    sphere = icosphere((0.0, 0.0, 0.0), 1.0, 4, name="Mirror")
    grid = M.grid_on_demand(sphere, SETTINGS)
    grid.face_images = GPUFaceImages()
    return sphere, grid


@pytest.fixture(scope="module")
def coarse_mirror(gpu_ready):
    """The same sphere and grid with 24-pixel cube faces: for the tests of which nodes are
    projected and kept, where what a node sees does not matter, only that it is built."""
    from dataclasses import replace

    from curved_reflections.drawing.methods.morph_source import GPUFaceImages

    sphere = icosphere((0.0, 0.0, 0.0), 1.0, 4, name="Mirror")
    grid = M.grid_on_demand(sphere, replace(SETTINGS, face_resolution=24))
    grid.face_images = GPUFaceImages()
    return sphere, grid


@pytest.fixture(scope="module")
def octree_mirror(gpu_ready):
    """The same sphere and grid with ray octrees at the nodes (Martin & Popescu 2004)."""
    from dataclasses import replace

    from curved_reflections.engine.methods.octree import octree_grid_on_demand

    sphere = icosphere((0.0, 0.0, 0.0), 1.0, 4, name="Mirror")
    return sphere, octree_grid_on_demand(sphere, replace(SETTINGS, face_resolution=96))


def _run_now(function, *args):
    """An executor's ``submit`` that runs the function at once."""
    from concurrent.futures import Future

    future = Future()
    future.set_result(function(*args))
    return future


def _view(eye, size=(320, 240)):
    return look_at_view(eye, (0.0, 0.0, 0.0), fov_y_deg=50.0, width=size[0], height=size[1])


def _pass(mirror, meshes, budget_mb=256.0):
    from curved_reflections.drawing.methods.morph_pass import MorphPass
    from curved_reflections.drawing.draw_geometry import prepare_geometry

    sphere, grid = mirror
    geometry = prepare_geometry([sphere], meshes, edge_fraction=None)
    return MorphPass(geometry, [(grid, np.eye(4))], budget_mb=budget_mb), geometry


@pytest.mark.parametrize("grid", ["mirror", "octree_mirror"])
@pytest.mark.parametrize("eye", [(0.4, -2.3, 0.3), (-1.9, 1.2, -0.8)])
def test_gpu_blend_is_the_numpy_blend(request, grid, eye):
    """Same vertices answered, same pixels within 0.05 px: the float32 match, blend and
    surface refinement (analytic Newton) against the float64 engine, for the four nodes
    of a tetrahedron (with the rest of its cube for the surface fit) and the eight of an
    octree grid's cube."""
    mirror = request.getfixturevalue(grid)
    _assert_gpu_blend_is_numpy_blend(mirror, _view(eye), n_nodes=8)  # the eye's cube, outside the mirror


def test_a_cell_with_a_node_inside_the_mirror_blends_over_the_other_seven(mirror):
    """The cube of this eye's tetrahedron has a corner inside the sphere (never built;
    the tetrahedron's four are outside): the other seven are fitted, by a shader built
    for seven."""
    grid = mirror[1]
    view = _view((-1.65, 0.75, 0.65))
    _, nodes, weights, _ = grid.check_view(view)
    assert len(nodes) == 7 and np.count_nonzero(weights) == 4
    _assert_gpu_blend_is_numpy_blend(mirror, view, n_nodes=7)


def test_the_blend_shader_builds_for_cells_of_four_to_eight_nodes(gpu_ready):
    """A tetrahedron's cube keeps the nodes outside the mirror (4 to 8; a shader each)."""
    from curved_reflections.drawing.methods.morph_pass import blend_shader

    for n_nodes in range(4, 9):
        assert blend_shader(n_nodes, 1, 1, min(4, n_nodes)) is not None


def _assert_gpu_blend_is_numpy_blend(mirror, view, n_nodes):
    morph, geometry = _pass(mirror, [_cloud()])
    assert morph.blend(view) == [0]
    assert morph.counts["node_projections"] == n_nodes
    found = morph.read(0)
    expected = mirror[1].project(geometry.vertices, view)
    compared = 0
    for k in range(min(len(found), len(expected.groups))):
        ours, theirs = np.isfinite(found[k][:, 0]), expected.valid[k]
        both = ours & theirs
        pixels, _ = view.to_pixels(found[k][both])
        errors = np.linalg.norm(pixels - expected.pixels[k][both], axis=1)
        # Decided apart: answered by one side only, or a fit whose residual passes its
        # bound in float32 and not in float64 (a vertex the cell's images see spread
        # over a third of this coarse grid's sphere), the linear blend taken instead.
        assert (ours != theirs).sum() + (errors > 0.5).sum() <= max(2, 0.002 * theirs.sum())
        assert np.percentile(errors, 99) < 0.05
        compared += both.sum()
    assert compared > 500


def test_nodes_are_projected_once_and_kept(coarse_mirror):
    """A second view in the same tetrahedron, then one in a neighbouring cell whose
    nodes were prefetched, project no node; the budget keeps the nodes in use (a
    tetrahedron's four and the rest of its cube, which the surface fit reads)."""
    mirror = coarse_mirror  # some 50 nodes built: 24-pixel cube faces, a quarter of the rays
    morph, _ = _pass(mirror, [_cloud(600)])
    first = _view((0.4, -2.3, 0.3))
    morph.blend(first)
    assert morph.counts["node_projections"] == 8 and len(morph.nodes) == 8
    morph.blend(_view((0.41, -2.29, 0.31)))
    assert morph.counts["node_projections"] == 8
    # Prefetching: the numpy projection of the nodes around the eye, handed to `submit`
    # (here run at once), uploaded by collect().
    assert morph.prefetch(first, _run_now, max_pending=2) == 2 and morph.prefetching == 2
    assert morph.prefetched and morph.collect() == 2 and morph.counts["node_projections"] == 10
    prefetched = 0
    while morph.prefetch(first, _run_now, max_pending=8):  # the rest of the 4 x 4 x 4 nodes around the eye
        prefetched += morph.collect()
    assert 20 <= prefetched <= 54 and morph.prefetching == 0
    grid = mirror[1]
    tet = grid.check_view(first)[0]
    step = grid.grid.spacing * np.array([0.6, 0.0, 0.0])
    moved = _view(np.array([0.4, -2.3, 0.3]) + step)
    assert grid.check_view(moved)[0] != tet
    projected = morph.counts["node_projections"]
    morph.blend(moved)
    assert morph.counts["node_projections"] == projected  # its nodes were prefetched

    # An animation's prefetch serves the cells its camera is about to enter first.
    fresh, _ = _pass(mirror, [_cloud(600)])
    fresh.blend(first)
    far = np.array([0.4, -2.3, 0.3]) + grid.grid.spacing * np.array([0.0, 0.0, 2.6])  # three cells up
    ahead_nodes = {int(n) for n in grid.check_view(_view(far))[1]}
    assert not any((0, node) in fresh.nodes for node in ahead_nodes)
    assert fresh.prefetch(first, _run_now, max_pending=len(ahead_nodes), ahead=[far]) == len(ahead_nodes)
    assert fresh.collect() == len(ahead_nodes) and all((0, node) in fresh.nodes for node in ahead_nodes)

    one_node = 2 * 3 * morph.meshes.width * morph.meshes.height * 16
    small, _ = _pass(mirror, [_cloud(600)], budget_mb=8.5 * one_node / 2 ** 20)
    small.blend(first)
    assert len(small.nodes) == 8 and small.nodes.evictions == 0
    small.blend(moved)
    assert len(small.nodes) == 8 and small.nodes.evictions > 0  # the old nodes went, the eight in use stay
    assert small.nodes.nbytes <= small.nodes.budget_bytes


def test_renderer_draws_the_grid_where_the_runtime_camera_draws(mirror):
    """The red square beside the sphere, drawn from the grid every frame with no camera,
    covers the pixels the runtime camera's reflection covers."""
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    sphere, grid = mirror
    meshes = [_square("Near", 2.5, 1.0, RED), _square("Far", 4.0, 4.0, GREEN)]
    view = _view((0.4, -2.3, 0.3), (96, 96))
    morphed_renderer = ReflectionRenderer([sphere], meshes, passes=[MorphPass.factory([(grid, np.eye(4))])])
    morphed = morphed_renderer.render(view, None, world_color=(*BLUE, 1.0), trace=False)
    bounds = scene_bounds([sphere], meshes, margin=1.0)
    sbc = build_sample_based_camera([sphere], view, bounds, downsample=2)
    runtime = ReflectionRenderer([sphere], meshes).render(view, sbc, world_color=(*BLUE, 1.0), trace=False)
    assert morphed_renderer.pass_named("morphing").counts["blends"] == 1
    for colour, recall in ((RED, 0.85), (GREEN, 0.7)):
        ours = np.abs(morphed[..., :3] - colour).max(axis=2) < 1e-3
        theirs = np.abs(runtime[..., :3] - colour).max(axis=2) < 1e-3
        assert theirs.sum() > 100
        assert (ours & theirs).sum() >= 0.9 * ours.sum()
        assert (ours & theirs).sum() >= recall * theirs.sum()


def test_polished_frames_are_the_numpy_engines_and_the_exact_reflections(gpu_ready):
    """Each frame's blend polished on the mirror (``MorphPass(polish_frames=True)``,
    ``glsl/image_polish.glsl``'s FRAME_ANSWERS) on a rounded box, a mirror that is not a
    quadric: the same vertices answered as the numpy engine's polished blend, within
    0.01 px of it and of the exact solver, where the blend alone misses by pixels."""
    from curved_reflections.tools.surfaces import superellipsoid
    from curved_reflections.engine.reference.exact import solve_reflections
    from curved_reflections.engine.geometry.raytrace import ReflectorSet
    from curved_reflections.drawing.draw_geometry import prepare_geometry
    from curved_reflections.drawing.methods.morph_pass import MorphPass
    from curved_reflections.drawing.methods.morph_source import GPUFaceImages

    box = superellipsoid((0.0, 0.0, 0.0), (1.2, 0.9, 0.8), 4.0, 4, "Box")
    grid = M.grid_on_demand(box, SETTINGS, polish=True)
    grid.face_images = GPUFaceImages()
    cloud = _cloud(1500)
    geometry = prepare_geometry([box], [cloud], edge_fraction=None)
    view = _view((0.4, -2.6, 0.5))
    answers = {}
    for polish in (False, True):
        morph = MorphPass(geometry, [(grid, np.eye(4))], polish_frames=polish)
        assert morph.blend(view) == [0]
        ours = morph.read(0)[0]
        grid.polish_frames = polish
        theirs = grid.project(geometry.vertices, view)
        found = np.isfinite(ours[:, 0])
        assert (found != theirs.valid[0]).sum() <= 2
        both = found & theirs.valid[0]
        pixels, _ = view.to_pixels(ours[both])
        assert np.percentile(np.linalg.norm(pixels - theirs.pixels[0][both], axis=1), 99) < 0.01
        answers[polish] = ours, both
    # The exact reflections of the vertices answered either way only: the rest are never
    # compared (each vertex is solved on its own).
    solved = np.flatnonzero(answers[False][1] | answers[True][1])
    exact = solve_reflections(ReflectorSet([box]), view, geometry.vertices[solved])
    exact = exact.select(exact.visible)
    truth = np.full((len(geometry.vertices), 2), np.nan)
    truth[solved[exact.point]] = exact.pixel
    errors = {}
    for polish, (ours, both) in answers.items():
        seen = both & np.isfinite(truth[:, 0])
        errors[polish] = np.linalg.norm(view.to_pixels(ours[seen])[0] - truth[seen], axis=1)
    assert np.percentile(errors[False], 99) > 2.0
    assert np.percentile(errors[True], 99) < 0.01 and len(errors[True]) > 500  # blend 5.8 px; polished 1.5e-5 px on 765
