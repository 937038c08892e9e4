# SPDX-License-Identifier: GPL-3.0-or-later
"""One frame of reflections for one view: the stages Render Image and the live view share.

capture (:mod:`.capture`: the evaluated scene as reflector and diffuse-mesh arrays) ->
looks (each reflector's colour, reflectivity, Fresnel and fade distance,
:func:`.render_inputs.reflector_properties`) -> grids (the baked morphing grids of the
reflectors that want one, :func:`.morph_bake.load_grids`) -> plan (which registered
method draws each reflector, :func:`.method_plan.plan`) -> renderer (the meshes on the GPU
and one per-frame pass per method, ``drawing/reflection_draw.py``) -> is a
sample-based camera needed for this view (:meth:`FramePipeline.camera_job`: a reflector
no per-frame pass draws in it, or a higher order) -> the camera (:meth:`CameraJob.build`,
bpy-free: the live view runs it on a worker) -> warnings (:meth:`FramePipeline.warnings`).

:class:`FramePipeline` keeps what a frame made for the next one: Render Image's
animation makes again only what changed (:meth:`FramePipeline.update`), and the live
view (``live.LiveScene``, a pipeline with its scheduling) captures the reflectors or the
meshes alone as edits arrive. Every stage reads one :class:`FrameSettings`
(:func:`settings_of`).
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from ..engine.frame_settings import FrameSettings
from ..engine.geometry.raytrace import ReflectorSet
from ..engine.heap import release_freed_memory
from ..engine.methods.sbc.sbc_build import build_sample_based_camera, clip_start_inside
from ..engine.scene import scene_bounds
from ..engine.view import View
from ..drawing.reflection_draw import ReflectionRenderer
from . import accuracy, method_plan, morph_bake
from .capture import capture_scene
from .glass_layer import glass_layer
from .picture_check import TracedReference, check_picture
from .render_inputs import BOUNDS_MARGIN, reflector_properties, world_color


def settings_of(scene, *, live: bool = False, **overrides) -> FrameSettings:
    """The frame settings of ``scene.curved_reflections``; ``live``: the viewport's (a
    camera's answers are not polished on the CPU there); ``overrides``: fields to
    replace (a caller's explicit Max Order, say)."""
    s = scene.curved_reflections
    values = {"max_order": s.max_order, "downsample": s.downsample, "accuracy_px": s.accuracy_px,
              "polish_frames": s.morph_polish_frames, "morph_budget_mb": s.morph_gpu_budget_mb,
              "polish_camera": not live}
    values.update({name: value for name, value in overrides.items() if value is not None})
    return FrameSettings(**values)


def captured_key(captured) -> tuple:
    """(reflectors, meshes) hashes of a capture: a frame whose capture, modes, settings
    and mirror looks match the last one's reuses its renderer (meshes uploaded and
    subdivided once) and its method plan."""
    def digest(items, fields) -> str:
        hasher = hashlib.sha1()
        for item in items:
            hasher.update(item.name.encode("utf-8", "surrogatepass"))
            for name in fields:
                value = getattr(item, name)
                if value is not None:
                    hasher.update(np.ascontiguousarray(value).tobytes())
        return hasher.hexdigest()

    return (digest(captured.reflectors, ("vertices", "triangles", "normals")),
            digest(captured.meshes, ("vertices", "triangles", "colors", "uvs", "normals", "image")))


def clip_start_message(name: str) -> str:
    """What Render Image and the live view say when the view starts inside a sealed mirror
    (``sbc_build.clip_start_inside``): what is drawn there, and how to see the mirror's
    outside instead."""
    return (f"{name!r}: the camera's clip start cuts into this mirror (or the camera is on it); its inside, "
            "closed and empty, meets no light and is drawn black, as Cycles shows it: move the camera back or "
            "lower its Clip Start to see its outside")


@dataclass(frozen=True)
class CameraJob:
    """What a view's sample-based camera is built from: the prepared reflectors, the view,
    the scene box reflected rays end at, the settings, and the reflectors whose first
    order the per-frame passes draw in the view (the camera leaves them out)."""

    reflector_set: ReflectorSet
    view: View
    bounds: tuple
    settings: FrameSettings
    first_order_left_out: frozenset

    def build(self):
        """The view's ray map and BSP trees (``engine/methods/sbc/sbc_build.py``); bpy-free."""
        s = self.settings
        return build_sample_based_camera(self.reflector_set, self.view, self.bounds, max_order=s.max_order,
                                         downsample=s.downsample, accuracy_px=s.accuracy_px,
                                         first_order_left_out=self.first_order_left_out)


@dataclass
class FramePipeline:
    """What one scene's frames keep between them (see the module docstring)."""

    settings: FrameSettings = field(default_factory=FrameSettings)
    captured: object = None  # capture.CapturedScene
    reflector_set: object = None  # ReflectorSet of the captured reflectors
    plan: method_plan.MethodPlan = field(default_factory=method_plan.MethodPlan)
    grids: list = field(default_factory=list)  # (MorphingGrid, matrix) the plan draws from baked grids
    renderer: object = None
    bounds: tuple | None = None  # the capture's scene box
    world: tuple = (0.0, 0.0, 0.0, 1.0)
    #: The last :meth:`update`'s capture key and capture time, and how many frames reused the renderer.
    key: tuple = ()
    capture_seconds: float = 0.0
    reused: int = 0
    #: What the last plan has to warn about (a grid that could not be baked).
    plan_warnings: list = field(default_factory=list)
    #: The capture's glass and its renderer (``glass_layer.GlassLayer``), None without glass.
    glass: object = None
    #: The reflectors' looks the renderer was made with (``render_inputs.reflector_properties``).
    properties: dict = field(default_factory=dict)
    #: The picture check's renderer with every reflector traced (``picture_check.py``).
    traced_reference: TracedReference = field(default_factory=TracedReference)
    #: Whether the refraction search draws the convex glass the GPU's trace cannot (image
    #: textures past its atlas, ``image_atlas.py``: the live view); Render Image then
    #: traces it on the CPU.
    SEARCHES_GLASS: ClassVar[bool] = False

    def plan_reflectors(self, scene, captured, bake_missing: bool = False, final_render: bool | None = None) -> None:
        """Load the baked grids the reflectors want (with ``bake_missing``, bake a grid
        mode's missing one first: Render Image) and plan every reflector's method
        (``final_render``, default ``bake_missing``: ``PlanInputs.final_render``)."""
        self.plan_warnings = []
        loaded = morph_bake.load_grids(scene, captured.reflectors, bake_missing=bake_missing,
                                       warnings=self.plan_warnings)
        self.plan = method_plan.plan(scene, captured.reflectors, self.settings.accuracy_px,
                                     grids={grid.reflector_name: (grid, matrix) for grid, matrix in loaded},
                                     final_render=bake_missing if final_render is None else final_render,
                                     max_order=self.settings.max_order)
        self.grids = self.plan.drawn_grids()

    def new_renderer(self, scene, captured, properties: dict | None = None, seal: bool = True) -> None:
        """A renderer of ``captured`` with the plan's passes; ``seal``: first seal the
        reflectors' empty interiors against the new meshes (``ReflectorSet.seal_empty_interiors``)."""
        if seal:
            self.reflector_set.seal_empty_interiors(captured.meshes)
        properties = reflector_properties(captured.reflectors, scene) if properties is None else properties
        self.properties = properties
        self.renderer = ReflectionRenderer(captured.reflectors, captured.meshes, passes=self.plan.pass_factories(),
                                           settings=self.settings, reflector_set=self.reflector_set,
                                           glasses=captured.glass, **properties)
        self.captured = captured
        self.world = world_color(scene)
        self.bounds = scene_bounds(captured.reflectors, captured.meshes)
        # The capture's key hashes every mesh: only glass needs it here.
        self.glass = glass_layer(self.glass, captured, captured_key(captured), self.world, self.settings.accuracy_px,
                                 self.SEARCHES_GLASS, self.settings.max_order) if captured.glass else None

    def glass_alone(self, scene, captured, key: tuple | None = None) -> None:
        """A capture of glass and no mirror: no renderer of mirrors, the glass's layer
        alone draws the frame (``key``: ``captured_key(captured)``, when known)."""
        self.captured, self.renderer, self.reflector_set = captured, None, None
        self.world = world_color(scene)
        self.bounds = scene_bounds(captured.reflectors, captured.meshes)
        self.glass = glass_layer(self.glass, captured, captured_key(captured) if key is None else key, self.world,
                                 self.settings.accuracy_px, self.SEARCHES_GLASS, self.settings.max_order)

    def update(self, scene, depsgraph, settings: FrameSettings) -> None:
        """Render Image's frame: capture the scene and make again only what changed since
        the last frame: the reflectors' BVH when they moved, the plan (and grids, baking a
        grid mode's missing one) when they, their modes or the settings changed, the
        renderer when anything captured, the settings or the mirrors' looks changed."""
        release_freed_memory()  # the last frame's arrays, before this one's are made
        start = time.perf_counter()
        captured = capture_scene(depsgraph)
        self.capture_seconds = time.perf_counter() - start
        properties = reflector_properties(captured.reflectors, scene)
        # Modes, settings and the mirrors' looks may be animated too: they are part of the key.
        looks = hashlib.sha1(b"".join(np.ascontiguousarray(v).tobytes() for v in properties.values())).hexdigest()
        modes = tuple(method_plan.mode_of(scene, r.name) for r in captured.reflectors)
        key = captured_key(captured) + (modes, settings, looks)
        self.settings = settings
        if not captured.reflectors:  # glass alone: its layer is the frame
            self.glass_alone(scene, captured, key[:2])
            self.key = key
            return
        if self.reflector_set is None or key[0] != self.key[0]:
            self.reflector_set = ReflectorSet(list(captured.reflectors))
        if self.renderer is None or key[0] != self.key[0] or key[2:4] != self.key[2:4]:
            self.plan_reflectors(scene, captured, bake_missing=True)
            self.renderer = None
        if self.renderer is None or key != self.key:
            self.new_renderer(scene, captured, properties)
        else:
            self.reused += 1
        self.key = key
        release_freed_memory()  # the capture's, the set's and the renderer's temporaries

    def camera_bounds(self) -> tuple:
        """The scene box grown by :data:`.render_inputs.BOUNDS_MARGIN` of its diagonal:
        where a camera's reflected rays end."""
        lo, hi = self.bounds
        margin = BOUNDS_MARGIN * float(np.linalg.norm(hi - lo))
        return lo - margin, hi + margin

    def camera_job(self, view: View) -> CameraJob | None:
        """The sample-based camera ``view`` needs, or None: every reflector's first order
        is drawn by a per-frame pass in it, and no higher order can show, or a pass (the
        trace) draws every order of every reflector."""
        per_frame = self.renderer.per_frame_reflectors(view)
        higher_orders = self.settings.max_order > 1 and self.renderer.convex_mirrors.higher_orders
        every_order = frozenset().union(*(frame_pass.every_order_reflectors for frame_pass in self.renderer.passes))
        if len(per_frame) >= len(self.captured.reflectors) and (not higher_orders or
                                                                len(every_order) >= len(self.captured.reflectors)):
            return None
        return CameraJob(self.reflector_set, view, self.camera_bounds(), self.settings, per_frame)

    def check_methods(self, scene, view: View, image: np.ndarray | None = None) -> bool:
        """Measure the reflectors a per-frame method drew in the frame just drawn of
        ``view`` (``accuracy.measure``: the answers' error and the exact images they
        missed, against exactly traced rays), then, given the frame's ``image``, a chosen
        mode's picture against the trace's (``picture_check.check_picture``); where one
        fails, its method is passed over (Auto's next, or the trace) and the plan and the
        renderer are made again. Returns whether they were: the frame is drawn again."""
        per_frame = any(c.method not in (method_plan.RUNTIME, method_plan.TRACED) for c in self.plan.choices)
        replaced = per_frame and method_plan.note_measured(
            scene, accuracy.measure(self.plan, self.reflector_set, self.renderer, view, None))
        if not replaced and image is not None:
            replaced = check_picture(scene, self, view, image)
        if not replaced:
            return False
        self.plan_reflectors(scene, self.captured, final_render=True)
        self.new_renderer(scene, self.captured, seal=False)
        return True

    def warnings(self, view: View) -> list:
        """What the frame of ``view`` should warn about: a clip start inside a mirror, and
        what the plan met (a grid that could not be baked)."""
        inside = clip_start_inside(self.reflector_set, view) if view.is_perspective else []
        return [clip_start_message(name) for name in inside] + self.plan_warnings
