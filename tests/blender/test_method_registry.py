# SPDX-License-Identifier: GPL-3.0-or-later
"""Methods as plug-ins (blender/method_registry.py): the plan, the mode enum and the
renderer's passes come from the registry, so a method registered here, from the test,
draws a reflector without a line changed elsewhere."""

from dataclasses import dataclass

import bpy
import numpy as np
import pytest

from curved_reflections.drawing.frame_pass import Frame, FramePass, PassInputs
from curved_reflections.drawing.gpu_data import data_texture
from curved_reflections.drawing.reflected_meshes import FOUND_CODE
from curved_reflections.blender import demo_scenes, method_plan, method_registry
from curved_reflections.blender.method_registry import Method, Offer, PlanInputs, refuse
from curved_reflections.blender.render_image import render_scene

WIDTH, HEIGHT = 128, 96
FLAT = 'FLAT'


@dataclass(frozen=True)
class FlatMirror:
    """A flat reflector: its index and its plane (a point on it, its unit normal)."""

    index: int
    point: np.ndarray
    normal: np.ndarray


def _offer_flat(inputs: PlanInputs, index: int, reflector) -> Offer:
    """Takes a reflector whose vertices lie in one plane (within 1e-6 of its size)."""
    centred = reflector.vertices - reflector.vertices.mean(axis=0)
    _, singular, axes = np.linalg.svd(centred, full_matrices=False)
    if singular[-1] > 1e-6 * max(singular[0], 1e-300):
        return refuse(f"{reflector.name!r} is not flat")
    return Offer(True, "a flat mirror: every vertex mirrored in its plane",
                 FlatMirror(index, reflector.vertices.mean(axis=0), axes[-1]))


class FlatMirrorPass(FramePass):
    """Each vertex's reflection in a plane, in numpy, uploaded as an answer texture."""

    name = "flat"

    @classmethod
    def of_inputs(cls, methods: tuple, inputs: PassInputs) -> "FlatMirrorPass":
        return cls(inputs, methods)

    def __init__(self, inputs: PassInputs, methods):
        self.geometry, self.meshes, self.methods = inputs.geometry, inputs.meshes, list(methods)
        self._answers = []

    def update(self, frame: Frame) -> None:
        vertices, eye, self._answers = self.geometry.vertices, frame.view.eye, []
        for mirror in self.methods:
            mirrored = vertices - 2.0 * ((vertices - mirror.point) @ mirror.normal)[:, None] * mirror.normal
            towards = mirrored - eye
            t = ((mirror.point - eye) @ mirror.normal) / (towards @ mirror.normal)
            same_side = np.sign((vertices - mirror.point) @ mirror.normal) == np.sign((eye - mirror.point)
                                                                                      @ mirror.normal)
            valid = same_side & (t > 0.0) & (t < 1.0)
            texels = np.zeros((self.meshes.n_vertices, 4), np.float32)
            texels[valid, :3] = eye + t[valid, None] * towards[valid] - self.geometry.shift
            texels[valid, 3] = FOUND_CODE
            self._answers.append((mirror.index, data_texture(texels, self.meshes.width)))

    def answers(self) -> list:
        return list(self._answers)


@pytest.fixture
def flat_method():
    method_registry.register(Method(FLAT, "Flat Mirror", "Mirror every vertex in the reflector's plane", 'MOD_MIRROR',
                                    _offer_flat, FlatMirrorPass.factory, summary="mirrored in its plane"))
    yield
    method_registry.unregister(FLAT)


@pytest.fixture
def flat_scene(empty_scene, registered, gpu_ready):
    """sbc_fig3 with its ball made a flat, upright mirror behind the cube and two columns."""
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, WIDTH, HEIGHT)
    mirror = bpy.data.objects["MirrorSphere"]
    xs, zs = np.meshgrid(np.linspace(-1.8, 1.8, 9), np.linspace(0.1, 2.3, 6))
    vertices = np.c_[xs.ravel(), np.full(xs.size, 0.5), zs.ravel()]
    faces = [(r * 9 + c, r * 9 + c + 1, (r + 1) * 9 + c + 1, (r + 1) * 9 + c) for r in range(5) for c in range(8)]
    mesh = bpy.data.meshes.new("FlatMirror")
    mesh.from_pydata(vertices.tolist(), [], faces)
    mirror.data = mesh
    mirror.location, mirror.rotation_euler, mirror.scale = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    return scene


def test_a_method_registered_by_a_test_draws_a_reflector(flat_scene, flat_method):
    mirror = bpy.data.objects["MirrorSphere"]
    mirror.curved_reflections.mode = FLAT  # the mode enum lists it
    flat_scene.curved_reflections.max_order = 1  # an open mirror may show higher orders: a camera would draw them
    depsgraph = bpy.context.evaluated_depsgraph_get()
    flat = render_scene(flat_scene, depsgraph)
    [choice] = method_plan.last_choices(flat_scene)
    assert (choice.method, choice.reason) == (FLAT, "a flat mirror: every vertex mirrored in its plane")
    assert flat.camera is None and flat.stats["methods"] == {"MirrorSphere": FLAT}  # no camera built for it

    mirror.curved_reflections.mode = 'RUNTIME'
    runtime = render_scene(flat_scene, depsgraph)
    assert runtime.camera is not None
    mirror.curved_reflections.reflectivity = 0.0
    unreflected = render_scene(flat_scene, depsgraph)
    palette = demo_scenes.palette(flat_scene)
    for name in ("Cube", "Column1", "Column2"):  # in front of the mirror: seen directly and reflected
        colour = np.array(palette[name])
        seen = [(np.abs(image[..., :3] - colour).max(axis=2) < 0.02).sum() for image in (flat.image,
                                                                                         unreflected.image)]
        assert seen[0] > seen[1] + 20, (name, seen)
    differing = np.abs(flat.image[..., :3] - runtime.image[..., :3]).max(axis=2) > 0.05
    assert differing.mean() < 0.01  # the plug-in draws what the sample-based camera draws


def test_a_reflector_the_method_refuses_is_ray_traced_with_the_reason(empty_scene, registered, gpu_ready,
                                                                      flat_method):
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, WIDTH, HEIGHT)
    bpy.data.objects["MirrorSphere"].curved_reflections.mode = FLAT
    rendered = render_scene(scene, bpy.context.evaluated_depsgraph_get())
    [choice] = method_plan.last_choices(scene)
    assert choice.method == method_plan.TRACED and rendered.camera is None  # the trace draws every order
    assert choice.reason == "'MirrorSphere' is not flat; ray traced instead"
    assert rendered.stats["methods"] == {"MirrorSphere": method_plan.TRACED}


def test_auto_tries_the_registered_methods_in_order_and_the_enum_follows_the_registry(flat_method):
    names = [m.name for m in method_registry.registered()]
    assert names == ['ITERATIVE', 'RUNTIME', 'MORPHING', 'OCTREE', 'PERTURBATION', 'TRACED', FLAT]
    items = method_registry.enum_items()
    assert [item[0] for item in items] == ['AUTO'] + names
    assert [item[3] for item in items] == list(range(len(names) + 1))  # saved files keep their numbers
    assert [m.name for m in method_plan._candidates('AUTO')] == ['ITERATIVE', 'MORPHING', 'TRACED']
    assert "Iterative (GPU), Morphing, Ray Traced (GPU), else Runtime" in items[0][2]
    method_registry.unregister(FLAT)
    assert FLAT not in [item[0] for item in method_registry.enum_items()]


def test_methods_sharing_a_pass_key_get_one_pass(flat_method):
    factories = method_registry.pass_factories({method_plan.MORPHING: ["a"], method_plan.OCTREE: ["b"], FLAT: ["c"]})
    made = [factory.args[0] if hasattr(factory, "args") else None for factory in factories]
    assert made == [(), ("a", "b"), (), (), ("c",)]  # iterative, grids, perturbation, traced, flat: registry order
