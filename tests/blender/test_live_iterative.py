# SPDX-License-Identifier: GPL-3.0-or-later
"""The live view in Auto and Iterative mode (blender/live.py, blender/method_plan.py):
star-shaped reflectors are searched on the GPU every frame, with no camera to build."""

import bpy
import numpy as np
import pytest

from curved_reflections.engine.view import look_at_view
from curved_reflections.blender import demo_scenes, live, method_plan, star_maps

from test_live import HEIGHT, WIDTH, _camera_view, _draw, _pixels_of, _touched


@pytest.fixture
def fig3(empty_scene, registered, gpu_ready):
    """sbc_fig3, its mirror ball in the default (Auto) mode."""
    return demo_scenes.build("sbc_fig3", bpy.context.scene, WIDTH, HEIGHT)


def _torus(scene):
    bpy.ops.mesh.primitive_torus_add(major_radius=0.8, minor_radius=0.3, location=(2.5, 2.5, 0.6))
    torus = bpy.context.active_object
    torus.name = "Ring"
    torus.curved_reflections.is_reflector = True
    return torus


def _coarse_torus(scene):
    """The Ring of _torus on 64 x 8 segments (Blender's default is 48 x 12): the Runtime
    camera the accuracy test builds for it takes about a fifth of the time (its cost
    follows the minor segments: 3.2 s a test at 8, 7.2 s at 10, 11-13 s at 12)."""
    bpy.ops.mesh.primitive_torus_add(major_radius=0.8, minor_radius=0.3, major_segments=64, minor_segments=8,
                                     location=(2.5, 2.5, 0.6))
    torus = bpy.context.active_object
    torus.name = "Ring"
    torus.curved_reflections.is_reflector = True
    return torus


def test_auto_mode_searches_the_mirror_ball_and_builds_no_camera(fig3, capfd):
    assert bpy.data.objects["MirrorSphere"].curved_reflections.mode == 'AUTO'
    assert bpy.ops.curved_reflections.start_live() == {'FINISHED'}
    assert "Info: Started reflections: MirrorSphere searched on the GPU every frame" in capfd.readouterr().out
    state = live.state_of(fig3)
    [choice] = method_plan.last_choices(fig3)
    assert (choice.reflector, choice.method) == ("MirrorSphere", method_plan.ITERATIVE)
    assert choice.reason.startswith("star-shaped around")
    assert state.counts["builds"] == 0 or all(c.sbc is None for c in state.cameras.values())

    drawn, image = _draw(fig3, _camera_view(fig3))
    assert drawn
    # The vertices the search left unanswered are counted (they are never drawn).
    assert 0 < state.stats["unanswered"] < state.stats["searched"] == len(state.renderer.geometry.vertices)
    touched = _touched(image)
    assert 1000 < touched.sum() < 3000  # the ball's disc only (reflectors only)
    cube = _pixels_of(image, "Cube", fig3)
    assert len(cube) >= 15 and touched[cube[:, 0], cube[:, 1]].all()
    assert sum(len(_pixels_of(image, f"Column{k}", fig3)) > 0 for k in range(1, 8)) >= 3

    # A new view draws at once, with no request, job or camera build.
    builds, draws = state.counts["builds"], state.counts["draws"]
    centre = np.array(bpy.data.objects["MirrorSphere"].matrix_world.translation)
    moved = look_at_view(centre + (3.0, -4.0, 1.5), centre, fov_y_deg=40.0, width=WIDTH, height=HEIGHT)
    drawn, other = _draw(fig3, moved, key="another region")
    assert drawn and not state.requests and not state.jobs
    assert state.counts["builds"] == builds and state.counts["draws"] == draws + 1
    assert np.abs(other - image).max() > 0.1  # the reflection follows the view


def test_a_view_inside_the_searched_reflector_is_reported_and_drawing_resumes_outside(fig3):
    state = live.start(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    centre = np.array(bpy.data.objects["MirrorSphere"].matrix_world.translation)
    inside = look_at_view(centre + (0.1, 0.0, 0.1), centre + (3.0, 0.0, 0.0), width=WIDTH, height=HEIGHT)
    assert not live.draw_safely(fig3, live.CAMERA_KEY, inside)
    assert state.level == 'ERROR' and state.status.startswith("'MirrorSphere': the view is inside this reflector")
    assert live.draw_safely(fig3, live.CAMERA_KEY, _camera_view(fig3))
    assert state.level == 'INFO'


def test_a_torus_in_iterative_mode_is_searched_as_pieces_and_in_auto_mode_the_live_view_traces_it(fig3):
    """A torus is not star-shaped: Iterative mode searches it as pieces seen from inside
    (engine/methods/iterative/pieces.py); Auto traces it (each redraw would search every
    piece), with no camera for its first orders, and the panel says why."""
    torus = _torus(fig3)
    state = live.start(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    choices = {c.reflector: c for c in method_plan.last_choices(fig3)}
    assert choices["Ring"].method == method_plan.TRACED
    assert choices["Ring"].reason.startswith("'Ring' is not star-shaped")
    assert "searched as pieces in Iterative mode" in choices["Ring"].reason
    assert choices["Ring"].reason.endswith("each pixel's reflected ray traced on the GPU every frame: every image, "
                                           "to Max Order")
    assert [m.name for m in state.renderer.pass_named("traced").methods] == ["Ring"]
    # The ball traced too: the trace draws every order (Max Order 2), so no camera is built.
    bpy.data.objects["MirrorSphere"].curved_reflections.mode = method_plan.TRACED
    state = live.start(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    assert live.draw_safely(fig3, live.CAMERA_KEY, _camera_view(fig3)) and not state.jobs
    assert state.camera_job(_camera_view(fig3)) is None and state.renderer.pass_named("traced").claims() == {0, 1}
    bpy.data.objects["MirrorSphere"].curved_reflections.mode = method_plan.AUTO

    torus.curved_reflections.mode = 'ITERATIVE'
    state = live.start(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    choices = {c.reflector: c for c in method_plan.last_choices(fig3)}
    assert choices["MirrorSphere"].method == choices["Ring"].method == method_plan.ITERATIVE, choices["Ring"].reason
    assert choices["Ring"].reason.startswith("not star-shaped: ")
    assert choices["Ring"].reason.endswith("pieces seen from inside it, each searched on the GPU")
    [pieces] = [e for e in state.plan.engines_of(method_plan.ITERATIVE) if e.name == "Ring"]
    assert 2 <= len(pieces.pieces) <= 12
    assert live.draw_safely(fig3, live.CAMERA_KEY, _camera_view(fig3))
    search = state.renderer.pass_named("iterative")
    ring = pieces.index
    assert [answer.reflector_index for answer in search.answers()].count(ring) == len(pieces.pieces)
    # The camera (Max Order 2: the torus reflects itself) leaves the searched first orders out.
    camera = state.cameras[live.CAMERA_KEY]
    assert camera.sbc is None or not {tuple(h) for h in camera.sbc.groups} & {(0,), (ring,)}
    counts = search.status_counts()["Ring"]
    assert counts["found"] > 0.2 * (counts["found"] + counts["unanswered"])


def test_second_order_in_auto_mode_builds_a_camera_for_the_higher_orders(fig3):
    """Max Order 2 (the default): the lone convex ball cannot reflect itself, so the
    search draws it with no camera; a second mirror (a column) brings reflections of
    reflections, and a camera for them."""
    assert fig3.curved_reflections.max_order == 2
    state = live.start(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    assert state.cameras[live.CAMERA_KEY].sbc is None
    bpy.data.objects["Column1"].curved_reflections.is_reflector = True
    state = live.start(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    assert state.cameras[live.CAMERA_KEY].sbc is not None
    camera = state.cameras[live.CAMERA_KEY]
    assert {(0, 1), (1, 0)} & {tuple(h) for h in camera.sbc.groups}
    # The searched mirrors' first orders are left out of the camera, which is built again
    # should a pass stop drawing one of them.
    searched = state.renderer.per_frame_reflectors(camera.view)
    assert searched and camera.sbc.first_order_left_out == searched
    assert not {tuple(h) for h in camera.sbc.groups} & {(k,) for k in searched}
    assert camera.first_orders_drawn(lambda view: searched)
    assert not camera.first_orders_drawn(lambda view: frozenset())
    assert live.draw_safely(fig3, live.CAMERA_KEY, _camera_view(fig3))


def test_a_mirror_moved_without_turning_keeps_its_map(fig3, monkeypatch):
    state = live.start(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    before = state.plan.engines_of(method_plan.ITERATIVE)[0].reflector_map

    def no_second_check(*_args, **_kwargs):
        raise AssertionError("the moved mirror was checked again")

    monkeypatch.setattr(star_maps, "check_star_shaped", no_second_check)
    bpy.data.objects["MirrorSphere"].location.x += 0.5
    bpy.context.view_layer.update()
    state = live.start(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    after = state.plan.engines_of(method_plan.ITERATIVE)[0].reflector_map
    np.testing.assert_allclose(after.centre - before.centre, (0.5, 0.0, 0.0), atol=1e-6)
    assert after.texels is before.texels
    assert live.draw_safely(fig3, live.CAMERA_KEY, _camera_view(fig3))


def test_star_shaped_check_of_blender_primitives(fig3):
    """Suzanne (ears, eye sockets) and a torus are not star-shaped (Auto traces them in
    the live view); a UV sphere and a scaled, subdivided cube (rounded) are."""
    from curved_reflections.blender.capture import capture_scene

    bpy.ops.mesh.primitive_monkey_add(location=(3.0, -2.0, 1.0))
    bpy.context.active_object.name = "Suzanne"
    bpy.ops.mesh.primitive_torus_add(location=(-3.0, 2.0, 1.0))
    bpy.context.active_object.name = "Ring"
    bpy.ops.mesh.primitive_cube_add(location=(-3.0, -2.0, 1.0), scale=(1.0, 0.6, 0.4))
    cube = bpy.context.active_object
    cube.name = "Rounded"
    cube.modifiers.new("smooth", 'SUBSURF').levels = 2
    for name in ("Suzanne", "Ring", "Rounded"):
        bpy.data.objects[name].curved_reflections.is_reflector = True
    reflectors = capture_scene(bpy.context.evaluated_depsgraph_get()).reflectors
    plan = method_plan.plan(fig3, reflectors)
    chosen = {c.reflector: c for c in plan.choices}
    assert chosen["MirrorSphere"].method == method_plan.ITERATIVE
    assert chosen["Rounded"].reason.startswith("star-shaped around")  # its flat sides fold: traced live
    for name in ("Suzanne", "Ring"):
        assert chosen[name].method == method_plan.TRACED
        assert chosen[name].reason.startswith(f"{name!r} is not star-shaped")
    # Suzanne is open (no pieces seen from inside); the torus is closed (pieces in Iterative mode).
    assert "not a closed surface" in chosen["Suzanne"].reason
    assert "searched as pieces in Iterative mode" in chosen["Ring"].reason


def test_a_new_capture_of_the_reflectors_makes_older_cameras_stale(fig3):
    state = live.start(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    generation, bakes, remeshes = state.generation, state.counts["captures"], state.counts["remeshes"]
    state.dirty_meshes = True  # a diffuse object changed: the cameras stay
    live.process(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    assert (state.generation, state.counts["remeshes"]) == (generation, remeshes + 1)
    state.dirty_reflectors = True  # a mirror changed: every camera is built again
    live.process(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    assert (state.generation, state.counts["captures"]) == (generation + 1, bakes + 1)


def test_perturbation_mode_draws_live_with_no_camera_and_the_torus_too(fig3, capfd):
    """Perturbation (Chen & Arvo 2000) draws the ball and a torus in the viewport with no
    sample-based camera; a new view is projected again, the same view is not (Max Order
    1: two mirrors, or the torus alone, would reflect each other at 2, by a camera)."""
    fig3.curved_reflections.max_order = 1
    bpy.data.objects["MirrorSphere"].curved_reflections.mode = 'PERTURBATION'
    torus = _torus(fig3)
    torus.curved_reflections.mode = 'PERTURBATION'
    assert bpy.ops.curved_reflections.start_live() == {'FINISHED'}
    assert ("Info: Started reflections: MirrorSphere, Ring by perturbation of paths traced each view"
            in capfd.readouterr().out)
    state = live.state_of(fig3)
    choices = {c.reflector: c for c in method_plan.last_choices(fig3)}
    assert {name: c.method for name, c in choices.items()} == {"MirrorSphere": method_plan.PERTURBATION,
                                                               "Ring": method_plan.PERTURBATION}
    assert all(c.sbc is None for c in state.cameras.values())
    drawn, image = _draw(fig3, _camera_view(fig3))
    assert drawn
    passes = state.renderer.pass_named("perturbation")
    assert passes.counts["projections"] == 1 and len(passes.answers()) >= 2
    touched = _touched(image)
    cube = _pixels_of(image, "Cube", fig3)
    assert len(cube) >= 15 and touched[cube[:, 0], cube[:, 1]].mean() > 0.95
    drawn, _ = _draw(fig3, _camera_view(fig3))
    assert drawn and passes.counts["projections"] == 1  # the same view: the answers are kept
    centre = np.array(bpy.data.objects["MirrorSphere"].matrix_world.translation)
    moved = look_at_view(centre + (3.0, -4.0, 1.5), centre, fov_y_deg=40.0, width=WIDTH, height=HEIGHT)
    drawn, other = _draw(fig3, moved, key="another region")
    assert drawn and passes.counts["projections"] == 2 and np.abs(other - image).max() > 0.1


def test_the_drawn_methods_accuracy_is_measured_when_the_view_settles(fig3):
    """Once the view has not changed for a moment, the live view checks the drawn
    answers against exactly traced rays (engine/spot_check.py); the panel shows it. The
    ball's iterative search: sub-pixel. A torus beside it, drawn by a Runtime camera
    (in Runtime mode: Auto traces it), is measured too."""
    from curved_reflections.blender import accuracy

    # The Runtime camera's check projects accuracy.CAMERA_SAMPLE (3000) of the scene's vertices.
    _coarse_torus(fig3).curved_reflections.mode = 'RUNTIME'
    state = live.start(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    view = _camera_view(fig3)
    assert _draw(fig3, view)[0]
    checks = state.counts["checks"]
    live.process(fig3, bpy.context.evaluated_depsgraph_get(), now=state.last_view[1] + 0.1)
    assert state.counts["checks"] == checks  # not settled yet
    live.process(fig3, bpy.context.evaluated_depsgraph_get(), now=state.last_view[1] + accuracy.SETTLE_SECONDS + 0.01)
    assert state.checking is not None  # measured on a worker: the viewport does not wait
    state.checking[0].result(timeout=120)
    live.process(fig3, bpy.context.evaluated_depsgraph_get(), now=state.last_view[1] + accuracy.SETTLE_SECONDS + 0.02)
    assert state.checking is None and state.counts["checks"] == checks + 1
    found = method_plan.measured(fig3)
    ball, ring = found["MirrorSphere"], found["Ring"]
    assert ball.method == method_plan.ITERATIVE and ball.check.confirmed >= 0.95 * ball.check.checked > 50
    assert ball.check.percentile(95) < 0.5 and ball.check.within(1.0)
    assert ring.method == method_plan.RUNTIME and ring.check.checked > 20 and ring.check.percentile(50) < 1.0
    assert accuracy.panel_line(ball).startswith("In this view (Iterative): p95 0.")
    _draw(fig3, view)  # the same view again: not checked again
    live.process(fig3, bpy.context.evaluated_depsgraph_get(), now=state.last_view[1] + 10.0)
    assert state.counts["checks"] == checks + 1


def test_auto_passes_over_a_method_measured_outside_the_accuracy_until_refresh(fig3, monkeypatch):
    """A check that finds the Auto ball's search outside the scene's Accuracy (made to,
    here) has it drawn by the next method Auto tries, the trace, from then on, and the
    panel says why; Refresh tries the search again."""
    from curved_reflections.engine.spot_check import SpotCheck
    from curved_reflections.blender import accuracy

    state = live.start(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    view = _camera_view(fig3)
    assert _draw(fig3, view)[0] and method_plan.last_choices(fig3)[0].method == method_plan.ITERATIVE
    monkeypatch.setattr(accuracy, "spot_check", lambda *args, **kwargs: SpotCheck(96, np.full(96, 3.0)))
    live.process(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    live.process(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)  # plans again
    [choice] = method_plan.last_choices(fig3)
    assert choice.method == method_plan.TRACED
    assert "Iterative (GPU): p95 3.00 px in a view (Accuracy 1 px)" in choice.reason
    assert not state.plan.engines_of(method_plan.ITERATIVE) and state.plan.engines_of(method_plan.TRACED)
    assert _draw(fig3, view)[0] and state.renderer.pass_named("traced").claims() == {0}
    monkeypatch.undo()
    live.refresh(fig3, bpy.context.evaluated_depsgraph_get(), wait=True)
    assert method_plan.last_choices(fig3)[0].method == method_plan.ITERATIVE


def test_a_resting_view_is_drawn_as_render_image_draws_it(fig3):
    """Once the view has rested (``accuracy.SETTLE_SECONDS``), its next draw places the
    searched reflections exactly (a moving view's are snapped within the Accuracy) and
    picks the pixels Render Image traces (the ball's rim), which are traced on the
    worker and drawn over that view once they land: the resting viewport shows Render
    Image's picture. Another view is drawn snapped, without them."""
    import time

    from curved_reflections.blender import accuracy, live_traces
    from curved_reflections.drawing.gpu_data import read_texture

    assert bpy.ops.curved_reflections.start_live() == {'FINISHED'}
    state = live.state_of(fig3)
    view, depsgraph = _camera_view(fig3), bpy.context.evaluated_depsgraph_get()
    _, moving = _draw(fig3, view)
    live.process(fig3, depsgraph, now=time.monotonic() + accuracy.SETTLE_SECONDS)
    assert state.band is not None and state.band.future is None  # asked for: the next draw picks it
    _draw(fig3, view)
    traced = state.band.future.result(timeout=60)
    assert 30 < len(traced.pixels) < 0.2 * WIDTH * HEIGHT
    live.process(fig3, depsgraph)
    _, rested = _draw(fig3, view)
    rendered = state.renderer.render(view, None, state.world)
    # The ball's pixels as the render's pre-pass saw them (not those the cube hides).
    mirror = read_texture(state.renderer.targets(WIDTH, HEIGHT).prepass_labels, WIDTH, HEIGHT)[..., 0] == 1.0
    assert mirror.sum() > 1000

    def differing(image) -> float:
        return float((np.abs(image[..., :3] - rendered[..., :3]).max(axis=2) > 0.05)[mirror].mean())

    assert differing(rested) < 0.01 < differing(moving)
    moved = look_at_view(np.array(view.eye) + (0.3, 0.0, 0.0), (0.0, 0.0, 0.9), fov_y_deg=30.0, width=WIDTH,
                         height=HEIGHT)
    _draw(fig3, moved)
    assert not live_traces.resting(state, moved, None) and live_traces.band_traced(state, moved, None) is None
