# SPDX-License-Identifier: GPL-3.0-or-later
"""Render the scene camera with curved reflections, offscreen, to a PNG.

One frame of the pipeline (:mod:`.frame_pipeline`) for the scene camera at the scene's
render resolution, an animation a loop over the frames that keeps the pipeline between
them. It works in background mode too (``blender -b``, ``import bpy``): the GPU is
initialised first when needed (:mod:`.gpu_init`).

:func:`render_scene` is what the operator and ``scripts/demo.py`` call; it returns the
linear image and the time of each stage. The PNG holds display sRGB values (the
"Standard" view transform), as Blender's own renders of the demo scenes do.

Settings come from ``scene.curved_reflections`` (down-sampling, accuracy, highest
order) and, per reflector, ``obj.curved_reflections`` (reflectivity, Fresnel, fade
distance: :func:`reflector_properties`); reflected rays that leave the scene show the
world's Background colour. Real objects are drawn by the renderer's pre-pass with the
same shading as their reflections (a headlight Lambert, ``engine/geometry/band_trace.py``).
"""

from __future__ import annotations

import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

import bpy
import numpy as np
from bpy.props import BoolProperty, StringProperty

from ..engine.errors import SceneInputError
from ..engine.heap import release_freed_memory
from ..engine.srgb import linear_to_srgb
from ..engine.methods.sbc.sbc_build import check_view_outside_reflectors
from ..engine.view import View
from .capture import view_from_camera
from .frame_pipeline import FramePipeline, settings_of
from .glass_layer import over
from .gpu_init import ensure_gpu
from .live_workers import prefetcher
from .properties import BLEND_RELATIVE
from .png import write_png

#: Node projections an animation keeps queued on the prefetching thread (one runs).
PREFETCHED_NODES = 2
#: Frames ahead whose cells an animation's prefetch serves first, the camera's last move
#: extrapolated.
PREDICTED_FRAMES = 6
#: An animation checks its methods (``FramePipeline.check_methods``) on its first frame
#: and every this many frames after: a check costs a fraction of a frame on a folded
#: mirror (the exact solver on a hundred points; a chosen mode's picture, a traced frame),
#: and a mirror's folds do not come and go from one frame to the next.
CHECK_EVERY_FRAMES = 8


@dataclass
class ReflectionRender:
    """One rendered frame: (H, W, 4) float32 linear RGBA, rows bottom to top, and timings.

    ``seconds`` holds ``capture`` (the scene), ``plan`` (the view and what changed of
    the pipeline: :meth:`.frame_pipeline.FramePipeline.update`), ``sbc`` (ray map and BSP trees),
    ``draw`` (the passes, the band trace, the composite, the read-back, and the
    check of the per-frame methods with any frame drawn again after it) and
    ``total``; ``stats`` the camera's and the renderer's figures, ``methods``
    ({reflector: method}) and ``warnings`` (messages for the user).
    """

    image: np.ndarray
    view: View
    seconds: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    camera: object = None  # the sample-based camera built for the frame, if one was (accuracy checks)

    @property
    def display(self) -> np.ndarray:
        """Display sRGB in [0, 1] (Standard view transform), alpha 1."""
        rgb = linear_to_srgb(self.image[..., :3]).astype(np.float32)
        return np.concatenate([rgb, np.ones(rgb.shape[:2] + (1,), np.float32)], axis=2)


@dataclass
class FrameState(FramePipeline):
    """What the frames of one render keep between them: the pipeline's capture, plan,
    grids and renderer (:meth:`FramePipeline.update` makes again only what changed), and
    the last frame's camera position, which the node prefetch extrapolates."""

    last_eye: object = None
    frames: int = 0


def render_scene(scene, depsgraph, *, max_order: int | None = None, downsample: int | None = None,
                 accuracy_px: float | None = None, trace_edges: bool = False, trace_gaps: bool = False,
                 state: FrameState | None = None) -> ReflectionRender:
    """Render ``scene.camera`` at the render resolution with reflections (offscreen).

    One frame of the pipeline (:mod:`.frame_pipeline`): each reflector is drawn by the
    method its mode chooses (:mod:`.method_plan`), a sample-based camera of this view is
    built only when some reflector or a higher order needs one. Settings not given come
    from ``scene.curved_reflections``. The band along each sample-based reflector's
    visible edge, which its camera cannot reach, is ray traced; ``trace_edges`` also
    traces the mirror pixels next to a drawn reflection that got none (see
    ``drawing/reflection_draw.py``), ``trace_gaps`` every pixel of a mirror drawn
    from its morphing grid that the blend left without a reflection (exact, and several
    times slower: see docs/benchmarks/morph_animation.md). ``state`` keeps the pipeline
    between the frames of an animation, and with it the passes' work for the next
    frames (the grids' nodes around the camera) runs on a worker thread while the frame
    is drawn (:func:`_prefetch`). The reflectors a per-frame method drew are checked in
    the frame (their error and the exact images they missed, and in a chosen mode the
    picture against the trace's: ``FramePipeline.check_methods``; an animation every
    :data:`CHECK_EVERY_FRAMES` frames): a method that fails is passed over, and the
    frame is drawn again with the next. Bad input (no camera, no reflector, a reflector
    without faces, the camera inside a reflector) raises :class:`SceneInputError` naming
    the object; the GPU is initialised if needed.
    """
    settings = settings_of(scene, max_order=max_order, downsample=downsample, accuracy_px=accuracy_px)
    animating = state is not None
    state = FrameState() if state is None else state
    start = time.perf_counter()
    view = view_from_camera(scene.camera, scene, depsgraph)
    ensure_gpu()
    state.update(scene, depsgraph, settings)
    planned_at = time.perf_counter()
    if animating:
        if state.renderer is not None:
            _prefetch(state.renderer, view, state.last_eye)
        state.last_eye = view.eye if view.is_perspective else None
    image, sbc, build_seconds, stats = None, None, 0.0, {"methods": {}, "warnings": []}
    if state.renderer is not None:  # else a scene of glass alone
        image, sbc, build_seconds = _mirrors_frame(scene, state, view, animating, trace_edges, trace_gaps)
        stats = {**(sbc.stats if sbc is not None else {}), **state.renderer.stats,
                 "methods": {c.reflector: c.method for c in state.plan.choices}, "warnings": state.warnings(view)}
    if state.glass is not None:
        started = time.perf_counter()
        glass_image, in_front = state.glass.render(view, state.world, settings.max_order)
        image = over(image, glass_image, in_front)
        stats["glass"] = {"pixels": int(in_front.sum()), "seconds": time.perf_counter() - started}
        if state.glass.nested:
            stats["warnings"].append(f"Glass inside other glass (seen through {', '.join(state.glass.nested)}): a ray "
                                     "leaving the inner glass is drawn as if it left into air")
    end = time.perf_counter()
    state.frames += 1
    seconds = {"capture": state.capture_seconds, "plan": planned_at - start - state.capture_seconds,
               "sbc": build_seconds,
               "draw": end - planned_at - build_seconds, "total": end - start,
               "trace": sbc.stats.get("trace_seconds", float("nan")) if sbc is not None else 0.0}
    return ReflectionRender(image, view, seconds, stats, sbc)


def _mirrors_frame(scene, state: FrameState, view: View, animating: bool, trace_edges: bool, trace_gaps: bool):
    """The mirrors' frame of ``view``: (image, the sample-based camera or None, seconds
    spent building it). The methods drawn per frame are checked in the frame (every
    :data:`CHECK_EVERY_FRAMES` frames of an animation), and the frame drawn again with the
    next method where one fails (each method once at most)."""
    checking = not animating or state.frames % CHECK_EVERY_FRAMES == 0
    build_seconds = 0.0
    while True:
        job = state.camera_job(view)
        if job is None or job.first_order_left_out:
            check_view_outside_reflectors(state.reflector_set, view)
        started = time.perf_counter()
        sbc = None if job is None else job.build()
        release_freed_memory()  # the ray map's and the trees' temporaries
        build_seconds += time.perf_counter() - started
        image = state.renderer.render(view, sbc, state.world, trace_edges=trace_edges, trace_gaps=trace_gaps)
        if not (checking and state.check_methods(scene, view, image)):
            return image, sbc, build_seconds


def _prefetch(renderer, view, last_eye) -> None:
    """Put on the GPU what the passes' worker finished during the last frame, and start
    the work of the next frames around this frame's camera (``FramePass.prefetch``): a
    frame's band trace and capture keep one core busy and leave the other to the worker,
    and an octree grid's node costs a fraction of a second of numpy, four or eight of
    them a frame that enters a new cell (docs/benchmarks/octree_animation.md). The cells the
    camera reaches in the next PREDICTED_FRAMES frames, if it keeps its last move, go
    first. Only work the main thread would do the same way (``exact``), so that a
    frame's image does not depend on which work was ready."""
    ahead = () if last_eye is None or not view.is_perspective else [
        view.eye + n * (view.eye - last_eye) for n in range(1, PREDICTED_FRAMES + 1)]
    for frame_pass in renderer.passes:
        frame_pass.collect()
        frame_pass.prefetch(view, prefetcher().submit, max_pending=PREFETCHED_NODES, exact=True, ahead=ahead)


def output_path(filepath: str) -> Path:
    """The PNG file ``filepath`` names (``//`` is the .blend file's folder; ``.png`` added
    where missing), or a ValueError saying what is wrong with it: a folder instead of a
    file, a folder that is a file, one that cannot be written, or a ``//`` path in a file
    never saved."""
    if filepath.startswith("//") and not bpy.data.filepath:
        raise ValueError(f"{filepath!r} is relative to the .blend file's folder, but the file is not saved yet; "
                         "save it or give a full path")
    if filepath.endswith(("/", "\\")) or Path(bpy.path.abspath(filepath)).is_dir():
        raise ValueError(f"{filepath!r} is a folder; give a file name in it, e.g. {filepath.rstrip('/')}/"
                         "reflections.png")
    path = Path(bpy.path.abspath(bpy.path.ensure_ext(filepath, ".png")))
    folder = path.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise ValueError(f"cannot write {str(path)!r}: {str(folder)!r} is a file, not a folder")
    if not os.access(folder, os.W_OK):
        raise ValueError(f"cannot write {str(path)!r}: the folder {str(folder)!r} is not writable")
    return path


def frame_filepath(filepath: str, frame: int) -> str:
    """The PNG path of ``frame``: the last run of ``#`` becomes the zero-padded frame
    number, as in Blender's output path; without ``#`` the number (4 digits) is appended."""
    path = bpy.path.ensure_ext(filepath, ".png")
    stem, extension = path[:-4], path[-4:]
    runs = list(re.finditer(r"#+", stem))
    if not runs:
        return f"{stem}{frame:04d}{extension}"
    run = runs[-1]
    return f"{stem[:run.start()]}{frame:0{len(run.group())}d}{stem[run.end():]}{extension}"


def _write(path: Path, result: ReflectionRender) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    write_png(path, result.display)


class CURVED_REFLECTIONS_OT_render_image(bpy.types.Operator):
    """Render the scene camera with curved reflections to a PNG image, or every frame of the animation"""

    bl_idname = "curved_reflections.render_image"
    bl_label = "Render Reflections Image"
    bl_options = {'REGISTER'}

    filepath: StringProperty(name="File Path", description="PNG file to write; for an animation, # characters "
                             "are the zero-padded frame number (else it is appended); // is the .blend file's folder",
                             subtype='FILE_PATH', options=BLEND_RELATIVE)
    filter_glob: StringProperty(default="*.png", options={'HIDDEN'})
    animation: BoolProperty(name="Animation", description="Render every frame from the scene's start to its end "
                            "frame, one PNG each", default=False)
    trace_gaps: BoolProperty(name="Trace Morphing Gaps", description="Ray trace the pixels of mirrors drawn from "
                             "their morphing grid that the grid leaves without a reflection (exact there, several "
                             "times slower)", default=False)
    #: Set by invoke: an animation started from the UI runs modally (progress, Esc cancels).
    interactive: BoolProperty(default=False, options={'HIDDEN', 'SKIP_SAVE'})

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    def invoke(self, context, event):
        if not self.filepath:
            self.filepath = "//reflections_####.png" if self.animation else "//reflections.png"
        self.interactive = True
        context.window_manager.fileselect_add(self)
        return {'RUNNING_MODAL'}

    def _render(self, context, path: Path) -> ReflectionRender | None:
        """One frame to ``path``; reports and returns None on bad input or a write error."""
        try:
            result = render_scene(context.scene, context.evaluated_depsgraph_get(), trace_gaps=self.trace_gaps,
                                  state=self._state)
        except (SceneInputError, RuntimeError) as error:  # RuntimeError: the GPU could not be initialised
            self.report({'ERROR'}, str(error))
            return None
        try:
            _write(path, result)
        except (OSError, RuntimeError) as error:
            self.report({'ERROR'}, f"Could not write {str(path)!r}: {error}")
            return None
        return result

    def execute(self, context):
        if not self.filepath:
            self.report({'ERROR'}, "No file path given for the image")
            return {'CANCELLED'}
        self._state = FrameState()
        if self.animation:
            scene = context.scene
            self._frames = list(range(scene.frame_start, scene.frame_end + 1, max(1, scene.frame_step)))
            self._original_frame = scene.frame_current
            self._done = 0
            self._seconds = 0.0
            if self.interactive and not bpy.app.background:
                context.window_manager.progress_begin(0, len(self._frames))
                self._timer = context.window_manager.event_timer_add(0.001, window=context.window)
                context.window_manager.modal_handler_add(self)
                return {'RUNNING_MODAL'}
            while self._done < len(self._frames):
                if not self._next_frame(context):
                    return self._finish(context, cancelled=True)
            return self._finish(context)
        try:
            path = output_path(self.filepath)
        except ValueError as error:
            self.report({'ERROR'}, str(error))
            return {'CANCELLED'}
        result = self._render(context, path)
        if result is None:
            return {'CANCELLED'}
        view, seconds = result.view, result.seconds
        self.report({'INFO'}, f"Rendered {view.width}x{view.height} with reflections to {str(path)!r} in "
                              f"{seconds['total']:.2f} s (camera {seconds['sbc']:.2f} s, "
                              f"drawing {seconds['draw']:.2f} s)")
        for message in result.stats["warnings"]:
            self.report({'WARNING'}, message)
        if "glass" in result.stats:
            self.report({'INFO'}, f"Glass ray traced on {result.stats['glass']['pixels']:,} pixels in "
                                  f"{result.stats['glass']['seconds']:.2f} s")
        untraced = result.stats.get("untraced_pixels", 0)
        if untraced:
            self.report({'WARNING'}, f"{untraced} mirror pixels without a reflection were filled, not ray traced "
                                     "(most of the mirror: does the camera's clip start cut into it?)")
        return {'FINISHED'}

    def _next_frame(self, context) -> bool:
        frame = self._frames[self._done]
        try:
            path = output_path(frame_filepath(self.filepath, frame))
        except ValueError as error:
            self.report({'ERROR'}, str(error))
            return False
        context.scene.frame_set(frame)
        result = self._render(context, path)
        if result is None:
            return False
        self._seconds += result.seconds["total"]
        self._done += 1
        return True

    def _finish(self, context, cancelled: bool = False):
        scene = context.scene
        scene.frame_set(self._original_frame)
        if getattr(self, "_timer", None) is not None:
            context.window_manager.event_timer_remove(self._timer)
            context.window_manager.progress_end()
            self._timer = None
        if cancelled:
            return {'CANCELLED'}
        per_frame = self._seconds / max(1, self._done)
        self.report({'INFO'}, f"Rendered {self._done} frames with reflections to "
                              f"{frame_filepath(self.filepath, self._frames[0])!r}... in {self._seconds:.1f} s "
                              f"({per_frame:.2f} s per frame)")
        return {'FINISHED'}

    def modal(self, context, event):
        if event.type == 'ESC':
            self.report({'WARNING'}, f"Animation cancelled after {self._done} of {len(self._frames)} frames")
            return self._finish(context, cancelled=True)
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        if not self._next_frame(context):
            return self._finish(context, cancelled=True)
        context.window_manager.progress_update(self._done)
        if self._done == len(self._frames):
            return self._finish(context)
        return {'RUNNING_MODAL'}


classes = (CURVED_REFLECTIONS_OT_render_image,)
