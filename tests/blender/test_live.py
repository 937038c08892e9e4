# SPDX-License-Identifier: GPL-3.0-or-later
"""Live reflections (blender/live.py, blender/bake.py), driven headlessly.

Background mode has no 3D view, so the draw code runs as the POST_VIEW handler would:
into a bound ``GPUOffScreen`` with the explicit view of the scene camera. The scene is
sbc_fig3 (mirror ball, columns, a cube almost touching the ball): the cube's flat
colour on the mirror is its reflection. ``depsgraph_update_post`` does fire in the bpy
module in background mode (after ``view_layer.update()``), so the auto-refresh tests
go through the real handler; timers never run there, so the debounced view rebuild is
driven by calling the timer's body (``live.process``) with explicit times.
"""

import os
import sys
import threading
import time

import bpy
import numpy as np
import pytest

from curved_reflections.engine.view import look_at_view
from curved_reflections.blender import demo_scenes, live, live_handlers, live_workers, scene_changes
from curved_reflections.blender.capture import view_from_camera

#: Clear colour of the offscreen: in no demo palette, so untouched pixels are known.
SENTINEL = (0.5, 0.25, 0.125, 1.0)
WIDTH, HEIGHT = 128, 96


@pytest.fixture
def fig3(empty_scene, registered, gpu_ready):
    """sbc_fig3 with its mirror in Runtime mode: these tests are of the camera per view
    (its worker, debounce and caches); Auto mode is tested in test_live_iterative.py."""
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, WIDTH, HEIGHT)
    bpy.data.objects["MirrorSphere"].curved_reflections.mode = 'RUNTIME'
    return scene


def _camera_view(scene):
    return view_from_camera(scene.camera, scene, bpy.context.evaluated_depsgraph_get())


def _draw(scene, view, key=live.CAMERA_KEY):
    """(drawn, image): what the draw handler draws over a SENTINEL-cleared framebuffer
    whose depth is cleared too (a scene of nothing but the far plane: the overlay is
    depth-tested against the scene's depth Blender leaves there)."""
    import gpu

    offscreen = gpu.types.GPUOffScreen(view.width, view.height, format='RGBA32F')
    try:
        with offscreen.bind():
            framebuffer = gpu.state.active_framebuffer_get()
            framebuffer.clear(color=SENTINEL, depth=1.0)
            drawn = live.draw_safely(scene, key, view)
            pixels = framebuffer.read_color(0, 0, view.width, view.height, 4, 0, 'FLOAT')
    finally:
        offscreen.free()
    pixels.dimensions = view.width * view.height * 4
    return drawn, np.array(pixels, dtype=np.float32).reshape(view.height, view.width, 4)


def _pixels_of(image, name, scene):
    colour = np.array(demo_scenes.palette(scene)[name])
    return np.argwhere(np.abs(image[..., :3] - colour).max(axis=2) < 0.02)


def _touched(image):
    return np.abs(image - SENTINEL).max(axis=2) > 1e-4


def test_bake_fills_stats_and_draws_the_cubes_reflection_on_the_mirror(fig3, capfd):
    assert bpy.ops.curved_reflections.start_live() == {'FINISHED'}
    assert "Info: Started reflections:" in capfd.readouterr().out
    state = live.state_of(fig3)
    assert list(state.cameras) == [live.CAMERA_KEY]
    assert state.stats["rays"] > 100 and state.stats["leaves"] > 10
    assert state.stats["build_ms"] > 0 and state.stats["memory_mb"] > 0
    assert (state.level, state.status) == ('INFO', "Reflections up to date")

    drawn, image = _draw(fig3, _camera_view(fig3))
    assert drawn and state.stats["draw_ms"] > 0
    touched = _touched(image)
    # Only the mirror ball is drawn over (reflectors only): a disc of ~1800 of 12288 px.
    assert 1000 < touched.sum() < 3000
    cube = _pixels_of(image, "Cube", fig3)
    assert len(cube) >= 15
    assert touched[cube[:, 0], cube[:, 1]].all()
    # The reflection is of the scene: the floor and several columns show as well.
    assert len(_pixels_of(image, "FloorA", fig3)) > 100
    assert sum(len(_pixels_of(image, f"Column{k}", fig3)) > 0 for k in range(1, 8)) >= 3


def test_refresh_rebuilds_and_clear_stops_drawing(fig3, capfd):
    assert bpy.ops.curved_reflections.refresh() == {'CANCELLED'}
    assert "Warning: Nothing to refresh: Start first" in capfd.readouterr().out
    bpy.ops.curved_reflections.start_live()
    state = live.state_of(fig3)
    assert bpy.ops.curved_reflections.refresh() == {'FINISHED'}
    assert "Info: Refreshed reflections:" in capfd.readouterr().out
    assert (state.counts["captures"], state.counts["builds"]) == (2, 2)
    assert _draw(fig3, _camera_view(fig3))[0]

    assert bpy.ops.curved_reflections.clear() == {'FINISHED'}
    assert live.state_of(fig3) is None
    drawn, image = _draw(fig3, _camera_view(fig3))
    assert not drawn and not _touched(image).any()


def test_moving_a_diffuse_object_moves_its_reflection_without_rebaking(fig3):
    bpy.ops.curved_reflections.start_live()
    state = live.state_of(fig3)
    view = _camera_view(fig3)
    before = _pixels_of(_draw(fig3, view)[1], "Cube", fig3).mean(axis=0)
    camera = state.cameras[live.CAMERA_KEY]
    ball = state.captured.reflectors[0]

    bpy.data.objects["Cube"].location.x -= 0.25  # along the ball, toward the left
    bpy.context.view_layer.update()  # depsgraph_update_post fires in background mode
    assert state.captured.reflectors[0] is ball  # not read again
    # (Background mode processes the change at once: the drawn view's accuracy is checked too.)
    assert state.counts == {"captures": 1, "remeshes": 1, "builds": 1, "draws": 1, "projections": 1, "checks": 1}
    assert state.cameras[live.CAMERA_KEY] is camera  # a mesh change re-projects: same camera
    after = _pixels_of(_draw(fig3, view)[1], "Cube", fig3).mean(axis=0)
    assert state.counts["projections"] == 2  # once, on the first draw after the change
    # A mirror ball reflects a move to the left as a (smaller) move to the left.
    assert after[1] < before[1] - 1.0


def test_redraws_without_changes_run_no_projection(fig3):
    """The projection is cached by the renderer (reflected triangles at their world
    reflector points): redraws of the same camera, from its view or a moved one, only
    draw; the renderer is built with the reflectors' Fresnel and fade settings."""
    mirror = bpy.data.objects["MirrorSphere"].curved_reflections
    mirror.use_fresnel, mirror.fresnel_f0, mirror.attenuation_distance = True, 0.2, 3.0
    bpy.ops.curved_reflections.start_live()
    state = live.state_of(fig3)
    view = _camera_view(fig3)
    for _ in range(3):
        assert _draw(fig3, view)[0]
    moved = look_at_view((0.8, -6.4, 2.4), (0.0, 0.0, 0.9), fov_y_deg=30.0, width=WIDTH, height=HEIGHT)
    assert _draw(fig3, moved)[0]
    assert (state.counts["draws"], state.counts["projections"]) == (4, 1)
    assert state.renderer.counts == {"projections": 1, "frames": 4}
    assert state.stats["projection_ms"] > 0
    labels = state.renderer.geometry.prepass_arrays()["labels"]
    on_mirror = labels[:, 0] == 1.0
    np.testing.assert_allclose(labels[on_mirror][:, 2:], [[0.2, 3.0]] * int(on_mirror.sum()), atol=1e-6)


def test_editing_a_reflector_rebakes(fig3):
    bpy.ops.curved_reflections.start_live()
    state = live.state_of(fig3)
    mirror = bpy.data.objects["MirrorSphere"]
    mirror.location.x += 0.2
    bpy.context.view_layer.update()
    assert (state.counts["captures"], state.counts["builds"]) == (2, 2)
    assert state.captured.reflectors[0].vertices[:, 0].max() == pytest.approx(1.2, abs=1e-3)

    # Geometry (a modifier) and marking another reflector re-bake too.
    mirror.modifiers.new("Wave", 'CAST').factor = 0.3
    bpy.context.view_layer.update()
    assert state.counts["captures"] == 3
    bpy.data.objects["Column1"].curved_reflections.is_reflector = True  # seen by its update callback
    assert state.counts["captures"] >= 4
    assert sorted(r.name for r in state.captured.reflectors) == ["Column1", "MirrorSphere"]
    assert _draw(fig3, _camera_view(fig3))[0]

    # Without Auto Refresh edits wait for Refresh.
    fig3.curved_reflections.auto_refresh = False
    bakes = state.counts["captures"]
    mirror.location.x -= 0.2
    bpy.context.view_layer.update()
    assert state.counts["captures"] == bakes


def test_a_view_change_is_debounced_built_on_the_worker_and_the_old_camera_draws_meanwhile(fig3):
    bpy.ops.curved_reflections.start_live()
    state = live.state_of(fig3)
    old = state.cameras[live.CAMERA_KEY]
    moved = look_at_view((0.8, -6.4, 2.4), (0.0, 0.0, 0.9), fov_y_deg=30.0, width=WIDTH, height=HEIGHT)

    drawn, image = _draw(fig3, moved)
    assert drawn  # the previous camera, until the new one is ready
    assert state.counts["projections"] == 1
    view, asked = state.requests[live.CAMERA_KEY]
    assert view is moved and not state.jobs
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert live.process(fig3, depsgraph, now=asked + 0.5 * live.DEBOUNCE_SECONDS)  # too early: waits
    assert not state.jobs
    assert live.process(fig3, depsgraph, now=asked + live.DEBOUNCE_SECONDS + 1e-3)  # now on the worker
    future = state.jobs[live.CAMERA_KEY].future
    future.result(timeout=60)
    # Collected; and the view drawn meanwhile, settled, is checked (engine/spot_check.py) on
    # a worker: pending until the check lands, then nothing.
    assert live.process(fig3, depsgraph, now=time.monotonic() + 1.0) and state.checking is not None
    state.checking[0].result(timeout=60)
    assert not live.process(fig3, depsgraph, now=time.monotonic() + 1.0)
    new = state.cameras[live.CAMERA_KEY]
    assert new is not old and new.view is moved and state.counts["builds"] == 2
    assert _draw(fig3, moved)[0]
    assert state.counts["projections"] == 2  # the new camera projects once
    assert live.CAMERA_KEY not in state.requests  # the same view asks for nothing


def test_a_landing_camera_brings_its_reflected_triangles_and_its_first_draw_only_uploads_them(fig3, monkeypatch):
    """The worker projects the meshes with the new camera (numpy) right after building
    it: the first draw with it runs no projection pass on the GPU. After a mesh change
    (a new renderer) the worker's triangles no longer fit, and the draw projects on the GPU."""
    from curved_reflections.drawing.methods.camera_source import CameraSource
    from curved_reflections.drawing.methods.sbc_gpu import SBCTextures
    from curved_reflections.drawing.methods.sbc_triangles import CameraTriangleMaker

    bpy.ops.curved_reflections.start_live()
    state = live.state_of(fig3)
    moved = look_at_view((0.8, -6.4, 2.4), (0.0, 0.0, 0.9), fov_y_deg=30.0, width=WIDTH, height=HEIGHT)
    live._start_camera(state, live.CAMERA_KEY, moved, wait=False)
    state.jobs[live.CAMERA_KEY].future.result(timeout=60)
    live._collect(state)
    camera = state.cameras[live.CAMERA_KEY]
    assert camera.projected is not None and camera.projected[1].batch is None  # arrays, not yet on the GPU
    projections = state.counts["projections"]

    def no_gpu_pass(*args, **kwargs):
        raise AssertionError("a projection pass on the main thread")

    with monkeypatch.context() as patch:
        patch.setattr(CameraTriangleMaker, "project_pass", no_gpu_pass)
        drawn, image = _draw(fig3, moved)
    assert drawn and len(_pixels_of(image, "Cube", fig3)) > 0
    assert isinstance(camera.source, CameraSource) and state.counts["projections"] == projections + 1

    bpy.data.objects["Cube"].location.x -= 0.25  # a new renderer: the GPU projects again, once
    bpy.context.view_layer.update()
    assert _draw(fig3, moved)[0] and isinstance(camera.source, SBCTextures)
    assert state.counts["projections"] == projections + 2


def test_a_resting_views_unreliable_cells_are_traced_on_a_worker_and_drawn_over_its_camera(fig3, monkeypatch):
    """Once a camera's own view is drawn, the pixels of the cells where it marks its
    projection unreliable are traced on a worker (traced_pixels.trace_doubtful); the
    timer redraws when they land, and they are drawn over the camera's reflections in
    that view only. Here every cell is unreliable and the tracer sees magenta."""
    from curved_reflections.engine.geometry import band_trace
    from curved_reflections.drawing import reflection_draw

    magenta = np.array([1.0, 0.0, 1.0])

    def every_cell(ray_map, *args, **kwargs):
        return np.ones((ray_map.rows, ray_map.columns), dtype=bool)

    def traced(self, view, pixels, *args, **kwargs):
        return np.concatenate([np.tile(magenta, (len(pixels), 1)), np.ones((len(pixels), 1))], axis=1)

    monkeypatch.setattr(band_trace, "unreliable_cells", every_cell)
    monkeypatch.setattr(band_trace.BandTracer, "trace", traced)
    monkeypatch.setattr(reflection_draw, "MAX_TRACED_FRACTION", 1.0)
    bpy.ops.curved_reflections.start_live()
    state = live.state_of(fig3)
    camera = state.cameras[live.CAMERA_KEY]

    def shown(image):
        return int((np.abs(image[..., :3] - magenta).max(axis=2) < 1e-3).sum())

    drawn, image = _draw(fig3, camera.view)  # the camera's answers; the trace starts
    assert drawn and shown(image) == 0 and len(_pixels_of(image, "Cube", fig3)) > 0
    traced_pixels = camera.tracing.future.result(timeout=60)
    assert 500 < len(traced_pixels.pixels) < 0.5 * camera.view.width * camera.view.height  # the mirror's
    live.process(fig3, bpy.context.evaluated_depsgraph_get())  # collects the landing (a redraw)
    assert camera.tracing.redrawn
    drawn, image = _draw(fig3, camera.view)
    assert drawn and shown(image) > 500 and len(_pixels_of(image, "Cube", fig3)) == 0  # every mirror pixel
    moved = look_at_view((0.8, -6.4, 2.4), (0.0, 0.0, 0.9), fov_y_deg=30.0, width=WIDTH, height=HEIGHT)
    drawn, image = _draw(fig3, moved)  # the same camera, from another view: its answers alone
    assert drawn and shown(image) == 0


def test_big_reflectors_are_made_ready_on_the_worker_while_the_last_reflections_draw(fig3, monkeypatch):
    """Reflectors of more than BACKGROUND_TRIANGLES (lowered here below the ball's) are
    made ready for tracing (BVH, seal) on the worker: the re-bake after moving the ball
    returns at once, the last reflection keeps drawing and the status counts the
    seconds; once ready the capture lands, a new camera is built and drawn. A Start that
    does not wait queues its views for then."""
    bpy.ops.curved_reflections.start_live()
    state = live.state_of(fig3)
    view = _camera_view(fig3)
    monkeypatch.setattr(live, "BACKGROUND_TRIANGLES", 10)
    ready = threading.Event()
    prepare = live_workers.prepare_reflectors
    monkeypatch.setattr(live_workers, "prepare_reflectors", lambda *args: ready.wait(60) and prepare(*args))
    fig3.curved_reflections.auto_refresh = False  # the handler would process at once, waiting (background mode)
    bpy.data.objects["MirrorSphere"].location.x += 0.2
    bpy.context.view_layer.update()
    state.dirty_reflectors = True
    renderer, generation, camera = state.renderer, state.generation, state.cameras[live.CAMERA_KEY]
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert live.process(fig3, depsgraph)  # returns while the worker is held: pending
    assert state.preparing is not None and state.renderer is renderer and state.generation == generation
    assert "Preparing 'MirrorSphere' for ray tracing" in state.status and "triangles" in state.status
    drawn, image = _draw(fig3, view)
    assert drawn and len(_pixels_of(image, "Cube", fig3)) > 0  # the last reflection
    assert live.process(fig3, depsgraph) and state.preparing is not None
    ready.set()
    state.preparing.future.result(timeout=60)
    assert live.process(fig3, depsgraph)  # lands; the view's camera is rebuilt on the worker
    assert state.preparing is None and state.generation == generation + 1 and state.renderer is not renderer
    assert state.captured.reflectors[0].vertices[:, 0].max() == pytest.approx(1.2, abs=1e-3)
    state.jobs[live.CAMERA_KEY].future.result(timeout=60)
    live.process(fig3, depsgraph)
    assert state.cameras[live.CAMERA_KEY] is not camera and _draw(fig3, view)[0]

    live.start(fig3, depsgraph, {live.CAMERA_KEY: view}, wait=False)
    assert state.preparing is not None and state.requests[live.CAMERA_KEY] == (view, 0.0)
    from curved_reflections.blender import live_operators
    assert live_operators._summary(state).startswith("Preparing 'MirrorSphere' for ray tracing")  # what Start reports
    state.preparing.future.result(timeout=60)
    live.process(fig3, depsgraph)
    assert state.preparing is None and live.CAMERA_KEY in state.jobs and not state.requests
    state.jobs[live.CAMERA_KEY].future.result(timeout=60)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the nice value is per thread on Linux only")
def test_background_threads_yield_the_cores_to_drawing():
    """Camera builds and morphing prefetches run at a lower priority than Blender's
    drawing, which on a software GL driver shares their cores; the main thread keeps its own."""
    main = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    for executor in (live_workers.builder(), live_workers.prefetcher()):
        nice = executor.submit(lambda: os.getpriority(os.PRIO_PROCESS, threading.get_native_id())).result(timeout=10)
        assert nice == min(19, main + live_workers.BACKGROUND_NICENESS)
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == main


def test_a_view_whose_clip_start_cuts_into_the_sealed_ball_says_so(fig3):
    """The ball holds nothing, so a view whose near clip plane starts inside it sees only
    its inside, where a ray meets no light: every pixel is drawn black (as Cycles shows
    it), and the status line names the ball and says so."""
    bpy.ops.curved_reflections.start_live()
    state = live.state_of(fig3)
    ball = bpy.data.objects["MirrorSphere"]
    centre, radius = np.array(ball.matrix_world.translation), 0.5 * max(ball.dimensions)
    inside = look_at_view(centre - (0.0, 1.05 * radius, 0.0), centre, fov_y_deg=30.0, width=WIDTH, height=HEIGHT,
                          near=0.1 * radius)
    live._start_camera(state, live.CAMERA_KEY, inside, wait=True)
    assert state.cameras[live.CAMERA_KEY].sbc.ray_map.n_rays == 0
    assert state.level == 'WARNING' and "'MirrorSphere': the camera's clip start cuts into this mirror" in state.status
    assert "drawn black" in state.status
    drawn, image = _draw(fig3, inside)
    assert drawn and np.all(image[..., :3] == 0.0)
    live._start_camera(state, live.CAMERA_KEY, _camera_view(fig3), wait=True)
    assert state.status == "Reflections up to date"


def clip_half_a_radius_short_of_the_centre(scene, mode: str) -> None:
    """sbc_fig3's ball in ``mode``, the scene camera's clip start half a radius short of
    the ball's centre: a disc of the ball's front is cut away."""
    ball = bpy.data.objects["MirrorSphere"]
    ball.curved_reflections.mode = mode
    bpy.context.view_layer.update()
    centre, radius = np.array(ball.matrix_world.translation), 0.5 * max(ball.dimensions)
    matrix = np.array(scene.camera.matrix_world)
    scene.camera.data.clip_start = float(np.dot(centre - matrix[:3, 3], -matrix[:3, 2])) - 0.5 * radius


@pytest.mark.parametrize("mode", ['AUTO', 'RUNTIME'])
def test_where_the_clip_start_cuts_a_disc_off_the_sealed_ball_its_inside_is_drawn_black(fig3, mode):
    """The scene camera with its clip start half a radius short of the ball's centre: in
    the cut-away disc the view rays start inside the ball (the exact trace from the near
    plane, ``band_trace.BandTracer``, says no light), and the live view draws those
    pixels black, in both modes (the iterative search answers every vertex from the eye,
    and drew the cut-away front's reflections there), and the rest of the ball not."""
    from curved_reflections.engine.geometry.band_trace import NO_LIGHT, BandTracer

    clip_half_a_radius_short_of_the_centre(fig3, mode)
    view = _camera_view(fig3)
    state = live.start(fig3, bpy.context.evaluated_depsgraph_get(), {live.CAMERA_KEY: view}, wait=True)
    assert "'MirrorSphere': the camera's clip start cuts into this mirror" in state.status
    drawn, image = _draw(fig3, view)
    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH]
    pixels = np.c_[xs.ravel(), ys.ravel()] + 0.5
    tracer = BandTracer(state.captured.reflectors, state.captured.meshes, state.reflector_set)
    hits = tracer.intersect(*view.pixel_rays(pixels))
    mirror = (hits.hit & (hits.reflector < tracer.n_reflectors)).reshape(HEIGHT, WIDTH)
    exact = tracer.trace(view, pixels, 1, state.world).reshape(HEIGHT, WIDTH, 4)
    inside = mirror & np.all(exact == NO_LIGHT, axis=2)
    assert drawn and inside.sum() > 0.6 * mirror.sum() > 1000
    black = np.all(image[..., :3] == 0.0, axis=2)
    assert np.all(black[inside]) and not np.any(black[mirror & ~inside])


def test_a_draw_error_becomes_the_status_line(fig3, monkeypatch):
    bpy.ops.curved_reflections.start_live()
    state = live.state_of(fig3)

    def fail(*_args, **_kwargs):
        raise ValueError("broken shader")

    monkeypatch.setattr(state.renderer, "draw", fail)
    view = _camera_view(fig3)
    assert not live.draw_safely(fig3, live.CAMERA_KEY, view)
    assert state.level == 'ERROR' and state.status.startswith("Drawing stopped: ValueError: broken shader")
    assert not live.draw_safely(fig3, live.CAMERA_KEY, view)  # stopped, not retried every redraw
    monkeypatch.undo()
    bpy.ops.curved_reflections.refresh()
    assert state.drawing and live.draw_safely(fig3, live.CAMERA_KEY, view)


def test_unregister_leaves_no_handler_timer_or_state(empty_scene, gpu_ready):
    import curved_reflections

    curved_reflections.register()
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, 64, 48)
    live.start(scene, bpy.context.evaluated_depsgraph_get())  # on the worker: the timer polls it
    assert bpy.app.timers.is_registered(live._tick)
    assert live_handlers.on_depsgraph_update in bpy.app.handlers.depsgraph_update_post
    curved_reflections.unregister()
    for name in ("depsgraph_update_post", "load_pre", "load_post"):
        assert not [h for h in getattr(bpy.app.handlers, name) if "curved_reflections" in h.__module__]
    assert not bpy.app.timers.is_registered(live._tick)
    assert live_handlers._draw_handle is None and not live_workers.running() and not live._states
    assert not scene_changes._listeners


def test_loading_a_file_drops_the_live_state_and_keeps_the_handlers(fig3, tmp_path):
    bpy.ops.curved_reflections.start_live()
    path = tmp_path / "fig3.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    assert not live._states
    assert live_handlers.on_depsgraph_update in bpy.app.handlers.depsgraph_update_post
    assert bpy.ops.curved_reflections.start_live() == {'FINISHED'}
    assert _draw(bpy.context.scene, _camera_view(bpy.context.scene))[0]


# --- bad states: a clear message, never a traceback -----------------------------------


def _bake_error(capfd) -> str:
    with pytest.raises(RuntimeError) as error:
        bpy.ops.curved_reflections.start_live()
    captured = capfd.readouterr()
    assert "Traceback" not in captured.out + captured.err
    return str(error.value)


def test_no_reflector_marked(fig3, capfd):
    bpy.data.objects["MirrorSphere"].curved_reflections.is_reflector = False
    assert _bake_error(capfd).startswith("Error: 'Scene': has no visible object marked as a reflector")
    state = live.state_of(fig3)
    assert state.level == 'ERROR' and "no visible object marked as a reflector" in state.status
    assert not _draw(fig3, _camera_view(fig3))[0]


def test_reflector_out_of_view(fig3, capfd):
    fig3.camera.rotation_euler.z += np.pi  # look away from the ball
    bpy.context.view_layer.update()
    assert bpy.ops.curved_reflections.start_live() == {'FINISHED'}
    out = capfd.readouterr().out
    assert "Warning: 'MirrorSphere': out of view, no reflection to draw" in out
    assert live.state_of(fig3).level == 'WARNING'


def test_camera_inside_a_reflector(fig3, capfd):
    fig3.camera.location = (0.0, 0.1, 1.0)  # inside the ball (centre (0, 0, 1), radius 1)
    bpy.context.view_layer.update()
    assert _bake_error(capfd).startswith("Error: 'MirrorSphere': the view is inside this reflector")
    assert "the view is inside this reflector" in live.state_of(fig3).status


def test_camera_moving_inside_a_reflector_after_baking_reports_in_the_status(fig3):
    bpy.ops.curved_reflections.start_live()
    state = live.state_of(fig3)
    inside = look_at_view((0.0, 0.1, 1.0), (0.0, 1.0, 1.0), width=WIDTH, height=HEIGHT)
    live.draw_safely(fig3, live.CAMERA_KEY, inside)
    live.process(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    assert state.level == 'ERROR' and state.status.startswith("'MirrorSphere': the view is inside this reflector")
    # Nothing drawn for that view, and not retried on every redraw; the old view draws again.
    assert not live.draw_safely(fig3, live.CAMERA_KEY, inside)
    assert not state.requests and not state.jobs
    live.draw_safely(fig3, live.CAMERA_KEY, _camera_view(fig3))
    live.process(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    assert live.draw_safely(fig3, live.CAMERA_KEY, _camera_view(fig3))


def test_reflector_whose_modifiers_leave_no_faces(fig3, capfd):
    mirror = bpy.data.objects["MirrorSphere"]
    mirror.vertex_groups.new(name="nothing")
    mask = mirror.modifiers.new("Mask", 'MASK')
    mask.vertex_group = "nothing"  # an empty group: the Mask modifier removes every face
    bpy.context.view_layer.update()
    assert _bake_error(capfd).startswith("Error: 'MirrorSphere': has no faces once its modifiers are applied")
