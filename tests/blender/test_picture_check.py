# SPDX-License-Identifier: GPL-3.0-or-later
"""A chosen mode's picture against the trace (blender/picture_check.py)."""

import bpy
import numpy as np
import pytest

from curved_reflections.blender import demo_scenes, method_plan
from curved_reflections.blender.picture_check import MAX_UNLIKE_SHARE, MIN_PIXELS, UNLIKE_COLOUR, compare
from curved_reflections.blender.render_image import render_scene


def test_the_share_of_each_reflectors_pixels_unlike_the_trace_is_counted():
    traced = np.zeros((80, 100, 4), np.float32)
    labels = np.zeros((80, 100), np.float32)
    labels[:40, :] = 1.0  # reflector 0: 4000 px
    labels[40:, :50] = 2.0  # reflector 1: 2000 px
    image = traced.copy()
    image[:4, :30, 1] = 1.0  # 120 of reflector 0's pixels show something else
    image[40:60, :50, 0] = 0.5 * UNLIKE_COLOUR  # a shading difference: alike
    image[60:, 50:] = 1.0  # no reflector there: not counted
    checks = compare(image, traced, labels, [0, 1])
    assert (checks[0].pixels, checks[0].unlike, checks[1].pixels, checks[1].unlike) == (4000, 120, 2000, 0)
    assert not checks[0].within() and checks[1].within() and checks[0].share == pytest.approx(0.03)
    assert checks[0].shortfall() == "3.0 % of its pixels unlike the same view ray traced"
    few = compare(image[:, :30], traced[:, :30], labels[:, :30], [0])[0]
    assert few.pixels < MIN_PIXELS and few.share > MAX_UNLIKE_SHARE and few.within()  # too few to judge


def _bumpy_ball(amplitude: float):
    from test_frame_pipeline import _fold

    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, 240, 160)
    scene.curved_reflections.max_order = 1
    _fold(bpy.data.objects["MirrorSphere"], amplitude)
    bpy.data.objects["Cube"].location.x += 0.6
    bpy.data.objects["MirrorSphere"].curved_reflections.mode = 'ITERATIVE'
    return scene


@pytest.mark.parametrize("amplitude", [0.05, 0.08])
def test_a_chosen_mode_whose_picture_differs_from_the_trace_is_ray_traced(empty_scene, registered, gpu_ready,
                                                                          amplitude):
    """Iterative mode on a ball with bumps of 8 % of its radius: every image is searched
    from the folds' patches, and the answers pass the spot check, but where a fold's
    images meet, a triangle between vertices on two of them crosses the mirror: the
    picture differs from the trace's on 3 % of the ball's pixels, and Render Image draws
    the trace with the reason. With bumps of 5 % the picture is the trace's, and kept."""
    scene = _bumpy_ball(amplitude)
    rendered = render_scene(scene, bpy.context.evaluated_depsgraph_get())
    check = method_plan.measured(scene)["MirrorSphere"]
    picture = method_plan.pictures(scene)["MirrorSphere"]
    [choice] = method_plan.last_choices(scene)
    assert check.method == method_plan.ITERATIVE and check.check.within(1.0), check.check.summary()
    assert picture.pixels > 5000
    if amplitude == 0.05:
        assert rendered.stats["methods"] == {"MirrorSphere": "ITERATIVE"} and picture.share < 0.01
        return
    assert rendered.stats["methods"] == {"MirrorSphere": "TRACED"} and picture.share > 0.025
    assert choice.reason == f"Iterative (GPU): {picture.shortfall()}; ray traced instead"


def test_runtime_mode_is_judged_by_its_picture(empty_scene, registered, gpu_ready):
    """A sample-based camera's frame has no answers per vertex to check; its picture is
    compared with the trace's (the band along the ball's outline, which the render
    traces, alike in both), and on the plain ball it is the trace's: Runtime draws it."""
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, 240, 160)
    bpy.data.objects["MirrorSphere"].curved_reflections.mode = 'RUNTIME'
    rendered = render_scene(scene, bpy.context.evaluated_depsgraph_get())
    picture = method_plan.pictures(scene)["MirrorSphere"]
    assert rendered.stats["methods"] == {"MirrorSphere": "RUNTIME"} and rendered.camera is not None
    assert picture.pixels > 5000 and picture.share < MAX_UNLIKE_SHARE and "MirrorSphere" not in method_plan.measured(
        scene)


def test_the_resting_live_view_hands_a_chosen_mode_whose_picture_differs_to_the_trace(empty_scene, registered,
                                                                                      gpu_ready):
    """The live view checks a chosen mode's picture too, once its view has rested (the
    draw after the vertex check started), and plans again: the folded ball of the test
    above, in Iterative mode, is ray traced with the reason."""
    from test_live import _draw

    from curved_reflections.blender import accuracy, live
    from curved_reflections.blender.capture import view_from_camera

    scene = _bumpy_ball(0.08)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view = view_from_camera(scene.camera, scene, depsgraph)
    state = live.start(scene, depsgraph, {live.CAMERA_KEY: view}, wait=True)
    try:
        assert _draw(scene, view)[0] and not method_plan.pictures(scene)
        live.process(scene, depsgraph, wait=True, now=state.last_view[1] + accuracy.SETTLE_SECONDS + 0.01)
        check = method_plan.measured(scene)["MirrorSphere"]
        assert check.method == method_plan.ITERATIVE and check.check.within(1.0), check.check.summary()
        assert _draw(scene, view)[0]  # the resting view: its picture is checked
        picture = method_plan.pictures(scene)["MirrorSphere"]
        assert picture.share > 0.025 and state.dirty_reflectors
        live.process(scene, bpy.context.evaluated_depsgraph_get(), wait=True)  # plans again
        [choice] = method_plan.last_choices(scene)
        assert choice.method == method_plan.TRACED
        assert choice.reason == f"Iterative (GPU): {picture.shortfall()}; ray traced instead"
    finally:
        live.clear(scene)
