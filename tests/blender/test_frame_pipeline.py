# SPDX-License-Identifier: GPL-3.0-or-later
"""The frame pipeline that Render Image and the live view share (blender/frame_pipeline.py)."""

import bpy
import numpy as np
import pytest

from curved_reflections.engine.frame_settings import FrameSettings
from curved_reflections.blender import demo_scenes, live
from curved_reflections.blender.capture import view_from_camera
from curved_reflections.blender.frame_pipeline import settings_of
from curved_reflections.blender.render_image import render_scene

WIDTH, HEIGHT = 128, 96


@pytest.fixture
def fig3(empty_scene, registered, gpu_ready):
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, WIDTH, HEIGHT)
    yield scene
    live.clear(scene)


def _live_frame(scene):
    """The live view's pipeline for the scene camera's view, rendered offscreen with the
    renderer and the camera it keeps for that view."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    state = live.start(scene, depsgraph, wait=True)
    view = view_from_camera(scene.camera, scene, depsgraph)
    camera = state.cameras[live.CAMERA_KEY]
    assert camera.view.same_as(view)
    return state, state.renderer.render(view, camera.sbc, state.world)


@pytest.mark.parametrize("mode", ['AUTO', 'RUNTIME', 'PERTURBATION'])
def test_render_image_and_the_live_view_draw_the_same_pixels(fig3, mode):
    # Nothing touching the ball: Perturbation leaves out images of what almost touches the
    # mirror (the cube, the floor; a test below), and Render Image's check would draw it
    # in Runtime mode.
    bpy.data.objects["MirrorSphere"].location.z += 0.3
    bpy.data.objects["Cube"].location.x += 0.6
    bpy.data.objects["MirrorSphere"].curved_reflections.mode = mode
    rendered = render_scene(fig3, bpy.context.evaluated_depsgraph_get())
    state, image = _live_frame(fig3)
    assert rendered.stats["methods"] == {c.reflector: c.method for c in state.plan.choices}
    assert (rendered.camera is None) == (state.cameras[live.CAMERA_KEY].sbc is None) == (mode != 'RUNTIME')
    assert image.shape == rendered.image.shape == (HEIGHT, WIDTH, 4)
    assert np.array_equal(image, rendered.image)
    assert np.abs(image[..., :3] - image[0, 0, :3]).max() > 0.1  # a picture, not a blank frame


def test_the_settings_record_reads_the_scene_and_its_overrides(fig3):
    s = fig3.curved_reflections
    s.max_order, s.downsample, s.accuracy_px, s.morph_polish_frames = 3, 4, 0.75, False
    assert settings_of(fig3) == FrameSettings(max_order=3, downsample=4, accuracy_px=0.75, polish_frames=False,
                                              morph_budget_mb=s.morph_gpu_budget_mb, polish_camera=True)
    assert not settings_of(fig3, live=True).polish_camera
    assert settings_of(fig3, max_order=1, accuracy_px=None).max_order == 1
    assert settings_of(fig3, max_order=1, accuracy_px=None).accuracy_px == 0.75


def test_one_rule_decides_whether_a_view_needs_a_camera(fig3):
    """The searched ball alone at Max Order 2 needs none (it is convex: no higher order);
    in Runtime mode every view needs one, for the ball's first order."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view = view_from_camera(fig3.camera, fig3, depsgraph)
    state = live.start(fig3, depsgraph, wait=True)
    assert state.camera_job(view) is None and state.cameras[live.CAMERA_KEY].sbc is None
    bpy.data.objects["MirrorSphere"].curved_reflections.mode = 'RUNTIME'
    state = live.start(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    job = state.camera_job(view)
    assert job is not None and job.first_order_left_out == frozenset() and job.settings == state.settings
    assert state.cameras[live.CAMERA_KEY].sbc is not None


def _fold(mirror, amplitude: float) -> None:
    """Make ``mirror`` (the demo's ball) a ball with bumps of ``amplitude`` times its
    radius: star-shaped around its centre, and folded where the bumps are strong."""
    from curved_reflections.engine.geometry.sphere import bumpy_icosphere

    bumpy = bumpy_icosphere((0.0, 0.0, 0.0), 1.0, 4, amplitude)
    mesh = bpy.data.meshes.new("Bumpy")
    mesh.from_pydata(bumpy.vertices.tolist(), [], bumpy.triangles.tolist())
    mesh.shade_smooth()
    mirror.data = mesh
    mirror.scale = (1.0, 1.0, 1.0)


def test_iterative_mode_searches_every_image_of_a_folded_mirror_and_auto_traces_it(fig3):
    """With bumps of 15 % of the ball's radius a column is seen two or three times.
    Iterative mode searches every image of the folded mirror, and the check keeps it
    (exact where drawn, at most 5 % of the exact images missed); Auto traces it per pixel
    (every image, no camera) and says why: each frame would search each patch. The
    search's starts on the folds are made only for Iterative mode."""
    from curved_reflections.blender import method_plan, star_maps
    from curved_reflections.blender.frame_pipeline import FramePipeline

    _fold(bpy.data.objects["MirrorSphere"], 0.15)
    bpy.data.objects["Cube"].location.x += 0.6  # 3 % of the radius away: the bumps would cut into it
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view = view_from_camera(fig3.camera, fig3, depsgraph)
    pipeline = FramePipeline()
    pipeline.update(fig3, depsgraph, settings_of(fig3))
    [choice] = pipeline.plan.choices
    assert choice.method == method_plan.TRACED and "but it folds its reflections" in choice.reason, choice.reason
    assert pipeline.camera_job(view) is None  # the trace draws every order
    [mirror] = pipeline.captured.reflectors
    traced_map = star_maps.star_map(mirror)[1]
    assert traced_map.images > 1 and traced_map.patches is None
    bpy.data.objects["MirrorSphere"].curved_reflections.mode = method_plan.ITERATIVE
    pipeline.update(fig3, bpy.context.evaluated_depsgraph_get(), settings_of(fig3))
    [choice] = pipeline.plan.choices
    assert choice.method == method_plan.ITERATIVE and "every image" in choice.reason
    [engine] = pipeline.plan.engines_of(method_plan.ITERATIVE)
    assert len(engine.reflector_map.patches) > 50 and f"from {len(engine.reflector_map.patches)} patches" in choice.reason
    searched = pipeline.renderer
    searched.render(view, None, pipeline.world)
    assert not pipeline.check_methods(fig3, view) and pipeline.renderer is searched
    check = method_plan.measured(fig3)["MirrorSphere"].check
    assert check.within(1.0) and check.images > 60 and check.missed <= 0.05 * check.images, check.summary()


def test_an_explicit_mode_that_leaves_out_a_near_objects_images_falls_back_to_the_trace(fig3):
    """sbc_fig3's cube almost touches the ball (3 % of its radius away). Perturbation
    leaves out part of the cube's near face: the check, which samples each object's
    points, finds the cube's images missing (a uniform sample of the scene's vertices
    would hardly meet the cube), and the explicit mode falls back to the trace with the
    reason; the iterative search, in Auto, draws the cube and is kept."""
    from curved_reflections.blender import method_plan
    from curved_reflections.blender.frame_pipeline import FramePipeline

    fig3.curved_reflections.max_order = 1
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view = view_from_camera(fig3.camera, fig3, depsgraph)
    for mode, kept in (('AUTO', True), ('PERTURBATION', False)):
        bpy.data.objects["MirrorSphere"].curved_reflections.mode = mode
        pipeline = FramePipeline()
        pipeline.update(fig3, depsgraph, settings_of(fig3))
        pipeline.renderer.render(view, None, pipeline.world)
        replaced = pipeline.check_methods(fig3, view)
        assert replaced is not kept, (mode, method_plan.measured(fig3)["MirrorSphere"].check.summary())
        check = method_plan.measured(fig3)["MirrorSphere"].check
        [choice] = pipeline.plan.choices
        if kept:
            assert choice.method == method_plan.ITERATIVE and check.missed_in == ""
            continue
        assert check.missed_in == "Cube" and check.missed >= 2
        assert choice.method == method_plan.TRACED and pipeline.camera_job(view) is None
        assert choice.reason == (f"Perturbation: {check.missed} of {check.images} exact images of Cube not drawn in a "
                                 "view (Accuracy 1 px); ray traced instead")
