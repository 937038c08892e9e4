# SPDX-License-Identifier: GPL-3.0-or-later
"""Bake / clear morphing grids through bpy.ops, and the state drawing code then finds.

Background mode runs the operator's ``execute`` (a synchronous bake on worker
processes). Every outcome leaves a drawable state: a grid, or None (runtime mode)
with the reason in ``morph_status``.
"""

import bpy
import numpy as np
import pytest

from curved_reflections.blender import scene_status
from curved_reflections.blender.scene_status import status_of


@pytest.fixture
def morph_ops(registered, monkeypatch, tmp_path):
    from curved_reflections.blender import morph_bake

    # A fast bake (16 texels, as test_bad_input and test_working_session_files bake); the
    # figures are the benchmark's.
    monkeypatch.setattr(morph_bake, "FACE_RESOLUTION", 16)
    monkeypatch.setattr(morph_bake, "cache_root", lambda scene: tmp_path / "morphing")  # no test sees another's

    added = [cls for cls in morph_bake.classes if not cls.is_registered]
    for cls in added:
        bpy.utils.register_class(cls)
    scene_status.forget_all()
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


def _render_camera(scene):
    """First order only, and a 64x48 scene camera inside the ball's grid, looking at it."""
    scene.curved_reflections.max_order = 1
    bpy.ops.object.camera_add(location=(0.9, -1.5, 1.4))
    camera = bpy.context.active_object
    camera.rotation_euler = (np.radians(70.0), 0.0, np.radians(15.0))
    scene.camera = camera
    scene.render.resolution_x, scene.render.resolution_y = 64, 48


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
    assert morph_ops.morph_status(empty_scene).count("baked 8 nodes") == 1  # said once, not also as the summary
    grid = morph_ops.load_morphing(reflector, matrix, empty_scene)
    assert grid is not None and grid.grid.shape == (2, 2, 2)
    assert "Ball: morphing (baked grid loaded)" in morph_ops.morph_status(empty_scene)
    # Polish Node Images (on by default) gives the loaded grid the mirror its nodes were built from.
    assert len(grid.mirror().triangles) == len(reflector.triangles)  # a closed ball: no strip added
    empty_scene.curved_reflections.morph_polish_nodes = False
    assert morph_ops.load_morphing(reflector, matrix, empty_scene).mirror is None
    empty_scene.curved_reflections.morph_polish_nodes = True
    from curved_reflections.engine import look_at_view
    from curved_reflections.engine.methods.morphing.morphing import ViewOutsideGrid

    with pytest.raises(ViewOutsideGrid) as outside:
        grid.project(np.zeros((1, 3)), look_at_view([0.0, -20.0, 1.0], [0.5, 0.0, 1.0]), matrix=matrix)
    morph_ops.note_runtime_fallback(status_of(empty_scene), outside.value)
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
    assert not any(morph_ops.cache_directory(empty_scene).iterdir())


def test_a_renamed_mirror_keeps_its_grid_and_an_undone_rename_too(empty_scene, morph_ops):
    ball = _mirror_scene(empty_scene)
    assert bpy.ops.curved_reflections.bake_morphing(processes=1) == {'FINISHED'}
    files = {p.name: p.stat().st_mtime_ns for p in morph_ops.cache_directory(empty_scene).rglob("node_*")}
    for name in ("Kettle", "Ball"):  # renamed, then the rename undone
        ball.name = name
        bpy.context.view_layer.update()
        reflector, matrix = _captured(bpy.context, morph_ops)
        assert morph_ops.load_morphing(reflector, matrix, empty_scene) is not None
        assert f"{name}: morphing (baked grid loaded)" in morph_ops.morph_status(empty_scene)
        (folder,) = morph_ops.cache_directory(empty_scene).iterdir()
        assert folder.name.startswith(f"{name}-")
        assert {p.name: p.stat().st_mtime_ns for p in folder.glob("node_*")} == files
    ball.name = "Kettle"
    assert bpy.ops.curved_reflections.bake_morphing(processes=1) == {'FINISHED'}
    assert "Kettle: baked 0 nodes" in morph_ops.morph_status(empty_scene)
    assert "8 were baked already" in morph_ops.morph_status(empty_scene)


def test_bake_without_a_morphing_reflector_reports_an_error(empty_scene, morph_ops):
    _mirror_scene(empty_scene, mode='RUNTIME')
    with pytest.raises(RuntimeError, match="No visible reflector is in Morphing or Octree mode"):
        bpy.ops.curved_reflections.bake_morphing()
    assert not status_of(empty_scene).bake.get("running")


def test_classes_tuple_and_status_while_running(morph_ops, empty_scene):
    assert [cls.bl_idname for cls in morph_ops.classes] == ["curved_reflections.bake_morphing",
                                                            "curved_reflections.clear_morphing"]
    status_of(empty_scene).bake = {"running": True, "done": 3, "total": 405, "reflector": "Ball",
                                   "message": ""}
    assert morph_ops.morph_status(empty_scene) == "Baking Ball: 3/405 nodes (Esc cancels)"
    assert not bpy.ops.curved_reflections.bake_morphing.poll()
    status_of(empty_scene).bake = {}
    assert np.prod(tuple(empty_scene.curved_reflections.morph_grid)) == 405


def _baked_node_files(morph_ops, scene):
    return sorted(p.name for p in morph_ops.cache_directory(scene).rglob("node_*"))


def test_two_files_with_one_object_name_keep_their_own_grids(empty_scene, morph_ops, tmp_path):
    """A.blend and B.blend both have a "Ball": each file's grids live in its own folder,
    a bake or Clear in one never touches the other's; Save As takes the grids along."""
    ball = _mirror_scene(empty_scene)
    first, second = tmp_path / "A.blend", tmp_path / "B.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(first))
    assert bpy.ops.curved_reflections.bake_morphing(processes=1) == {'FINISHED'}
    a_folder = morph_ops.cache_directory(bpy.context.scene)
    assert a_folder.name.startswith("A-") and len(_baked_node_files(morph_ops, bpy.context.scene)) == 8

    bpy.ops.wm.save_as_mainfile(filepath=str(second))  # the copy has the grid too
    scene = bpy.context.scene
    b_folder = morph_ops.cache_directory(scene)
    assert b_folder != a_folder and b_folder.name.startswith("B-")
    reflector, matrix = _captured(bpy.context, morph_ops)
    assert morph_ops.load_morphing(reflector, matrix, scene) is not None
    ball = bpy.data.objects["Ball"]
    ball.scale = (1.3, 1.0, 1.0)  # B's Ball changes: its new bake replaces only B's grid
    bpy.context.view_layer.update()
    assert bpy.ops.curved_reflections.bake_morphing(processes=1) == {'FINISHED'}
    assert bpy.ops.curved_reflections.clear_morphing() == {'FINISHED'}
    assert not list(b_folder.iterdir())

    bpy.ops.wm.open_mainfile(filepath=str(first))
    scene = bpy.context.scene
    assert morph_ops.cache_directory(scene) == a_folder
    reflector, matrix = _captured(bpy.context, morph_ops)
    assert morph_ops.load_morphing(reflector, matrix, scene) is not None  # A's grid survived


def test_a_range_of_nodes_bakes_only_those_and_reports_what_is_left(empty_scene, morph_ops):
    _mirror_scene(empty_scene)
    assert bpy.ops.curved_reflections.bake_morphing(processes=1, object_name="Ball", nodes="0-2") == {'FINISHED'}
    assert len(_baked_node_files(morph_ops, empty_scene)) == 3
    assert "3 of 8 nodes baked, the other ranges still to bake" in morph_ops.morph_status(empty_scene)
    reflector, matrix = _captured(bpy.context, morph_ops)
    assert morph_ops.load_morphing(reflector, matrix, empty_scene) is None
    assert "the morphing cache has 3 of 8 nodes" in morph_ops.morph_status(empty_scene)
    assert bpy.ops.curved_reflections.bake_morphing(processes=1, nodes="3-") == {'FINISHED'}
    assert "baked 5 nodes" in morph_ops.morph_status(empty_scene)
    assert morph_ops.load_morphing(reflector, matrix, empty_scene) is not None
    for bad, message in (("5-2", "nodes 0 to 7"), ("x", "write first-last")):
        with pytest.raises(RuntimeError, match=message):
            bpy.ops.curved_reflections.bake_morphing(nodes=bad)
    with pytest.raises(RuntimeError, match="'Cube': not a visible reflector in Morphing or Octree mode"):
        bpy.ops.curved_reflections.bake_morphing(object_name="Cube")


def test_a_damaged_node_costs_only_its_reflector_and_a_bake_repairs_it(empty_scene, morph_ops, gpu_ready):
    """The live view: a damaged node file met while drawing turns its reflector to runtime
    mode with a line naming the file; another reflector keeps drawing; Bake repairs it."""
    from curved_reflections.engine.baking import bake_cache
    from curved_reflections.engine import look_at_view
    from curved_reflections.blender import live

    from test_live import _draw, _touched

    _mirror_scene(empty_scene)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.6, location=(-2.2, 0.5, 1.0), segments=24, ring_count=12)
    other = bpy.context.active_object
    other.name = "Other"
    other.curved_reflections.is_reflector = True
    other.curved_reflections.mode = 'ITERATIVE'
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(0.5, -2.0, 1.0))
    empty_scene.curved_reflections.max_order = 1
    assert bpy.ops.curved_reflections.bake_morphing(processes=1) == {'FINISHED'}
    view = look_at_view([0.9, -1.6, 1.3], [0.0, 0.0, 1.0], fov_y_deg=70.0, width=96, height=72)
    state = live.start(empty_scene, bpy.context.evaluated_depsgraph_get(), views={"v": view}, wait=True)
    assert [grid.reflector_name for grid, _ in state.grids] == ["Ball"]
    drawn, before = _draw(empty_scene, view, "v")
    assert drawn and state.renderer.pass_named("morphing").counts["blends"] == 1

    for _, future in state.renderer.pass_named("morphing")._pending.values():
        future.result(timeout=120)  # the prefetch started by the draw reads node files too
    directory = next(morph_ops.cache_directory(empty_scene).glob("Ball-*"))
    damaged_file = sorted(directory.glob("node_*.npz"))[0]  # one node of the eye's cell (all 8 are read)
    damaged_file.write_bytes(b"damaged")
    state = live.refresh(empty_scene, bpy.context.evaluated_depsgraph_get(), views={"v": view}, wait=True)
    drawn, after = _draw(empty_scene, view, "v")  # the fault is met here, the others draw on
    assert drawn and state.drawing
    grid = state.grids[0][0]
    assert grid.failure is not None and ".npz is unreadable" in str(grid.failure)
    line = dict(morph_ops.reflector_modes(empty_scene))["Ball"]
    assert line.startswith("runtime mode: the morphing cache file node_") and "Bake Morphing Grid" in line
    live.process(empty_scene, bpy.context.evaluated_depsgraph_get(), wait=True)  # the camera it asked for
    drawn, runtime = _draw(empty_scene, view, "v")
    assert drawn and state.cameras["v"].sbc is not None
    assert _touched(runtime).sum() > 0.8 * _touched(before).sum()

    assert damaged_file.name in line or damaged_file.name in str(grid.failure)
    assert bpy.ops.curved_reflections.bake_morphing(processes=1) == {'FINISHED'}
    assert "Ball: baked 1 nodes" in morph_ops.morph_status(empty_scene)  # the damaged one alone
    assert bake_cache.baked_nodes(directory, 8)[0].all()
    state = live.refresh(empty_scene, bpy.context.evaluated_depsgraph_get(), views={"v": view}, wait=True)
    drawn, repaired = _draw(empty_scene, view, "v")
    assert drawn and state.grids[0][0].failure is None and state.renderer.pass_named("morphing").counts["blends"] == 1


def test_a_reshaped_mirror_is_baked_afresh_and_drawn_from_its_new_shape(empty_scene, morph_ops, gpu_ready,
                                                                        monkeypatch):
    """Bake a ball, move its vertices into an ellipsoid (same topology, same object
    transform) and bake again: every node is built anew, the report says why, and Render
    Image draws what a cache baked afresh for the ellipsoid draws, with Polish Node Images
    and Polish Every Frame off (where nothing corrects a stale node) and on."""
    from curved_reflections.blender.frame_pipeline import FramePipeline
    from curved_reflections.blender.render_image import render_scene

    # What the cache serves is under test, not the accuracy of this 2x2x2, 16-texel grid:
    # the accuracy check would pass the mirror on to the trace.
    monkeypatch.setattr(FramePipeline, "check_methods", lambda self, scene, view, image=None: False)

    ball = _mirror_scene(empty_scene)
    _render_camera(empty_scene)
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(-0.3, -1.6, 0.6))
    settings = empty_scene.curved_reflections

    def render(polish: bool):
        settings.morph_polish_nodes = settings.morph_polish_frames = polish
        result = render_scene(empty_scene, bpy.context.evaluated_depsgraph_get())
        assert result.stats["methods"] == {"Ball": "MORPHING"}, status_of(empty_scene).choices
        return result.image

    assert bpy.ops.curved_reflections.bake_morphing(processes=1) == {'FINISHED'}
    of_the_ball = render(False)
    co = np.empty(3 * len(ball.data.vertices))
    ball.data.vertices.foreach_get("co", co)
    ball.data.vertices.foreach_set("co", co * np.tile([1.0, 0.75, 1.3], len(ball.data.vertices)))
    ball.data.update()
    assert bpy.ops.curved_reflections.bake_morphing(processes=1) == {'FINISHED'}
    line = morph_ops.morph_status(empty_scene)
    assert "Ball: baked 8 nodes" in line
    assert "shape or its grid settings changed since its last bake, so no node was reused" in line
    assert len([p for p in morph_ops.cache_directory(empty_scene).iterdir() if p.is_dir()]) == 1
    reshaped = [render(polish) for polish in (False, True)]
    assert bpy.ops.curved_reflections.clear_morphing() == {'FINISHED'}
    assert bpy.ops.curved_reflections.bake_morphing(processes=1) == {'FINISHED'}
    assert "changed since" not in morph_ops.morph_status(empty_scene)
    for polish, image in zip((False, True), reshaped):
        assert np.array_equal(image, render(polish)), polish
    assert np.mean(np.any(reshaped[0] != of_the_ball, axis=-1)) > 0.01  # the ellipsoid shows the cube elsewhere


def test_render_image_in_morphing_mode_bakes_a_missing_grid_first(empty_scene, morph_ops, gpu_ready, capfd):
    """No grid yet: Render Image bakes it (every node) and draws the mirror from it; the
    next render finds it and bakes nothing."""
    from curved_reflections.blender.render_image import render_scene

    _mirror_scene(empty_scene)
    _render_camera(empty_scene)
    assert _baked_node_files(morph_ops, empty_scene) == []
    result = render_scene(empty_scene, bpy.context.evaluated_depsgraph_get())
    assert len(_baked_node_files(morph_ops, empty_scene)) == 8
    assert "baking the morphing grid of 'Ball' first: none baked yet" in capfd.readouterr().out
    assert result.stats["methods"] == {"Ball": "MORPHING"} and "n_rays" not in result.stats
    files = {p: p.stat().st_mtime_ns for p in morph_ops.cache_directory(empty_scene).rglob("node_*")}
    render_scene(empty_scene, bpy.context.evaluated_depsgraph_get())
    assert {p: p.stat().st_mtime_ns for p in morph_ops.cache_directory(empty_scene).rglob("node_*")} == files


def test_render_image_in_octree_mode_bakes_ray_octrees_first(empty_scene, morph_ops, gpu_ready, capfd):
    """Octree mode (Martin & Popescu 2004): Render Image bakes the grid of ray octrees
    (the manifest says so) and draws the mirror from it, with no camera per view. Set
    back to Morphing, the next bake replaces it with the tetrahedral grid."""
    from curved_reflections.engine.baking import bake_cache
    from curved_reflections.blender.render_image import render_scene

    ball = _mirror_scene(empty_scene, mode='OCTREE')
    _render_camera(empty_scene)
    result = render_scene(empty_scene, bpy.context.evaluated_depsgraph_get())
    assert "baking the morphing grid of 'Ball' first: none baked yet" in capfd.readouterr().out
    assert result.stats["methods"] == {"Ball": "OCTREE"} and "n_rays" not in result.stats
    (manifest,) = morph_ops.cache_directory(empty_scene).rglob(bake_cache.MANIFEST)
    with np.load(manifest, allow_pickle=False) as data:
        assert str(data["kind"]) == "octree"
    assert len(_baked_node_files(morph_ops, empty_scene)) == 8
    ball.curved_reflections.mode = 'MORPHING'
    assert bpy.ops.curved_reflections.bake_morphing(processes=1) == {'FINISHED'}
    (manifest,) = morph_ops.cache_directory(empty_scene).rglob(bake_cache.MANIFEST)
    with np.load(manifest, allow_pickle=False) as data:
        assert str(data["kind"]) == "tetrahedral"
