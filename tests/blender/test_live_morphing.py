# SPDX-License-Identifier: GPL-3.0-or-later
"""Reflectors in Morphing mode in the live view (blender/live.py, SBC paper VI).

The sbc_fig3 scene, its mirror ball switched to Morphing. The grid comes from
``morphing.grid_on_demand`` (nodes built when a view first needs them) in place of a
baked cache, so the test builds four nodes instead of baking a grid; loading and
staleness of real caches are tested in test_morph_bake.py. A view inside the grid
draws the ball's reflections from the grid with no camera built; the same view in
Runtime mode draws nearly the same image; a view outside the grid draws runtime
mode, and the panel's line for the ball says which mode draws it and why.
"""

import bpy
import numpy as np
import pytest

from curved_reflections.engine.methods.morphing import morph_grid, morphing
from curved_reflections.engine.view import look_at_view
from curved_reflections.blender import demo_scenes, live, morph_bake
from curved_reflections.blender import scene_status
from curved_reflections.blender.scene_status import status_of

from test_live import HEIGHT, WIDTH, _draw, _pixels_of, _touched

SETTINGS = morph_grid.MorphSettings(grid=(7, 7, 5), margin=0.8, face_resolution=48)


@pytest.fixture
def fig3_morphing(empty_scene, registered, gpu_ready, monkeypatch):
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, WIDTH, HEIGHT)
    bpy.data.objects["MirrorSphere"].curved_reflections.mode = 'RUNTIME'  # each test chooses its mode

    def grid_on_demand(reflector, matrix, scene, reflector_index=0):
        local = morph_grid.reflector_in_frame(reflector, morph_grid.rigid_frame(matrix))
        status_of(scene).grid_lines[reflector.name] = "morphing (baked grid loaded)"
        return morphing.grid_on_demand(local, SETTINGS, reflector_index,
                                       polish=scene.curved_reflections.morph_polish_nodes)

    monkeypatch.setattr(morph_bake, "load_morphing", grid_on_demand)
    scene_status.forget_all()
    return scene


def _views():
    mirror = bpy.data.objects["MirrorSphere"]
    centre = np.array(mirror.matrix_world.translation)
    radius = 0.5 * max(mirror.dimensions)
    near = look_at_view(centre + radius * np.array([0.4, -2.4, 0.8]), centre, fov_y_deg=45.0,
                        width=WIDTH, height=HEIGHT, name="near")
    far = look_at_view(centre + radius * np.array([0.4, -9.0, 2.0]), centre, fov_y_deg=20.0,
                       width=WIDTH, height=HEIGHT, name="far")
    return mirror, near, far


def test_morphing_draws_inside_its_grid_and_runtime_outside(fig3_morphing):
    scene = fig3_morphing
    mirror, near, far = _views()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    state = live.start(scene, depsgraph, views={"near": near}, wait=True)
    assert state.cameras["near"].sbc is not None  # Runtime mode: a camera
    runtime = _draw(scene, near, "near")[1]

    mirror.curved_reflections.mode = 'MORPHING'  # its update callback re-bakes (auto refresh)
    assert [grid.reflector_name for grid, _ in state.grids] == ["MirrorSphere"]
    camera = state.cameras["near"]
    assert camera.sbc is None and [grid.reflector_name for grid, _ in camera.morph] == ["MirrorSphere"]
    drawn, morphed = _draw(scene, near, "near")
    assert drawn and state.stats["morphing"] == "MirrorSphere"
    assert morph_bake.reflector_modes(scene) == [("MirrorSphere", "morphing: the view is inside the baked grid")]
    # The same mirror pixels are drawn, and they show what runtime mode shows there.
    touched = _touched(morphed)
    assert touched.sum() > 0.9 * _touched(runtime).sum() > 1000
    same = np.abs(morphed[..., :3] - runtime[..., :3]).max(axis=2) < 0.02
    # The live view snaps morphing's vertices to the Accuracy's grid (1 px), the runtime
    # camera's triangles not: measured 0.89 of the pixels alike (over 0.9 unsnapped).
    assert same[touched].mean() > 0.85
    assert len(_pixels_of(morphed, "FloorA", scene)) > 200

    # A view outside the grid is drawn in runtime mode, and the panel says why.
    live._start_camera(state, "far", far, wait=True)
    assert state.cameras["far"].sbc is not None and state.cameras["far"].morph == []
    assert _draw(scene, far, "far")[0]
    assert morph_bake.reflector_modes(scene) == [
        ("MirrorSphere", "runtime mode: the view is outside the morphing grid")]

    # Back to Runtime: a camera again, and the ball no longer listed as morphing.
    mirror.curved_reflections.mode = 'RUNTIME'
    assert state.grids == [] and state.cameras["near"].sbc is not None
    assert morph_bake.reflector_modes(scene) == []
    np.testing.assert_allclose(_draw(scene, near, "near")[1], runtime, atol=1e-6)


def test_render_image_draws_from_the_grid_on_the_gpu(fig3_morphing):
    """Render Image in Morphing mode, the scene camera inside the grid: no camera is built,
    the grid is blended on the GPU, and the image is the Runtime mode's but for a few
    per cent of its pixels (fewer with all its gaps ray traced, not only the band along
    the silhouette); later frames keep the renderer and the nodes' images."""
    from mathutils import Vector

    from curved_reflections.blender.render_image import FrameState, render_scene

    scene = fig3_morphing
    scene.curved_reflections.max_order = 1  # a second order would need a camera
    mirror, near, _ = _views()
    camera = scene.camera
    camera.location = Vector(near.eye)
    camera.rotation_euler = (Vector(mirror.matrix_world.translation) - camera.location).to_track_quat(
        '-Z', 'Y').to_euler()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    runtime = render_scene(scene, depsgraph)
    assert runtime.stats["n_rays"] > 100

    mirror.curved_reflections.mode = 'MORPHING'
    state = FrameState()
    morphed = render_scene(scene, bpy.context.evaluated_depsgraph_get(), state=state)
    assert morphed.stats["methods"] == {"MirrorSphere": "MORPHING"}
    assert "n_rays" not in morphed.stats  # no camera built (the on-demand grid builds its nodes meanwhile)
    # The camera's tetrahedron and the rest of its cube, whose images the surface fit reads.
    assert state.renderer.pass_named("morphing").counts == {"blends": 1, "node_projections": 8}
    # Polish Node Images is on by default: the eight nodes' grazing and widened-chart
    # images were polished on the GPU (two dispatches a node where it has both).
    grid = state.renderer.pass_named("morphing").grids[0][0]
    assert grid.mirror is not None and grid.image_polish.dispatches >= 8
    # The test grid is coarse (48-pixel faces, 7 x 7 x 5 nodes): measured, 1.67 % of the
    # image (before each frame's blend was polished) (the ball fills about half of it) differs from the runtime camera's (2.0 %
    # before the surface fit read the whole cube's nodes, 3.2 % before images were matched
    # across nodes by MATCH_SLOPE, 2.2 % before the strip along the rim was traced and
    # blended fragments held to 6 degrees), 1.68 % with every gap traced (1.98 % against
    # 2.0 % before: the cube's fit leaves fewer gaps).
    differing = np.abs(morphed.image[..., :3] - runtime.image[..., :3]).max(axis=2) > 0.05
    assert differing.mean() < 0.03
    # Each frame's blend is polished on the mirror (Polish Every Frame, on by default), so
    # the hidden-point test applies; on this quadric mirror the polish moves images by a
    # fraction of a pixel: 1.73 % of the image differs, 1.70 % with the blend alone.
    morph = state.renderer.pass_named("morphing")
    assert morph.polish_frames and morph.hidden_fraction < 1.0
    scene.curved_reflections.morph_polish_frames = False
    alone = FrameState()
    blended = render_scene(scene, bpy.context.evaluated_depsgraph_get(), state=alone)
    morph = alone.renderer.pass_named("morphing")
    assert not morph.polish_frames and morph.hidden_fraction == np.inf
    assert (np.abs(blended.image[..., :3] - runtime.image[..., :3]).max(axis=2) > 0.05).mean() < 0.03
    scene.curved_reflections.morph_polish_frames = True
    # The band along the silhouette without a reflection and the strip between it and the
    # reflection are traced, every gap on request only.
    traced = render_scene(scene, bpy.context.evaluated_depsgraph_get(), trace_gaps=True, state=state)
    assert 100 < morphed.stats["traced_pixels"] < 0.5 * traced.stats["traced_pixels"]
    closer = np.abs(traced.image[..., :3] - runtime.image[..., :3]).max(axis=2) > 0.05
    assert closer.mean() < differing.mean() + 0.002  # the traced gaps are what the runtime camera draws
    camera.location.x += 0.01
    render_scene(scene, bpy.context.evaluated_depsgraph_get(), state=state)
    assert state.reused == 2 and state.renderer.pass_named("morphing").counts["blends"] == 3
    # Its nodes project on the GPU: an animation prefetches none on the worker thread,
    # whose numpy projection would differ by float32's rounding.
    assert state.renderer.pass_named("morphing").prefetching == 0


def test_render_image_in_octree_mode_draws_from_ray_octrees_on_the_gpu(fig3_morphing, monkeypatch):
    """Octree mode: the grid of ray octrees (Martin & Popescu 2004) is blended over the
    eight nodes of the camera's cell on the GPU, and the image is the Runtime mode's but
    for a few per cent of its pixels, as the tetrahedral grid's above. An animation
    projects the nodes around the camera ahead on a worker thread, and a frame is the
    same whether they were ready or not."""
    from dataclasses import replace

    from mathutils import Vector

    from curved_reflections.engine.methods.octree import OctreeGrid, octree_grid_on_demand
    from curved_reflections.blender.render_image import PREFETCHED_NODES, FrameState, render_scene

    def octree_on_demand(reflector, matrix, scene, reflector_index=0):
        local = morph_grid.reflector_in_frame(reflector, morph_grid.rigid_frame(matrix))
        return octree_grid_on_demand(local, replace(SETTINGS, face_resolution=96), reflector_index)

    monkeypatch.setattr(morph_bake, "load_morphing", octree_on_demand)
    scene = fig3_morphing
    scene.curved_reflections.max_order = 1
    mirror, near, _ = _views()
    camera = scene.camera
    camera.location = Vector(near.eye)
    camera.rotation_euler = (Vector(mirror.matrix_world.translation) - camera.location).to_track_quat(
        '-Z', 'Y').to_euler()
    runtime = render_scene(scene, bpy.context.evaluated_depsgraph_get())
    mirror.curved_reflections.mode = 'OCTREE'
    state = FrameState()
    octree = render_scene(scene, bpy.context.evaluated_depsgraph_get(), state=state)
    assert octree.stats["methods"] == {"MirrorSphere": "OCTREE"} and "n_rays" not in octree.stats
    assert isinstance(state.renderer.pass_named("morphing").grids[0][0], OctreeGrid)
    assert state.renderer.pass_named("morphing").counts == {"blends": 1, "node_projections": 8}
    differing = np.abs(octree.image[..., :3] - runtime.image[..., :3]).max(axis=2) > 0.05
    assert differing.mean() < 0.05  # measured: 3.8 % (the rim of the ball, where rays graze)

    morph = state.renderer.pass_named("morphing")
    assert morph.prefetching == PREFETCHED_NODES
    for _, future in list(morph._pending.values()):
        future.result(timeout=300)
    camera.location.x += 0.01
    depsgraph = bpy.context.evaluated_depsgraph_get()
    moved = render_scene(scene, depsgraph, state=state)
    assert morph.counts["node_projections"] == 8 + PREFETCHED_NODES  # collected, none projected again
    np.testing.assert_array_equal(moved.image, render_scene(scene, depsgraph).image)


def test_live_view_prefetches_the_nodes_around_the_eye(fig3_morphing):
    """After a draw from the grid, the next node around the eye is projected on a worker
    thread; the timer's pass sees it ready, the next draw uploads it and starts another."""
    scene = fig3_morphing
    scene.curved_reflections.max_order = 1
    mirror, near, _ = _views()
    mirror.curved_reflections.mode = 'MORPHING'
    state = live.start(scene, bpy.context.evaluated_depsgraph_get(), views={"near": near}, wait=True)
    assert _draw(scene, near, "near")[0]
    morph = state.renderer.pass_named("morphing")
    assert morph.counts["node_projections"] == 8 and morph.prefetching == 1
    (_, future), = morph._pending.values()
    future.result(timeout=120)
    assert live.process(scene, bpy.context.evaluated_depsgraph_get())  # still work: a node to upload
    assert _draw(scene, near, "near")[0]
    assert morph.counts["node_projections"] == 9 and morph.prefetching == 1 and len(morph.nodes) == 9
