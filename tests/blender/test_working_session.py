# SPDX-License-Identifier: GPL-3.0-or-later
"""The working-session corpus, live view (issue 46): what an artist does between frames
with the live reflections running, each case ending in the right picture or a clear
message, nothing sticky, no traceback, no data lost.

"The right picture" is the picture of the same final state built afresh
(``session_scene.fresh``: the live state cleared and started again): the session's
draw must equal it. Background mode has no 3D view: the draw handler's code runs into
an offscreen (``test_live._draw``), and an edit reaches the live view through the real
``depsgraph_update_post`` handler on ``view_layer.update()``. The files, bakes and
caches of a session are in test_working_session_files.py; docs/benchmarks/reliability.md
lists every case.
"""

import bpy
import bmesh  # after bpy: Blender's module provides it
import numpy as np
import pytest

from curved_reflections.blender import live, live_handlers, live_workers
from curved_reflections.blender.capture import capture_scene
from curved_reflections.engine.view import look_at_view

from session_scene import (HEIGHT, WIDTH, _touched, add_ball, build, camera_view, differing, draw, fresh,
                           select_only, settle)

#: Share of pixels a picture may differ from the fresh one where the session left a
#: different history of cameras (traced pixels landing in another order): a few pixels.
TINY = 0.005


@pytest.fixture
def session(empty_scene, registered, gpu_ready, capfd):
    """The corpus scene with the live view started; after the case, nothing it did may
    have printed a traceback."""
    scene = build()
    assert bpy.ops.curved_reflections.start_live() == {'FINISHED'}
    yield scene
    live.clear_all()
    captured = capfd.readouterr()
    assert "Traceback" not in captured.out + captured.err


def _update():
    bpy.context.view_layer.update()


def _ball():
    return bpy.data.objects["Ball"]


def test_edit_mode_edit_of_the_mirror(session):
    before = settle()[1]
    select_only(_ball())
    bpy.ops.object.mode_set(mode='EDIT')
    mesh = bmesh.from_edit_mesh(_ball().data)
    for vertex in mesh.verts:
        vertex.co.x *= 1.3
    bmesh.update_edit_mesh(_ball().data)
    _update()
    state = live.state_of(session)
    assert state.counts["captures"] >= 2  # seen in Edit Mode
    in_edit = settle()[1]
    assert _touched(in_edit).sum() > _touched(before).sum() + 40  # a wider mirror
    assert differing(in_edit, fresh()) == 0.0
    bpy.ops.object.mode_set(mode='OBJECT')
    _update()
    assert differing(settle()[1], in_edit) == 0.0


def test_sculpting_the_mirror(session):
    """A sculpt stroke writes the mesh's positions in Sculpt Mode (here: inflated 15 %)."""
    before = settle()[1]
    select_only(_ball())
    bpy.ops.object.mode_set(mode='SCULPT')
    mesh = _ball().data
    positions = np.empty(3 * len(mesh.vertices), np.float32)
    mesh.vertices.foreach_get("co", positions)
    mesh.vertices.foreach_set("co", positions * 1.15)
    mesh.update()
    _update()
    sculpted = settle()[1]
    assert live.state_of(session).counts["captures"] >= 2
    assert _touched(sculpted).sum() > _touched(before).sum() + 40
    assert differing(sculpted, fresh()) == 0.0
    bpy.ops.object.mode_set(mode='OBJECT')
    assert differing(settle()[1], sculpted) == 0.0


def _modifier_picture(session, *kinds):
    ball = _ball()
    for kind in kinds:
        modifier = ball.modifiers.new(kind.title(), kind)
        if kind == 'CAST':
            modifier.cast_type, modifier.factor = 'CUBOID', 0.8
        elif kind == 'SIMPLE_DEFORM':
            modifier.deform_method, modifier.angle, modifier.deform_axis = 'TWIST', np.radians(60.0), 'X'
    _update()
    return settle()[1]


def test_add_reorder_disable_and_apply_modifiers(session):
    plain = settle()[1]
    cast_then_twist = _modifier_picture(session, 'CAST', 'SIMPLE_DEFORM')
    assert differing(cast_then_twist, plain) > 0.01 and differing(cast_then_twist, fresh()) == 0.0
    select_only(_ball())
    assert bpy.ops.object.modifier_move_to_index(modifier="Simple_Deform", index=0) == {'FINISHED'}
    _update()
    twist_then_cast = settle()[1]
    assert [m.name for m in _ball().modifiers] == ["Simple_Deform", "Cast"]
    assert differing(twist_then_cast, cast_then_twist) > 0.002 and differing(twist_then_cast, fresh()) == 0.0
    for modifier in _ball().modifiers:
        modifier.show_viewport = False
    _update()
    assert differing(settle()[1], plain) == 0.0  # as before any modifier
    for modifier in _ball().modifiers:
        modifier.show_viewport = True
    _update()
    assert bpy.ops.object.modifier_apply(modifier="Simple_Deform") == {'FINISHED'}
    assert bpy.ops.object.modifier_apply(modifier="Cast") == {'FINISHED'}
    _update()
    assert not _ball().modifiers
    assert differing(settle()[1], twist_then_cast) < 0.002  # the same surface, now the mesh's own


def test_hiding_the_only_mirror_stops_drawing_it_until_shown(session, capfd):
    before = settle()[1]
    _ball().hide_set(True)
    _update()
    with pytest.raises(RuntimeError, match="'Scene': has no visible object marked as a reflector"):
        bpy.ops.curved_reflections.refresh()
    state = live.state_of(session)
    assert state.level == 'ERROR' and "no visible object marked as a reflector" in state.status
    drawn, image = draw()
    assert not drawn and not _touched(image).any()  # no ghost of the hidden mirror
    _ball().hide_set(False)
    _update()
    assert bpy.ops.curved_reflections.refresh() == {'FINISHED'}
    assert state.level == 'INFO' and differing(settle()[1], before) == 0.0


def test_hiding_one_of_two_mirrors_then_editing_the_scene(session):
    other = add_ball("Other")
    assert bpy.ops.curved_reflections.refresh() == {'FINISHED'}
    both = settle()[1]
    other.hide_set(True)  # sends no depsgraph update of its own
    bpy.data.objects["Box"].location.z += 0.05  # the next edit finds it
    _update()
    state = live.state_of(session)
    assert [r.name for r in state.captured.reflectors] == ["Ball"]
    image = settle()[1]
    assert state.level == 'INFO', state.status
    assert _touched(image).sum() < _touched(both).sum() - 50 and differing(image, fresh()) == 0.0


def test_deleting_one_of_two_reflectors_while_their_camera_builds(session):
    """The view's camera builds on the worker; the mirror left is drawn alone."""
    other = add_ball("Other")
    state = live.start(session, bpy.context.evaluated_depsgraph_get(), wait=False)
    assert live.CAMERA_KEY in state.jobs
    bpy.data.objects.remove(other)
    _update()
    state.jobs.get(live.CAMERA_KEY) and state.jobs[live.CAMERA_KEY].future.result(timeout=60)
    image = settle()[1]
    assert [r.name for r in state.captured.reflectors] == ["Ball"] and state.level == 'INFO'
    assert differing(image, fresh()) == 0.0


def test_deleting_the_only_reflector_while_its_camera_builds(session):
    """The camera that lands is dropped: no ghost of the deleted mirror is drawn."""
    state = live.start(session, bpy.context.evaluated_depsgraph_get(), wait=False)
    build = state.jobs[live.CAMERA_KEY].future
    bpy.data.objects.remove(_ball())
    _update()
    build.result(timeout=60)
    live.process(session, bpy.context.evaluated_depsgraph_get(), wait=True)  # the camera lands: dropped
    assert state.level == 'ERROR' and "no visible object marked as a reflector" in state.status
    drawn, image = draw()
    assert not drawn and not _touched(image).any()


def test_renaming_the_scene(session, tmp_path):
    state = live.state_of(session)
    session.name = "Shot 2"
    assert live.state_of(session) is state  # the state is the scene's, whatever its name
    assert bpy.ops.curved_reflections.render_image(filepath=str(tmp_path / "shot.png")) == {'FINISHED'}
    _ball().curved_reflections.is_reflector = False
    with pytest.raises(RuntimeError, match="'Shot 2': has no visible object marked"):
        bpy.ops.curved_reflections.refresh()


def test_renaming_the_mirror(session):
    before = settle()[1]
    state = live.state_of(session)
    _ball().name = "Mirror"
    bpy.data.objects["Box"].location.z += 0.0  # any edit: the renamed mirror is captured under its new name
    bpy.data.objects["Box"].update_tag()
    _update()
    assert [r.name for r in state.captured.reflectors] == ["Mirror"]
    assert differing(settle()[1], before) == 0.0
    bpy.data.objects["Mirror"].scale.x = 0.0
    with pytest.raises(RuntimeError, match="'Mirror': has zero scale along an axis"):
        bpy.ops.curved_reflections.refresh()


@pytest.mark.parametrize("linked", [True, False], ids=["linked", "unlinked"])
def test_duplicating_a_mirror(session, linked):
    select_only(_ball())
    assert bpy.ops.object.duplicate(linked=linked) == {'FINISHED'}
    copy = bpy.context.active_object
    copy.location = (-1.8, 0.8, 1.2)
    copy.scale = (0.5, 0.5, 0.5)
    _update()
    assert copy.curved_reflections.is_reflector and (copy.data == _ball().data) == linked
    state = live.state_of(session)
    assert sorted(r.name for r in state.captured.reflectors) == ["Ball", copy.name]
    image = settle()[1]
    assert differing(image, fresh()) == 0.0
    copy.data.vertices[0].co.z += 0.4  # an edit of the copy's mesh: the original too when linked
    copy.data.update()
    _update()
    ball_vertices = capture_scene(bpy.context.evaluated_depsgraph_get()).reflectors[0].vertices
    assert (np.abs(ball_vertices - state.captured.reflectors[0].vertices).max() > 0.1) == linked
    assert differing(settle()[1], fresh()) == 0.0


def _scatter(instance, as_instance: bool, points):
    """An object of two points whose Geometry Nodes put ``instance`` on both."""
    mesh = bpy.data.meshes.new("Points")
    mesh.from_pydata(points, [], [])
    host = bpy.data.objects.new("Scatter", mesh)
    bpy.context.scene.collection.objects.link(host)
    tree = bpy.data.node_groups.new("Scatter", 'GeometryNodeTree')
    tree.interface.new_socket("Geometry", in_out='INPUT', socket_type='NodeSocketGeometry')
    tree.interface.new_socket("Geometry", in_out='OUTPUT', socket_type='NodeSocketGeometry')
    nodes = tree.nodes
    group_in, group_out = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    points, place = nodes.new("GeometryNodeMeshToPoints"), nodes.new("GeometryNodeInstanceOnPoints")
    info = nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value = instance
    info.inputs["As Instance"].default_value = as_instance
    tree.links.new(group_in.outputs[0], points.inputs["Mesh"])
    tree.links.new(points.outputs[0], place.inputs["Points"])
    tree.links.new(info.outputs["Geometry"], place.inputs["Instance"])
    tree.links.new(place.outputs[0], group_out.inputs[0])
    host.modifiers.new("Scatter", 'NODES').node_group = tree
    _update()
    return host


def test_geometry_nodes_instances_of_a_mirror_and_of_a_reflected_object(session):
    """Instances of the marked ball are mirrors; instances of the box's geometry (not of
    the object) are reflected, each under its mesh's name."""
    small = add_ball("Small", location=(0.0, 8.0, -3.0), radius=0.3)  # seen only through its instances
    _scatter(small, as_instance=True, points=[(-1.4, 1.0, 1.3), (-2.0, 1.5, 0.6)])
    captured = capture_scene(bpy.context.evaluated_depsgraph_get())
    assert [r.name for r in captured.reflectors] == ["Ball", "Small"] + [
        "Small (instanced by Scatter)" + suffix for suffix in ("", " #2")]
    assert bpy.ops.curved_reflections.refresh() == {'FINISHED'}
    assert differing(settle()[1], fresh()) < TINY

    bpy.data.objects.remove(bpy.data.objects["Scatter"])
    box = bpy.data.objects["Box"]
    box.hide_set(True)
    assert bpy.ops.curved_reflections.refresh() == {'FINISHED'}
    without = settle()[1]
    _scatter(box, as_instance=False, points=[(1.6, -0.9, 0.6), (1.1, -1.7, 1.5)])
    captured = capture_scene(bpy.context.evaluated_depsgraph_get())
    assert [m.name for m in captured.meshes] == ["Cube (instanced by Scatter)" + s for s in ("", " #2")]
    assert bpy.ops.curved_reflections.refresh() == {'FINISHED'}
    image = settle()[1]
    assert differing(image, without) > 0.003 and differing(image, fresh()) < TINY  # the scattered boxes, reflected


def test_undo_and_redo_during_a_live_build(session):
    bpy.ops.ed.undo_push(message="start")
    original = settle()[1]
    _ball().location.x += 0.4
    _update()
    bpy.ops.ed.undo_push(message="move")
    moved = settle()[1]
    assert differing(moved, original) > 0.01
    scene = bpy.context.scene
    state = live.start(scene, bpy.context.evaluated_depsgraph_get(), wait=False)  # a camera on the worker
    assert bpy.ops.ed.undo() == {'FINISHED'}
    scene = bpy.context.scene  # undo gives new Python objects for the same data
    assert live.state_of(scene) is state and bpy.data.objects["Ball"].location.x == pytest.approx(0.0)
    for build in list(state.jobs.values()):
        build.future.result(timeout=60)
    undone = settle(scene)[1]
    assert differing(undone, moved) > 0.01 and differing(undone, fresh(scene)) < TINY
    assert bpy.ops.ed.redo() == {'FINISHED'}
    scene = bpy.context.scene
    assert differing(settle(scene)[1], moved) < TINY


def _two_viewports(session):
    live.clear(session)
    front, side = camera_view(), look_at_view((5.0, -3.0, 2.0), (0.0, 0.0, 1.0), fov_y_deg=40.0, width=WIDTH,
                                              height=HEIGHT)
    state = live.start(session, bpy.context.evaluated_depsgraph_get(), views={"front": front, "side": side},
                       wait=True)
    return state, front, side


def test_two_viewports(session):
    """Two 3D views of one scene keep a camera each; moving one view rebuilds its own."""
    state, front, side = _two_viewports(session)
    assert sorted(state.cameras) == ["front", "side"]
    images = {key: settle(key=key, view=view)[1] for key, view in (("front", front), ("side", side))}
    assert differing(images["front"], images["side"]) > 0.02
    side_camera = state.cameras["side"]
    closer = look_at_view((4.0, -2.4, 1.8), (0.0, 0.0, 1.0), fov_y_deg=40.0, width=WIDTH, height=HEIGHT)
    closer_image = settle(key="side", view=closer)[1]
    assert state.cameras["side"] is not side_camera and state.cameras["front"].view is front
    assert differing(closer_image, fresh(key="side", view=closer)) == 0.0


def test_a_second_window_on_another_scene(session):
    """Another scene in a second window is live too; an edit in one scene leaves the
    other's state alone."""
    state, front, side = _two_viewports(session)
    other = bpy.data.scenes.new("Other")
    for obj in (_ball(), bpy.data.objects["Box"], session.camera):
        other.collection.objects.link(obj)
    other.camera = session.camera
    other.render.resolution_x, other.render.resolution_y = WIDTH, HEIGHT
    other.view_layers[0].update()
    depsgraph = other.view_layers[0].depsgraph
    other_state = live.start(other, depsgraph, views={"window": front}, wait=True)
    assert other_state is not state and other_state.captured.reflectors[0].name == "Ball"
    captures = other_state.counts["captures"]
    bpy.data.objects["Box"].location.x += 0.2  # linked to both scenes: only the context's processes it
    _update()
    assert other_state.counts["captures"] == captures and state.counts["remeshes"] == 1
    for key, view in (("front", front), ("side", side)):
        assert differing(settle(key=key, view=view)[1], fresh(key=key, view=view)) == 0.0


def test_disable_and_enable_the_extension_with_the_live_view_running(session, registered):
    before = settle()[1]
    ball = _ball()
    ball.curved_reflections.mode = 'ITERATIVE'
    ball.curved_reflections.reflectivity = 0.8
    live.start(session, bpy.context.evaluated_depsgraph_get(), wait=False)  # work on the worker
    registered.unregister()
    assert not live._states and not live_workers.running() and live_handlers._draw_handle is None
    assert not [h for h in bpy.app.handlers.depsgraph_update_post if "curved_reflections" in h.__module__]
    registered.register()
    settings = bpy.data.objects["Ball"].curved_reflections  # kept in the file meanwhile
    assert (settings.is_reflector, settings.mode, settings.reflectivity) == (True, 'ITERATIVE', pytest.approx(0.8))
    settings.mode, settings.reflectivity = 'RUNTIME', 1.0
    assert bpy.ops.curved_reflections.start_live() == {'FINISHED'}
    assert differing(settle()[1], before) == 0.0


def _frames_equal_single_renders(scene, tmp_path):
    from curved_reflections.tools import reference_render

    assert bpy.ops.curved_reflections.render_image(filepath=str(tmp_path / "f_#"), animation=True) == {'FINISHED'}
    frames = [reference_render.read_png(tmp_path / f"f_{n}.png") for n in (1, 2, 3)]
    assert differing(frames[0], frames[2], 0.02) > 0.005  # the mirror deformed
    scene.frame_set(2)
    assert bpy.ops.curved_reflections.render_image(filepath=str(tmp_path / "single.png")) == {'FINISHED'}
    np.testing.assert_array_equal(reference_render.read_png(tmp_path / "single.png"), frames[1])
    return frames


def test_a_mirror_deformed_by_shape_keys_renders_its_animation(session, tmp_path):
    ball = _ball()
    ball.shape_key_add(name="Basis")
    stretched = ball.shape_key_add(name="Stretched")
    for point in stretched.data:
        point.co.x *= 1.5
    session.frame_start, session.frame_end = 1, 3
    for frame, value in ((1, 0.0), (3, 1.0)):
        stretched.value = value
        stretched.keyframe_insert("value", frame=frame)
    _frames_equal_single_renders(session, tmp_path)
    session.frame_set(3)  # scrubbing with the live view running
    assert differing(settle()[1], fresh()) == 0.0


def test_a_mirror_deformed_by_an_armature_renders_its_animation(session, tmp_path):
    bpy.ops.object.armature_add(location=(0.0, 0.0, 0.0))
    rig = bpy.context.active_object
    ball = _ball()
    ball.parent = rig
    ball.modifiers.new("Armature", 'ARMATURE').object = rig
    group = ball.vertex_groups.new(name="Bone")
    group.add([v.index for v in ball.data.vertices if v.co.z > 0.0], 1.0, 'REPLACE')
    bone = rig.pose.bones["Bone"]
    session.frame_start, session.frame_end = 1, 3
    for frame, scale in ((1, 1.0), (3, 1.5)):
        bone.scale = (scale, scale, scale)
        bone.keyframe_insert("scale", frame=frame)
    _frames_equal_single_renders(session, tmp_path)
    session.frame_set(3)
    assert differing(settle()[1], fresh()) == 0.0
