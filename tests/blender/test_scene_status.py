# SPDX-License-Identifier: GPL-3.0-or-later
"""One status store per scene (blender/scene_status.py): renaming a scene keeps its
plan and checks, and a mirror shown in two scenes has a status line in each."""

import bpy
import numpy as np
import pytest

from curved_reflections.engine.spot_check import SpotCheck
from curved_reflections.blender import accuracy, demo_scenes, live, method_plan, morph_bake, scene_status
from curved_reflections.blender.scene_status import status_of


@pytest.fixture
def fig3(empty_scene, registered, gpu_ready):
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, 64, 48)
    scene_status.forget_all()
    yield scene
    live.clear(scene)


def test_renaming_a_scene_mid_session_keeps_its_plan_and_its_checks(fig3):
    live.start(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    live.process(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)  # draws nothing: no view to check
    check = accuracy.Measured(method_plan.ITERATIVE, SpotCheck(10, np.zeros(10)))
    method_plan.note_measured(fig3, {"MirrorSphere": check})  # what the live view keeps for the panel
    [choice] = method_plan.last_choices(fig3)
    fig3.name = "Renamed"
    assert method_plan.last_choices(bpy.data.scenes["Renamed"]) == [choice] and choice.method == method_plan.ITERATIVE
    assert method_plan.measured(bpy.data.scenes["Renamed"]) == {"MirrorSphere": check}
    assert live.state_of(bpy.data.scenes["Renamed"]) is not None


def test_a_mirror_in_two_scenes_has_a_status_line_in_each(fig3):
    other = bpy.data.scenes.new("Other")
    mirror = bpy.data.objects["MirrorSphere"]
    other.collection.objects.link(mirror)
    mirror.curved_reflections.mode = 'MORPHING'
    morph_bake.note_morphing_active(status_of(fig3), mirror.name)
    morph_bake.note_cache_fault(status_of(other), mirror.name, type("Fault", (), {"problem": "a damaged file"}))
    assert morph_bake.reflector_modes(fig3) == [("MirrorSphere", "morphing: the view is inside the baked grid")]
    assert morph_bake.reflector_modes(other) == [("MirrorSphere", "runtime mode: a damaged file")]
    method_plan.plan(other, [], 1.0)
    assert method_plan.last_choices(other) == [] and method_plan.last_choices(fig3) == []  # fig3 not planned yet
    bpy.data.scenes.remove(other)


def test_a_file_load_forgets_every_scene_status(fig3):
    method_plan.note_measured(fig3, {})
    status_of(fig3).grid_lines["MirrorSphere"] = "a line"
    scene_status.forget_all()
    assert status_of(fig3).grid_lines == {} and method_plan.last_choices(fig3) == []
