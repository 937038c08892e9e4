# SPDX-License-Identifier: GPL-3.0-or-later
"""Every operator over a corpus of bad input (issue 18): a clear message naming the object
and the problem, never a traceback; the user's data unchanged; and once the input is
repaired, the next run works with no leftover error.

Each case builds a small scene (a mirror ball, a box, a camera) and breaks one thing.
In background mode an operator that reports an error makes ``bpy.ops`` raise
``RuntimeError`` with the report's text; an exception escaping ``execute`` shows as
"Python: Traceback", which no case may produce.
"""

import hashlib

import bpy
import numpy as np
import pytest

from curved_reflections.blender import live

#: The operators run on every case, with their arguments.
OPERATORS = {
    "check_scene": {},
    "start_live": {},
    "refresh": {},
    "render_image": {"filepath": "{folder}/image.png"},
    "bake_morphing": {"processes": 1},
}


def _scene_with_mirror():
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0.0, 0.0, 1.0), segments=16, ring_count=8)
    ball = bpy.context.active_object
    ball.name = "Ball"
    ball.curved_reflections.is_reflector = True  # in Morphing mode: every operator has work, Bake Morphing too
    ball.curved_reflections.mode = 'MORPHING'
    bpy.ops.mesh.primitive_cube_add(size=0.6, location=(1.6, -0.4, 0.6))
    bpy.context.active_object.name = "Box"
    bpy.ops.object.camera_add(location=(0.5, -6.0, 2.0), rotation=(np.radians(80.0), 0.0, 0.0))
    scene.camera = bpy.context.active_object
    scene.render.resolution_x, scene.render.resolution_y = 48, 36
    scene.curved_reflections.morph_grid = (2, 2, 2)
    return scene


def _break_nan_scale(scene):
    obj = bpy.data.objects["Ball"]
    obj.scale = (1.0, float("nan"), 1.0)
    return "Ball", "not a number", lambda: setattr(obj, "scale", (1.0, 1.0, 1.0))


def _break_zero_scale_reflector(scene):
    obj = bpy.data.objects["Ball"]
    obj.scale = (1.0, 1.0, 0.0)
    return "Ball", "zero scale", lambda: setattr(obj, "scale", (1.0, 1.0, 1.0))


def _break_empty_mesh(scene):
    obj = bpy.data.objects["Ball"]
    original = obj.data
    obj.data = bpy.data.meshes.new("Nothing")

    def repair():
        obj.data = original
    return "Ball", "no faces", repair


def _break_loose_edges(scene):
    obj = bpy.data.objects["Ball"]
    original = obj.data
    mesh = bpy.data.meshes.new("Wire")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (1, 1, 0)], [(0, 1), (1, 2)], [])
    obj.data = mesh

    def repair():
        obj.data = original
    return "Ball", "no faces", repair


def _break_no_camera(scene):
    camera = scene.camera
    scene.camera = None
    return scene.name, "no camera", lambda: setattr(scene, "camera", camera)


def _break_camera_inside_mirror(scene):
    camera = scene.camera
    location = tuple(camera.location)
    camera.location = (0.0, 0.0, 1.0)
    return "Ball", "inside", lambda: setattr(camera, "location", location)


def _break_no_reflector(scene):
    obj = bpy.data.objects["Ball"]
    obj.curved_reflections.is_reflector = False
    return scene.name, "reflector", lambda: setattr(obj.curved_reflections, "is_reflector", True)


CASES = {
    "nan_scale": _break_nan_scale,
    "zero_scale_reflector": _break_zero_scale_reflector,
    "empty_mesh": _break_empty_mesh,
    "loose_edges": _break_loose_edges,
    "no_camera": _break_no_camera,
    "camera_inside_mirror": _break_camera_inside_mirror,
    "no_reflector": _break_no_reflector,
}
#: Operators a case leaves alone: they do not read what it breaks.
NOT_AFFECTED = {
    ("check_scene", "no_camera"), ("check_scene", "camera_inside_mirror"),
    ("start_live", "camera_inside_mirror"), ("refresh", "camera_inside_mirror"),
    ("bake_morphing", "no_camera"), ("bake_morphing", "camera_inside_mirror"),
}


def _fingerprint() -> str:
    """The user's data an operator must leave as it found it: every object's transform,
    settings and mesh, and the scene's settings."""
    digest = hashlib.sha256()
    for obj in sorted(bpy.data.objects, key=lambda o: o.name):
        digest.update(obj.name.encode())
        digest.update(np.array(obj.matrix_world, dtype=np.float64).tobytes())
        settings = obj.curved_reflections
        digest.update(repr((settings.is_reflector, settings.mode, settings.reflectivity)).encode())
        if obj.type == 'MESH':
            coordinates = np.zeros(3 * len(obj.data.vertices), np.float32)
            obj.data.vertices.foreach_get("co", coordinates)
            digest.update(obj.data.name.encode() + coordinates.tobytes())
    scene = bpy.context.scene
    digest.update(repr((scene.camera.name if scene.camera else None, tuple(scene.curved_reflections.morph_grid),
                        scene.frame_current)).encode())
    return digest.hexdigest()


def _run(name: str, folder) -> str | None:
    """Run one operator; its error report, or None when it finished."""
    arguments = {k: v.format(folder=folder) if isinstance(v, str) else v for k, v in OPERATORS[name].items()}
    try:
        getattr(bpy.ops.curved_reflections, name)(**arguments)
    except RuntimeError as error:
        return str(error)
    return None


@pytest.fixture
def corpus_ops(empty_scene, registered, gpu_ready, tmp_path, monkeypatch):
    from curved_reflections.blender import morph_bake

    monkeypatch.setattr(morph_bake, "FACE_RESOLUTION", 16)  # a quick bake where one runs
    monkeypatch.setattr(morph_bake, "cache_root", lambda scene: tmp_path / "morphing")
    yield tmp_path
    live.clear_all()


@pytest.mark.parametrize("case", CASES)
def test_every_operator_names_the_problem_and_recovers(corpus_ops, case):
    scene = _scene_with_mirror()
    bpy.context.view_layer.update()
    culprit, problem, repair = CASES[case](scene)
    bpy.context.view_layer.update()
    for name in OPERATORS:
        before = _fingerprint()
        error = _run(name, corpus_ops)
        assert _fingerprint() == before, f"{name} changed the user's data ({case})"
        if (name, case) in NOT_AFFECTED:
            continue
        assert error is not None, f"{name} accepted {case}"
        assert "Traceback" not in error and "Python:" not in error, error
        assert culprit in error and problem in error, (name, error)

    repair()
    bpy.context.view_layer.update()
    for name in OPERATORS:
        error = _run(name, corpus_ops)
        assert error is None, f"{name} after repairing {case}: {error}"
    state = live.state_of(scene)
    assert state is not None and state.level != 'ERROR', state.status


def test_a_squashed_diffuse_object_and_an_orthographic_camera_just_work(corpus_ops):
    """Not errors at all: a box scaled flat is reflected as a flat shape, and an
    orthographic camera renders (Morphing, which needs a perspective view, draws in
    Runtime mode)."""
    scene = _scene_with_mirror()
    bpy.data.objects["Box"].scale = (1.0, 1.0, 0.0)
    scene.camera.data.type = 'ORTHO'
    scene.camera.data.ortho_scale = 5.0
    bpy.context.view_layer.update()
    for name in OPERATORS:
        before = _fingerprint()
        assert _run(name, corpus_ops) is None, name
        assert _fingerprint() == before, name
