# SPDX-License-Identifier: GPL-3.0-or-later
"""One status store per scene (operators/scene_status.py): renaming a scene keeps its
plan and checks, and a mirror shown in two scenes has a status line in each."""

import bpy
import numpy as np
import pytest

from curved_reflections.addon.spot_check import SpotCheck
from curved_reflections.operators import accuracy, demo_scenes, live, methods, morph_bake, scene_status
from curved_reflections.operators.scene_status import status_of


@pytest.fixture
def fig3(empty_scene, registered, gpu_ready):
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, 64, 48)
    scene_status.forget_all()
    yield scene
    live.clear(scene)


def test_renaming_a_scene_mid_session_keeps_its_plan_and_its_checks(fig3):
    live.bake(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    live.process(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)  # draws nothing: no view to check
    check = accuracy.Measured(methods.ITERATIVE, SpotCheck(10, np.zeros(10)))
    methods.note_measured(fig3, {"MirrorSphere": check})  # what the live view keeps for the panel
    [choice] = methods.last_choices(fig3)
    fig3.name = "Renamed"
    assert methods.last_choices(bpy.data.scenes["Renamed"]) == [choice] and choice.method == methods.ITERATIVE
    assert methods.measured(bpy.data.scenes["Renamed"]) == {"MirrorSphere": check}
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
    methods.plan(other, [], 1.0)
    assert methods.last_choices(other) == [] and methods.last_choices(fig3) == []  # fig3 not planned yet
    bpy.data.scenes.remove(other)


def test_a_file_load_forgets_every_scene_status(fig3):
    methods.note_measured(fig3, {})
    status_of(fig3).grid_lines["MirrorSphere"] = "a line"
    scene_status.forget_all()
    assert status_of(fig3).grid_lines == {} and methods.last_choices(fig3) == []
