# SPDX-License-Identifier: GPL-3.0-or-later
"""The operators run through bpy.ops; register/unregister leaves Blender as it found it.

Reports of a background Blender go to the terminal ("Info: ...", "Error: ..."), and an
operator that reports an error makes ``bpy.ops`` raise ``RuntimeError`` with the text.
"""

import bpy
import pytest

import curved_reflections

OPERATORS = ("check_scene", "mark_reflector")
CLASS_NAMES = (
    "CURVED_REFLECTIONS_OT_check_scene",
    "CURVED_REFLECTIONS_OT_mark_reflector",
    "VIEW3D_PT_curved_reflections",
)


def _all_classes():
    """Every class the package registers, whatever its module."""
    from curved_reflections import blender

    return [cls for module in blender._modules for cls in module.classes]


def _add_cube(location=(0, 0, 0)):
    bpy.ops.mesh.primitive_cube_add(location=location)
    return bpy.context.active_object


def _assert_unregistered():
    assert not hasattr(bpy.types.Object, "curved_reflections")
    assert not hasattr(bpy.types.Scene, "curved_reflections")
    for name in CLASS_NAMES:
        assert not hasattr(bpy.types, name), name
    assert not any(cls.is_registered for cls in _all_classes())
    for name in OPERATORS:
        with pytest.raises(AttributeError):
            getattr(bpy.ops.curved_reflections, name).poll()


def test_register_adds_everything_and_unregister_removes_it():
    _assert_unregistered()
    curved_reflections.register()
    try:
        for name in CLASS_NAMES:
            assert hasattr(bpy.types, name), name
        assert all(cls.is_registered for cls in _all_classes())
        assert bpy.types.VIEW3D_PT_curved_reflections.bl_category == "Reflections"
        assert bpy.context.scene.curved_reflections.downsample == 2
    finally:
        curved_reflections.unregister()
    _assert_unregistered()


def test_mark_reflector_toggles_the_selected_objects(empty_scene, registered, capfd):
    first, second = _add_cube(), _add_cube((3, 0, 0))
    first.select_set(True)  # both selected, second active
    assert bpy.ops.curved_reflections.mark_reflector() == {'FINISHED'}
    assert first.curved_reflections.is_reflector and second.curved_reflections.is_reflector
    assert "Marked 2 objects as reflector" in capfd.readouterr().out

    assert bpy.ops.curved_reflections.mark_reflector() == {'FINISHED'}  # all marked: unmark
    assert not first.curved_reflections.is_reflector and not second.curved_reflections.is_reflector

    second.curved_reflections.is_reflector = True
    assert bpy.ops.curved_reflections.mark_reflector() == {'FINISHED'}  # mixed: mark all
    assert first.curved_reflections.is_reflector and second.curved_reflections.is_reflector
    assert bpy.ops.curved_reflections.mark_reflector(action='CLEAR') == {'FINISHED'}
    assert not second.curved_reflections.is_reflector


def test_mark_reflector_needs_a_selected_surface(empty_scene, registered):
    assert not bpy.ops.curved_reflections.mark_reflector.poll()
    _add_cube()
    assert bpy.ops.curved_reflections.mark_reflector.poll()


def test_check_scene_reports_counts(empty_scene, registered, capfd):
    _add_cube().curved_reflections.is_reflector = True
    _add_cube((4, 0, 0))
    _add_cube((-4, 0, 0))
    assert bpy.ops.curved_reflections.check_scene.poll()
    assert bpy.ops.curved_reflections.check_scene() == {'FINISHED'}
    out = capfd.readouterr().out
    # Flat-shaded cubes: the reflector splits per face (24 vertices), 12 triangles each.
    assert "Info: 1 reflector (12 triangles), 2 diffuse meshes (24 triangles)" in out


def test_check_scene_reports_bad_input_without_traceback(empty_scene, registered, capfd):
    _add_cube()  # nothing marked as a reflector
    with pytest.raises(RuntimeError) as error:
        bpy.ops.curved_reflections.check_scene()
    message = str(error.value)
    assert message.startswith("Error: 'Scene': has no visible object marked as a reflector")
    captured = capfd.readouterr()
    assert "Traceback" not in captured.out + captured.err


def test_check_scene_names_the_broken_object(empty_scene, registered):
    cube = _add_cube()
    cube.curved_reflections.is_reflector = True
    cube.data.vertices[0].co.z = float("nan")
    cube.data.update()
    with pytest.raises(RuntimeError, match=r"Error: 'Cube': 1 vertices are NaN"):
        bpy.ops.curved_reflections.check_scene()
