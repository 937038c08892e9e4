# SPDX-License-Identifier: GPL-3.0-or-later
"""The records of the live view (``live.py``): one scene's state, the camera of one
view, and a capture whose reflectors are being made ready on the worker."""

from __future__ import annotations

import weakref
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import ClassVar

from ..engine.frame_settings import FrameSettings
from ..engine.view import View
from .frame_pipeline import FramePipeline
from .scene_status import SceneStatus


@dataclass
class Tracing:
    """A camera's traced pixels (``traced_pixels.TracedPixels`` or None) on their way."""

    #: The renderer they are traced for (its meshes), weakly: a camera outlives a mesh
    #: edit's renderer, whose GPU textures must not outlive it here.
    renderer: weakref.ref
    future: Future
    redrawn: bool = False  # whether their landing asked for a redraw


@dataclass
class ViewCamera:
    """The sample-based camera of one view (``None`` when morphing grids draw every
    reflector), the grids covering the view, and their projection source once made
    (main thread)."""

    view: View
    sbc: object
    bounds: tuple
    settings: FrameSettings
    generation: int
    morph: list = field(default_factory=list)  # (MorphingGrid, matrix) of the grids covering the view
    source: object = None  # what the renderer projects with (made on the first draw: needs the GPU)
    last_drawn: float = 0.0
    #: (the renderer's CameraTriangleMaker, its CameraTriangles of this camera not yet on
    #: the GPU): made on the worker with the camera, adopted on the first draw.
    projected: tuple | None = None
    #: The pixels of the camera's unreliable cells, traced on a worker once the camera's
    #: own view is drawn (``live_traces.camera_traced``).
    tracing: Tracing | None = None

    def first_orders_drawn(self, per_frame_reflectors) -> bool:
        """Whether the per-frame passes (``per_frame_reflectors(view)``: the reflectors
        they draw in a view, asked only of a camera that left some out) still draw the
        first orders the camera left to them: a grid cleared or damaged since hands its
        reflector back, and the camera is built again."""
        left_out = frozenset() if self.sbc is None else self.sbc.first_order_left_out
        return not left_out or left_out <= per_frame_reflectors(self.view)


@dataclass
class CameraBuild:
    """A view's camera on its way (``live._start_camera``): what it is built for, and the
    renderer's triangle maker its reflected triangles are made with on the worker."""

    future: Future  # -> (SampleBasedCamera or None, its projection or None)
    view: View
    bounds: tuple
    settings: FrameSettings
    generation: int
    covering: list  # (MorphingGrid, matrix) of the grids covering the view
    maker: object  # the renderer's CameraTriangleMaker (its camera pass's)


@dataclass
class Preparing:
    """A capture whose reflectors are made ready for tracing on the worker (their BVH and
    seal, ``live_workers.prepare_reflectors``): the last reflections draw meanwhile."""

    future: Future
    captured: object
    started: float
    triangles: int


@dataclass
class LiveScene(FramePipeline):
    """Everything live about one scene (keyed by ``scene.session_uid``): the frame
    pipeline's capture, plan, grids and renderer, and the scheduling around it."""

    reflector_names: frozenset = frozenset()
    cameras: dict = field(default_factory=dict)  # view key -> ViewCamera
    jobs: dict = field(default_factory=dict)  # view key -> CameraBuild
    requests: dict = field(default_factory=dict)  # view key -> (View, time of the request)
    failed: dict = field(default_factory=dict)  # view key -> View whose camera could not be built
    generation: int = 0  # bumped by every capture of the reflectors: older cameras are stale
    preparing: object = None  # Preparing: a capture whose reflectors are made ready on the worker
    scene_status: SceneStatus = field(default_factory=SceneStatus)  # the panel's store of this scene
    dirty_reflectors: bool = False
    dirty_meshes: bool = False
    drawing: bool = True  # False after a draw failed, until the next bake or refresh
    status: str = ""
    level: str = 'INFO'  # 'INFO', 'WARNING' or 'ERROR'
    stats: dict = field(default_factory=dict)
    counts: dict = field(default_factory=lambda: {"captures": 0, "remeshes": 0, "builds": 0, "draws": 0,
                                                  "projections": 0, "checks": 0})
    #: The last view drawn, when it was first drawn, the camera it was drawn with, and
    #: whether its accuracy has been checked (``accuracy.measure`` once it settles).
    last_view: tuple | None = None
    #: (the check of the last view running on a worker, the renderer it measures).
    checking: tuple | None = None
    #: The renderer whose chosen modes' picture was checked (``live_check.check_picture_at_rest``).
    picture_checked: object = None
    #: The band of the last resting view, traced (``live_traces.BandTrace``).
    band: object = None
    SEARCHES_GLASS: ClassVar[bool] = True

    def report(self, level: str, message: str) -> None:
        self.level, self.status = level, message
