# SPDX-License-Identifier: GPL-3.0-or-later
"""The sample-based camera as a pass: its reflected triangles, made once per camera and
drawn every frame (SBC paper, Popescu, Sacks, Mei 2006, sections V-A and V-B).

A frame's camera arrives as a *projection source* (``Frame.source``: the camera's GPU
textures, ``sbc_gpu.SBCTextures``, or the camera projected in numpy,
``camera_source.CameraSource``). :class:`CameraPass` makes its
:class:`.sbc_triangles.CameraTriangles` with the renderer's
:class:`.sbc_triangles.CameraTriangleMaker` the first time that source is drawn, keeps
the last :data:`KEPT_CAMERAS` (one per viewport region), and draws them with
``glsl/reflection_mesh_vert.glsl``: in the camera's own view exactly at its projected
pixels; from a moved view (a new camera still building) each vertex at its first
reflector point, so the reflection stays on the mirror in world space instead of lagging
as pixels of the old view. It comes first among the renderer's passes and claims the
first-order reflections it drew (:meth:`CameraPass.claims`): the per-frame passes draw
only those the camera left to them.
"""

from __future__ import annotations

import gpu

from .. import draw_shaders
from ..frame_pass import Frame, FramePass
from ..gpu_data import vertex_buffer
from ..reflected_meshes import REFLECTION_COSINE, SNAP_SHARE, snap_grid
from ..screen_space import camera_position
from .sbc_gpu import SBCTextures
from .sbc_triangles import CameraTriangleMaker, CameraTriangles

#: Cameras whose reflected triangles are kept (one per viewport region that draws).
KEPT_CAMERAS = 8


class CameraPass(FramePass):
    """The reflected triangles of the sample-based cameras drawn over one renderer's
    meshes (``maker``, a :class:`CameraTriangleMaker`), the last :data:`KEPT_CAMERAS`
    kept, drawn for the frame's camera; ``n_reflectors``: every reflector of the scene,
    whose first orders the camera claims unless it left them to the per-frame passes."""

    name = "camera"

    def __init__(self, maker: CameraTriangleMaker, n_reflectors: int):
        self.maker = maker
        self.geometry = maker.geometry
        self.n_reflectors = int(n_reflectors)
        #: The triangles drawn last (kept after the frame: a second render of the same
        #: camera draws them again).
        self.last: CameraTriangles | None = None
        #: The frame's triangles (``None``: no camera this frame).
        self.current: CameraTriangles | None = None
        self._kept: dict = {}  # id(source) -> CameraTriangles, least recently drawn first

    @property
    def reflector_indices(self) -> list:
        return []

    def update(self, frame: Frame) -> None:
        """The triangles of the frame's camera: kept ones when its source was drawn
        before, else made now, in the camera's own view (``frame.camera``'s, else the
        source's)."""
        if frame.source is None:
            self.current = None
            return
        camera_view = frame.camera.ray_map.view if frame.camera is not None else frame.source.view
        self.current = self.triangles_of(frame.source, camera_view, frame.camera)
        if frame.camera is not None:
            self.current.camera = frame.camera

    def claims(self) -> frozenset:
        """Every reflector's first orders but those the camera left to the per-frame passes."""
        if self.current is None:
            return frozenset()
        return frozenset(range(self.n_reflectors)) - self.current.per_frame

    def answers(self) -> list:
        return []

    def draw(self, frame: Frame) -> None:
        """The frame's reflected triangles (SBC V-A's depth: lower orders first, the point
        nearer the mirror within an order), snapped within the Accuracy in a warm frame as
        the per-frame passes' vertices are, held to the same law-of-reflection test."""
        current = self.current
        if current is None or current.batch is None:
            return
        view, targets = frame.view, frame.targets
        size = (float(targets.width), float(targets.height))
        snap = SNAP_SHARE * frame.accuracy_px if frame.warm and frame.snap and frame.accuracy_px else 0.0
        shader = draw_shaders.shader("reflected")
        shader.bind()
        shader.uniform_float("view_projection", frame.world_to_clip)
        shader.uniform_float("view_size", size)
        shader.uniform_float("snap_grid", snap_grid((targets.width, targets.height), snap))
        shader.uniform_int("use_camera_pixel", int(view.same_as(current.camera_view)))
        shader.uniform_float("camera", camera_position(view, self.geometry.shift))
        shader.uniform_float("order_range", current.order_range)
        shader.uniform_float("reflection_cosine", REFLECTION_COSINE)
        shader.uniform_sampler("prepass_labels", targets.prepass_labels)
        shader.uniform_sampler("prepass_normals", targets.prepass_normals)
        for image, first, count in current.runs:
            shader.uniform_int("use_image", int(image >= 0))
            shader.uniform_sampler("image", frame.images(image))
            current.batch.draw_range(shader, elem_start=first, elem_count=count)

    def frame_stats(self) -> dict:
        """The frame's projection statistics (``projection_seconds``, vertex counts) and
        its mixed triangles (SBC V-B)."""
        if self.current is None:
            return {"mixed_triangles": 0}
        return {**self.current.stats, "mixed_triangles": self.current.mixed_triangles}

    def source_for(self, camera):
        """The projection source to draw ``camera`` with: the one its kept triangles were
        made from when the last frame drew this very camera, else its GPU textures."""
        last = self.last
        return last.source if last is not None and last.camera is camera else SBCTextures(camera)

    def triangles_of(self, source, camera_view, camera=None) -> CameraTriangles:
        """The reflected triangles of ``source``'s camera, built in ``camera_view``: the
        kept ones when they were made from this source, else made now."""
        kept = self._kept.get(id(source))
        if kept is None or kept.source is not source:
            batch = self.maker.vertex_points() if source.on_gpu else None
            kept = self._uploaded(self.maker.triangles(source, camera_view, camera, vertex_batch=batch))
        self._keep(kept)
        return kept

    def adopt(self, triangles: CameraTriangles) -> bool:
        """Keep ``triangles``, made by the maker elsewhere (a live view's worker thread,
        with a source that projects on the CPU), as its source's: they are put on the GPU
        now. False, and nothing kept, when the per-frame passes now draw other reflectors
        in its view than when they were made."""
        if triangles.per_frame != self.maker.per_frame_reflectors(triangles.camera_view):
            return False
        self._keep(self._uploaded(triangles))
        return True

    def holds(self, source) -> bool:
        """Whether the triangles of ``source`` are kept (a draw with it projects nothing)."""
        kept = self._kept.get(id(source))
        return kept is not None and kept.source is source

    def invalidate(self) -> None:
        """Forget the kept triangles: the next draw projects again."""
        self.last = self.current = None
        self._kept.clear()

    def _keep(self, triangles: CameraTriangles) -> None:
        self._kept.pop(id(triangles.source), None)
        while len(self._kept) >= KEPT_CAMERAS:
            self._kept.pop(next(iter(self._kept)))
        self._kept[id(triangles.source)] = triangles  # most recently used last
        self.last = triangles

    def _uploaded(self, triangles: CameraTriangles) -> CameraTriangles:
        """``triangles`` with their vertex arrays in one GPU vertex buffer (main thread)."""
        self.maker.counts["projections"] += 1
        if triangles.arrays is not None:
            buffer = vertex_buffer({name: (values, 'F32', 'FLOAT') for name, values in triangles.arrays.items()})
            triangles.batch, triangles.arrays = gpu.types.GPUBatch(type='TRIS', buf=buffer), None
        return triangles
