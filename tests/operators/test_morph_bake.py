# SPDX-License-Identifier: GPL-3.0-or-later
"""Bake / clear morphing grids through bpy.ops, and the state drawing code then finds.

Background mode runs the operator's ``execute`` (a synchronous bake on worker
processes). Every outcome leaves a drawable state: a grid, or None (runtime mode)
with the reason in ``morph_status``.
"""

import bpy
import numpy as np
import pytest


@pytest.fixture
def morph_ops(registered, monkeypatch):
    from curved_reflections.operators import morph_bake

    monkeypatch.setattr(morph_bake, "FACE_RESOLUTION", 32)  # a fast bake; the figures are the benchmark's

    added = [cls for cls in morph_bake.classes if not cls.is_registered]
    for cls in added:
        bpy.utils.register_class(cls)
    morph_bake._STATE.clear()
    morph_bake._REFLECTOR_STATUS.clear()
    yield morph_bake
    for cls in reversed(added):
        bpy.utils.unregister_class(cls)


def _mirror_scene(scene, mode='MORPHING'):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0.5, 0.0, 1.0), segments=24, ring_count=12)
    ball = bpy.context.active_object
    ball.name = "Ball"
    ball.curved_reflections.is_reflector = True
    ball.curved_reflections.mode = mode
    scene.curved_reflections.morph_grid = (2, 2, 2)
    scene.curved_reflections.morph_margin = 0.6
    return ball


def _captured(context, morph_bake):
    (reflector, matrix), = morph_bake.morphing_reflectors(context)
    return reflector, matrix


def test_bake_load_stale_and_clear(empty_scene, morph_ops):
    ball = _mirror_scene(empty_scene)
    context = bpy.context
    assert morph_ops.morph_status(empty_scene) == "No morphing grid baked in this session"
    reflector, matrix = _captured(context, morph_ops)
    assert morph_ops.load_morphing(reflector, matrix, empty_scene) is None
    assert "Ball: no morphing cache yet" in morph_ops.morph_status(empty_scene)

    assert bpy.ops.curved_reflections.bake_morphing(processes=2) == {'FINISHED'}
    assert "Ball: baked 8 nodes" in morph_ops.morph_status(empty_scene)
    grid = morph_ops.load_morphing(reflector, matrix, empty_scene)
    assert grid is not None and grid.grid.shape == (2, 2, 2)
    assert "Ball: morphing (baked grid loaded)" in morph_ops.morph_status(empty_scene)
    from curved_reflections.addon import look_at_view
    from curved_reflections.addon.morphing import ViewOutsideGrid

    with pytest.raises(ViewOutsideGrid) as outside:
        grid.project(np.zeros((1, 3)), look_at_view([0.0, -20.0, 1.0], [0.5, 0.0, 1.0]), matrix=matrix)
    morph_ops.note_runtime_fallback(outside.value)
    assert "Ball: runtime mode: the view is outside the morphing grid" in morph_ops.morph_status(empty_scene)

    # Moving the mirror keeps its grid (baked in its own frame); scaling it does not.
    ball.location = (2.0, 1.0, 0.5)
    ball.rotation_euler = (0.0, 0.0, 0.8)
    bpy.context.view_layer.update()
    reflector, matrix = _captured(context, morph_ops)
    assert morph_ops.load_morphing(reflector, matrix, empty_scene) is not None
    ball.scale = (1.2, 1.0, 1.0)
    bpy.context.view_layer.update()
    reflector, matrix = _captured(context, morph_ops)
    assert morph_ops.load_morphing(reflector, matrix, empty_scene) is None
    assert "other geometry or settings; bake again" in morph_ops.morph_status(empty_scene)

    assert bpy.ops.curved_reflections.clear_morphing() == {'FINISHED'}
    assert morph_ops.load_morphing(reflector, matrix, empty_scene) is None
    assert "Ball: no morphing cache yet" in morph_ops.morph_status(empty_scene)
    assert not any(morph_ops.cache_directory().iterdir())


def test_bake_without_a_morphing_reflector_reports_an_error(empty_scene, morph_ops):
    _mirror_scene(empty_scene, mode='RUNTIME')
    with pytest.raises(RuntimeError, match="No visible reflector is in Morphing mode"):
        bpy.ops.curved_reflections.bake_morphing()
    assert not morph_ops._STATE.get(empty_scene.name, {}).get("running")


def test_classes_tuple_and_status_while_running(morph_ops, empty_scene):
    assert [cls.bl_idname for cls in morph_ops.classes] == ["curved_reflections.bake_morphing",
                                                            "curved_reflections.clear_morphing"]
    morph_ops._STATE[empty_scene.name] = {"running": True, "done": 3, "total": 405, "reflector": "Ball",
                                          "message": ""}
    assert morph_ops.morph_status(empty_scene) == "Baking Ball: 3/405 nodes (Esc cancels)"
    assert not bpy.ops.curved_reflections.bake_morphing.poll()
    morph_ops._STATE.clear()
    assert np.prod(tuple(empty_scene.curved_reflections.morph_grid)) == 405
