# SPDX-License-Identifier: GPL-3.0-or-later
"""The Render Reflections Image operator: a PNG of the render size, in background mode,
and clean error reports (``bpy.ops`` raises ``RuntimeError`` with the message, no
traceback) naming the object at fault."""

from pathlib import Path

import bpy
import numpy as np
import pytest

from curved_reflections.blender import demo_scenes, method_plan
from curved_reflections.blender.frame_pipeline import clip_start_message
from curved_reflections.engine.geometry.band_trace import NO_LIGHT
from curved_reflections.tools import reference_render


@pytest.fixture
def fig3(empty_scene, registered):
    """sbc_fig3 at 80x60 in the context's scene."""
    return demo_scenes.build("sbc_fig3", bpy.context.scene, 80, 60)


def test_writes_a_png_of_the_render_size(fig3, tmp_path, capfd):
    fig3.render.resolution_percentage = 50
    path = tmp_path / "out" / "reflections.png"
    assert bpy.ops.curved_reflections.render_image(filepath=str(path)) == {'FINISHED'}
    image = reference_render.read_png(path)
    assert image.shape == (30, 40, 4)
    assert "Info: Rendered 40x30 with reflections" in capfd.readouterr().out
    # Not blank: the floor's two colours, the world and the columns all show.
    assert len(np.unique(image[..., :3].reshape(-1, 3), axis=0)) >= 6


def test_adds_the_png_extension(fig3, tmp_path):
    assert bpy.ops.curved_reflections.render_image(filepath=str(tmp_path / "frame")) == {'FINISHED'}
    assert (tmp_path / "frame.png").is_file()


@pytest.mark.parametrize("case", ["folder", "trailing_slash", "parent_is_file", "read_only", "unsaved_relative"])
def test_bad_paths_say_what_is_wrong(fig3, tmp_path, capfd, monkeypatch, case):
    import os

    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    locked = tmp_path / "locked"
    locked.mkdir()
    # These machines run as root, who may write anywhere: the folder reads as not writable.
    access = os.access
    monkeypatch.setattr(os, "access", lambda path, mode: Path(path) != locked and access(path, mode))
    path, message = {
        "folder": (str(tmp_path), "is a folder; give a file name in it"),
        "trailing_slash": (str(tmp_path / "new") + "/", "is a folder; give a file name in it"),
        "parent_is_file": (str(blocker / "image.png"), "is a file, not a folder"),
        "read_only": (str(locked / "image.png"), "is not writable"),
        "unsaved_relative": ("//image.png", "the file is not saved yet"),
    }[case]
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.curved_reflections.render_image(filepath=path)
    assert "Traceback" not in capfd.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "locked"] and not any(locked.iterdir())


def test_relative_paths_are_the_blend_files_folder(fig3, tmp_path):
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
    assert bpy.ops.curved_reflections.render_image(filepath="//renders/image") == {'FINISHED'}
    assert (tmp_path / "renders" / "image.png").is_file()


def _error(capfd, tmp_path) -> str:
    with pytest.raises(RuntimeError) as error:
        bpy.ops.curved_reflections.render_image(filepath=str(tmp_path / "never.png"))
    captured = capfd.readouterr()
    assert "Traceback" not in captured.out + captured.err
    assert not (tmp_path / "never.png").exists()
    return str(error.value)


def test_no_camera(fig3, tmp_path, capfd):
    fig3.camera = None
    assert _error(capfd, tmp_path).startswith("Error: 'Scene': has no camera")


def test_camera_that_is_not_a_camera(fig3, tmp_path, capfd):
    fig3.camera = bpy.data.objects["Cube"]
    assert _error(capfd, tmp_path).startswith("Error: 'Cube': is not a camera (it is a mesh object)")


def test_no_reflector(fig3, tmp_path, capfd):
    bpy.data.objects["MirrorSphere"].curved_reflections.is_reflector = False
    assert _error(capfd, tmp_path).startswith("Error: 'Scene': has no visible object marked as a reflector")


def test_reflector_without_faces(fig3, tmp_path, capfd):
    mesh = bpy.data.meshes.new("Points")
    mesh.from_pydata([(0, 0, 3), (1, 0, 3), (0, 1, 3)], [], [])
    points = bpy.data.objects.new("Points", mesh)
    fig3.collection.objects.link(points)
    points.curved_reflections.is_reflector = True
    assert _error(capfd, tmp_path).startswith("Error: 'Points': has no faces")


def test_camera_inside_a_reflector(fig3, tmp_path, capfd):
    fig3.camera.location = (0.0, 0.1, 1.0)  # inside the mirror sphere (centre (0, 0, 1), radius 1)
    message = _error(capfd, tmp_path)
    assert message.startswith("Error: 'MirrorSphere': the view is inside this reflector")


def test_reflector_settings_reach_the_renderer(fig3):
    """``obj.curved_reflections`` Fresnel and fade distance become the renderer's per
    reflector arguments (SBC V-D): F0 where Fresnel is on, NaN where off."""
    from curved_reflections.blender.capture import capture_scene
    from curved_reflections.blender.render_inputs import reflector_appearance, reflector_properties

    reflectors = capture_scene(bpy.context.evaluated_depsgraph_get()).reflectors
    names = [r.name for r in reflectors]
    settings = fig3.objects[names[0]].curved_reflections
    settings.use_fresnel, settings.fresnel_f0, settings.attenuation_distance = True, 0.3, 2.5
    settings.reflectivity = 0.75
    properties = reflector_properties(reflectors, fig3)
    assert properties["fresnel_f0"][0] == pytest.approx(0.3)
    assert properties["attenuation_distance"][0] == pytest.approx(2.5)
    assert properties["reflectivity"][0] == pytest.approx(0.75)
    assert np.isnan(properties["fresnel_f0"][1:]).all() and (properties["attenuation_distance"][1:] == 0).all()
    colors, reflectivity = reflector_appearance(reflectors, fig3)  # the older two-value form
    np.testing.assert_array_equal(reflectivity, properties["reflectivity"])


def test_render_honours_each_reflectors_mode(fig3):
    from curved_reflections.blender.render_image import render_scene

    depsgraph = bpy.context.evaluated_depsgraph_get()
    searched = render_scene(fig3, depsgraph)
    assert searched.stats["methods"] == {"MirrorSphere": "ITERATIVE"}
    assert searched.seconds["sbc"] < 0.05 and "n_rays" not in searched.stats  # no camera built
    assert searched.stats["iterative"]["MirrorSphere"]["found"] > 1000
    bpy.data.objects["MirrorSphere"].curved_reflections.mode = 'RUNTIME'
    camera = render_scene(fig3, depsgraph)
    assert camera.stats["methods"] == {"MirrorSphere": "RUNTIME"} and camera.stats["n_rays"] > 100
    # Both draw the same reflections: the images agree on nearly every pixel.
    differing = np.abs(searched.image[..., :3] - camera.image[..., :3]).max(axis=2) > 0.05
    assert differing.mean() < 0.03



def test_auto_traces_a_torus_and_iterative_mode_searches_it_as_pieces_as_runtime_draws_it(fig3):
    """A closed mirror that is not star-shaped: Render Image's Auto traces it per pixel
    (no camera built), Iterative mode searches it as pieces seen from inside it
    (engine/methods/iterative/pieces.py); both frames equal Runtime's on nearly all of
    the torus's pixels."""
    from curved_reflections.blender.render_image import render_scene

    fig3.render.resolution_x, fig3.render.resolution_y = 96, 72
    bpy.ops.mesh.primitive_torus_add(major_radius=0.8, minor_radius=0.3, major_segments=32, minor_segments=12,
                                     location=(2.2, 2.2, 0.6), rotation=(0.6, 0.0, 0.3))
    bpy.ops.object.shade_smooth()  # a faceted torus is a set of flat mirrors, not searched
    torus = bpy.context.active_object
    torus.name = "Ring"
    torus.curved_reflections.is_reflector = True
    fig3.curved_reflections.max_order = 1
    depsgraph = bpy.context.evaluated_depsgraph_get()
    traced = render_scene(fig3, depsgraph)
    assert traced.stats["methods"] == {"MirrorSphere": "ITERATIVE", "Ring": "TRACED"}, method_plan.last_choices(fig3)
    assert traced.seconds["sbc"] < 0.05  # no camera built
    torus.curved_reflections.mode = 'ITERATIVE'
    searched = render_scene(fig3, depsgraph)
    assert searched.stats["methods"]["Ring"] == "ITERATIVE"
    [ring] = [c for c in method_plan.last_choices(fig3) if c.reflector == "Ring"]
    assert ring.reason.startswith("not star-shaped: ") and "pieces seen from inside it" in ring.reason
    torus.curved_reflections.mode = 'RUNTIME'
    camera = render_scene(fig3, depsgraph)
    assert camera.stats["methods"]["Ring"] == "RUNTIME"
    for image in (traced.image, searched.image):
        differing = np.abs(image[..., :3] - camera.image[..., :3]).max(axis=2) > 0.05
        assert differing.mean() < 0.003  # 0.07 % measured for the pieces


def test_second_orders_of_searched_mirrors_get_a_camera_without_their_first_orders(empty_scene, registered,
                                                                                  monkeypatch):
    """Two facing balls, both searched (Iterative mode), at Max Order 2: the frame's
    camera is made for their images of each other alone, and the frame is the one a
    whole camera gives. Auto traces both instead, every order in one pass, the same
    frame on nearly every pixel (measured: all but 0.16 %)."""
    from curved_reflections.blender import frame_pipeline, render_image

    scene = demo_scenes.build("two_spheres", bpy.context.scene, 96, 64)
    assert scene.curved_reflections.max_order == 2
    depsgraph = bpy.context.evaluated_depsgraph_get()
    traced = render_image.render_scene(scene, depsgraph)
    assert set(traced.stats["methods"].values()) == {"TRACED"} and traced.camera is None
    assert all("would take a sample-based camera every frame" in c.reason for c in method_plan.last_choices(scene))
    for name in traced.stats["methods"]:
        scene.objects[name].curved_reflections.mode = 'ITERATIVE'
    higher = render_image.render_scene(scene, depsgraph)
    assert set(higher.stats["methods"].values()) == {"ITERATIVE"}
    assert (np.abs(traced.image[..., :3] - higher.image[..., :3]).max(axis=2) > 0.05).mean() < 0.01
    assert higher.camera.first_order_left_out == {0, 1}
    assert sorted(map(tuple, higher.camera.groups)) == [(0, 1), (1, 0)]
    build = frame_pipeline.build_sample_based_camera
    monkeypatch.setattr(frame_pipeline, "build_sample_based_camera",
                        lambda *args, first_order_left_out, **kwargs: build(*args, **kwargs))
    whole = render_image.render_scene(scene, depsgraph)
    assert {len(h) for h in whole.camera.groups} == {1, 2}
    assert whole.stats["n_sheets"] > higher.stats["n_sheets"]
    differing = np.abs(whole.image - higher.image).max(axis=2) > 1e-6
    assert differing.sum() == 0
    second = np.abs(whole.image[..., :3] - render_image.render_scene(scene, depsgraph, max_order=1).image[..., :3])
    assert (second.max(axis=2) > 0.05).sum() > 20  # the second orders are in the frame


def test_frame_paths():
    from curved_reflections.blender.render_image import frame_filepath

    assert frame_filepath("/out/shot_###.png", 7) == "/out/shot_007.png"
    assert frame_filepath("/out/a#b_##", 12) == "/out/a#b_12.png"  # the last run of #
    assert frame_filepath("/out/shot_", 7) == "/out/shot_0007.png"
    assert frame_filepath("/out/shot_#", 123) == "/out/shot_123.png"


def _orbit_camera(scene, frames: int) -> None:
    camera = scene.camera
    base = np.array(camera.location)
    scene.frame_start, scene.frame_end = 1, frames
    for frame in range(1, frames + 1):
        angle = np.radians(4.0 * (frame - 1))
        camera.location = (np.cos(angle) * base[0] - np.sin(angle) * base[1],
                           np.sin(angle) * base[0] + np.cos(angle) * base[1], base[2])
        camera.keyframe_insert("location", frame=frame)


def test_animation_writes_one_png_per_frame_equal_to_single_renders(fig3, tmp_path, capfd):
    _orbit_camera(fig3, 3)
    fig3.frame_set(2)
    assert bpy.ops.curved_reflections.render_image(filepath=str(tmp_path / "frames" / "f_###"),
                                                   animation=True) == {'FINISHED'}
    assert fig3.frame_current == 2  # the frame is restored
    written = sorted(p.name for p in (tmp_path / "frames").iterdir())
    assert written == ["f_001.png", "f_002.png", "f_003.png"]
    assert "Info: Rendered 3 frames with reflections" in capfd.readouterr().out
    frames = [reference_render.read_png(tmp_path / "frames" / name) for name in written]
    assert np.abs(frames[0] - frames[2]).max() > 0.1  # the camera moved
    fig3.frame_set(2)
    assert bpy.ops.curved_reflections.render_image(filepath=str(tmp_path / "single.png")) == {'FINISHED'}
    np.testing.assert_array_equal(reference_render.read_png(tmp_path / "single.png"), frames[1])


def test_animation_keeps_the_renderer_while_only_the_camera_moves_and_recaptures_moved_objects(fig3):
    from curved_reflections.blender.render_image import FrameState, render_scene

    _orbit_camera(fig3, 3)
    cube = bpy.data.objects["Cube"]
    cube.keyframe_insert("location", frame=2)
    cube.location.x += 0.3
    cube.keyframe_insert("location", frame=3)
    state = FrameState()
    renderers = []
    for frame in (1, 2, 3):
        fig3.frame_set(frame)
        render_scene(fig3, bpy.context.evaluated_depsgraph_get(), state=state)
        renderers.append(state.renderer)
    assert renderers[0] is renderers[1]  # only the camera moved
    assert renderers[2] is not renderers[1]  # the cube moved: captured and uploaded again
    assert state.frames == 3 and state.reused == 1


def test_a_view_whose_near_plane_cuts_the_mirror_is_filled_not_traced(fig3, tmp_path, capfd):
    """The camera 5 % of a radius from the ball with its clip start inside it. The ball
    holds nothing, so it is sealed (``ReflectorSet.seal_empty_interiors``): its view rays
    start inside it and end there, and the camera has no ray at all. With an object
    inside the ball, they are traced, nearly every mirror pixel has no reflection to
    draw, which is no band along an edge; the composite fills them instead of tracing
    tens of thousands of rays, and the report says so."""
    from curved_reflections.blender.render_image import render_scene

    ball = bpy.data.objects["MirrorSphere"]
    ball.curved_reflections.mode = 'RUNTIME'
    fig3.curved_reflections.max_order = 1
    ordinary = render_scene(fig3, bpy.context.evaluated_depsgraph_get())
    assert ordinary.stats["untraced_pixels"] == 0 < ordinary.stats["traced_pixels"]
    centre, radius = np.array(ball.matrix_world.translation), 0.5 * max(ball.dimensions)
    camera = fig3.camera
    camera.constraints.clear()
    camera.location = centre - (0.0, 1.05 * radius, 0.0)
    camera.rotation_euler = (np.pi / 2, 0.0, 0.0)
    camera.data.clip_start = 0.1 * radius
    fig3.render.resolution_x, fig3.render.resolution_y = 48, 36
    sealed = render_scene(fig3, bpy.context.evaluated_depsgraph_get())
    assert sealed.stats["n_rays"] == 0 and not sealed.stats.get("traced_pixels")
    assert np.all(sealed.image[..., :3] == 0.0)  # all of it the ball's inside: no light, as Cycles shows it
    assert sealed.stats["warnings"] == [clip_start_message("MirrorSphere")] and ordinary.stats["warnings"] == []
    assert bpy.ops.curved_reflections.render_image(filepath=str(tmp_path / "sealed.png")) == {'FINISHED'}
    assert "'MirrorSphere': the camera's clip start cuts into this mirror" in capfd.readouterr().out
    bpy.ops.mesh.primitive_cube_add(size=0.2 * radius, location=centre)  # holds the ball open
    near = render_scene(fig3, bpy.context.evaluated_depsgraph_get())
    assert near.stats["n_rays"] > 0 and near.stats["warnings"] == []  # not sealed: traced
    assert near.stats["traced_pixels"] == 0 and near.stats["untraced_pixels"] > 0.25 * 48 * 36
    assert bpy.ops.curved_reflections.render_image(filepath=str(tmp_path / "near.png")) == {'FINISHED'}
    assert "mirror pixels without a reflection were filled, not ray traced" in capfd.readouterr().out


@pytest.mark.parametrize("mode", ['AUTO', 'RUNTIME'])
def test_where_the_near_plane_cuts_the_sealed_ball_its_inside_shows_as_traced(fig3, mode):
    """The scene camera with its clip start half a radius short of the ball's centre: a
    disc of the ball's front is cut away, and there every view ray starts inside the
    ball, which holds nothing (sealed). Such a ray bounces inside without end and meets no
    light: the exact trace from the near plane (``band_trace.BandTracer``) says black
    there, as Cycles renders it, and the mirror's pixels show what the trace shows, in
    both modes (before, the iterative search drew the cut-away front's reflections there,
    the camera the world)."""
    from curved_reflections.blender.render_image import FrameState, render_scene
    from curved_reflections.engine.geometry.band_trace import BandTracer
    from curved_reflections.engine.srgb import linear_to_srgb
    from curved_reflections.tools import metrics

    from test_live import clip_half_a_radius_short_of_the_centre

    clip_half_a_radius_short_of_the_centre(fig3, mode)
    state = FrameState()
    result = render_scene(fig3, bpy.context.evaluated_depsgraph_get(), state=state)
    assert result.stats["warnings"] == [clip_start_message("MirrorSphere")]
    assert result.stats["methods"] == {"MirrorSphere": 'ITERATIVE' if mode == 'AUTO' else 'RUNTIME'}
    view, (height, width) = result.view, result.image.shape[:2]
    ys, xs = np.mgrid[0:height, 0:width]
    pixels = np.c_[xs.ravel(), ys.ravel()] + 0.5
    tracer = BandTracer(state.captured.reflectors, state.captured.meshes, state.reflector_set)
    hits = tracer.intersect(*view.pixel_rays(pixels))
    mirror = (hits.hit & (hits.reflector < tracer.n_reflectors)).reshape(height, width)
    exact = tracer.trace(view, pixels, fig3.curved_reflections.max_order, state.world).reshape(height, width, 4)
    inside = mirror & np.all(exact == NO_LIGHT, axis=2)
    assert mirror.sum() > 500 and inside.sum() > 0.6 * mirror.sum()
    palette = {**demo_scenes.palette(fig3), "(no light)": (0.0, 0.0, 0.0)}
    ours = metrics.label_image(linear_to_srgb(result.image[..., :3]), palette)
    truth = metrics.label_image(linear_to_srgb(exact[..., :3]), palette)
    assert np.all(result.image[inside][:, :3] == 0.0)
    assert metrics.share_differing(ours, truth, mirror) <= 0.02


def _lift_off_the_floor() -> None:
    """sbc_fig3 with nothing touching its ball: the ball 0.3 above the floor, the cube
    moved 0.6 away from it."""
    bpy.data.objects["MirrorSphere"].location.z += 0.3
    bpy.data.objects["Cube"].location.x += 0.6


def test_perturbation_mode_draws_what_the_camera_draws(fig3):
    """Perturbation (Chen & Arvo 2000) on the mesh and on the declared exact sphere: each
    image agrees with the Runtime camera's on nearly every pixel, and the plan says why.
    The ball is lifted off the floor and the cube moved off the ball: Perturbation leaves
    out images of what almost touches the mirror, and Render Image's check then draws the
    ball in Runtime mode (test_frame_pipeline.py)."""
    from curved_reflections.blender.render_image import render_scene

    _lift_off_the_floor()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    settings = bpy.data.objects["MirrorSphere"].curved_reflections
    settings.mode = 'RUNTIME'
    camera = render_scene(fig3, depsgraph)
    settings.mode = 'PERTURBATION'
    on_mesh = render_scene(fig3, depsgraph)
    assert on_mesh.stats["methods"] == {"MirrorSphere": "PERTURBATION"}, method_plan.last_choices(fig3)
    assert on_mesh.seconds["sbc"] < 0.05 and "n_rays" not in on_mesh.stats  # no camera built
    settings.analytic_shape = 'SPHERE'  # the demo's mirror: radius 1 around its origin
    exact = render_scene(fig3, depsgraph)
    reason = method_plan.last_choices(fig3)[0].reason
    assert "exact sphere" in reason and "mesh within" in reason
    for image in (on_mesh.image, exact.image):
        differing = np.abs(image[..., :3] - camera.image[..., :3]).max(axis=2) > 0.05
        assert differing.mean() < 0.03
    settings.analytic_radii = (1.5, 1.5, 1.5)  # no longer the mesh's sphere: the mesh reflects, and the panel says so
    render_scene(fig3, depsgraph)
    reason = method_plan.last_choices(fig3)[0].reason
    assert "from the declared sphere" in reason and "Perturbation on the mesh" in reason


def test_a_frame_is_drawn_again_when_auto_passes_a_method_over(fig3, monkeypatch):
    """Render Image checks the per-frame methods in the frame it drew (``FramePipeline.check_methods``,
    tested in test_frame_pipeline.py); when the check passed a method over, the frame is
    drawn again, and checked again. An animation checks its first frame, then every
    CHECK_EVERY_FRAMES frames."""
    from curved_reflections.blender import render_image
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    checks, renders = [], []
    check, render = render_image.FrameState.check_methods, ReflectionRenderer.render
    monkeypatch.setattr(render_image.FrameState, "check_methods",
                        lambda self, scene, view, image: checks.append(check(self, scene, view, image)) or
                        len(checks) == 1)
    monkeypatch.setattr(ReflectionRenderer, "render", lambda self, *a, **k: renders.append(1) or render(self, *a, **k))
    state = render_image.FrameState()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    render_image.render_scene(fig3, depsgraph, state=state)
    assert checks == [False, False] and len(renders) == 2  # the first frame and its redraw, each checked
    for _ in range(render_image.CHECK_EVERY_FRAMES):
        render_image.render_scene(fig3, depsgraph, state=state)
    assert len(checks) == 3 and len(renders) == 2 + render_image.CHECK_EVERY_FRAMES
