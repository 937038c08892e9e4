# SPDX-License-Identifier: GPL-3.0-or-later
"""The small scene of the working-session corpus (test_working_session*.py) and how its
pictures are compared.

A mirror ball (an icosphere of 320 triangles), a red box in front of it to its right, a
camera looking at both at 64x48, first order only, the ball in Runtime mode: a live
start costs about 0.15 s and a Render Image about 0.2 s. "The right picture" after a
session step is the picture of the same final state built afresh: the live view drawn
by a state started anew, or a Render Image of the state saved and opened anew.
"""

import time

import bpy
import numpy as np

from curved_reflections.blender import accuracy, live, live_traces
from curved_reflections.blender.capture import view_from_camera
from curved_reflections.blender.render_image import render_scene

from test_live import _draw, _touched

WIDTH, HEIGHT = 64, 48
RED = (1.0, 0.0, 0.0, 1.0)


def build(mode: str = 'RUNTIME'):
    """The corpus scene in the context's (empty) scene; returns the scene."""
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_ico_sphere_add(radius=1.0, location=(0.0, 0.0, 1.0), subdivisions=2)
    ball = bpy.context.active_object
    ball.name = "Ball"
    ball.curved_reflections.is_reflector = True
    ball.curved_reflections.mode = mode
    bpy.ops.mesh.primitive_cube_add(size=0.6, location=(1.6, -0.9, 0.6))
    box = bpy.context.active_object
    box.name, box.color = "Box", RED
    bpy.ops.object.camera_add(location=(0.5, -6.0, 2.0), rotation=(np.radians(80.0), 0.0, 0.0))
    scene.camera = bpy.context.active_object
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.curved_reflections.max_order = 1
    bpy.context.view_layer.update()
    return scene


def add_ball(name: str, location=(-1.6, 0.6, 1.0), radius: float = 0.5, mode: str = 'RUNTIME'):
    bpy.ops.mesh.primitive_ico_sphere_add(radius=radius, location=location, subdivisions=2)
    ball = bpy.context.active_object
    ball.name = name
    ball.curved_reflections.is_reflector = True
    ball.curved_reflections.mode = mode
    bpy.context.view_layer.update()
    return ball


def select_only(obj) -> None:
    for other in bpy.context.view_layer.objects:
        other.select_set(other == obj)
    bpy.context.view_layer.objects.active = obj


def camera_view(scene=None):
    scene = scene or bpy.context.scene
    return view_from_camera(scene.camera, scene, bpy.context.evaluated_depsgraph_get())


def draw(scene=None, key=live.CAMERA_KEY, view=None):
    """(drawn, image) of the live view's draw of ``view`` (the scene camera's by default)."""
    scene = scene or bpy.context.scene
    return _draw(scene, view or camera_view(scene), key)


def settle(scene=None, key=live.CAMERA_KEY, view=None):
    """Draw, let the live view build what the draw asked for (in this thread), trace what
    its camera doubts and, once the view rests, its band (on the worker), draw again: the
    picture the viewport shows once it has caught up."""
    scene = scene or bpy.context.scene
    draw(scene, key, view)
    _catch_up(scene)
    for _ in range(2):  # the camera's view drawn (its trace starts), then the band asked for
        draw(scene, key, view)
        _catch_up(scene)
    return draw(scene, key, view)


def _catch_up(scene):
    """What the live view's timer does once the view has rested, with the worker's
    traces waited for."""
    state = live.state_of(scene)
    if state is not None:
        live_traces.wait_for_traces(state)
    live.process(scene, bpy.context.evaluated_depsgraph_get(), wait=True,
                 now=time.monotonic() + accuracy.SETTLE_SECONDS)


def fresh(scene=None, key=live.CAMERA_KEY, view=None):
    """The live view's picture of the scene as it is now, from a state started anew."""
    scene = scene or bpy.context.scene
    view = view or camera_view(scene)
    live.clear(scene)
    live.start(scene, bpy.context.evaluated_depsgraph_get(), views={key: view}, wait=True)
    drawn, image = settle(scene, key, view)
    assert drawn
    return image


def differing(a, b, tolerance: float = 1e-3) -> float:
    """Share of the pixels where two pictures differ."""
    return float((np.abs(np.asarray(a) - np.asarray(b)).max(axis=2) > tolerance).mean())


def render(scene=None):
    """Render Image's picture (linear RGBA) of the scene camera."""
    scene = scene or bpy.context.scene
    return render_scene(scene, bpy.context.evaluated_depsgraph_get()).image


def red_pixels(image) -> np.ndarray:
    """(N, 2) row, column of the box's red (its reflection, in the live view)."""
    return np.argwhere((image[..., 0] > 0.5) & (image[..., 1] < 0.2) & (image[..., 2] < 0.2))


__all__ = ["build", "add_ball", "select_only", "camera_view", "draw", "settle", "fresh", "differing", "render",
           "red_pixels", "_touched", "WIDTH", "HEIGHT"]
