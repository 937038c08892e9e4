# SPDX-License-Identifier: GPL-3.0-or-later
"""Drawing curved reflections: the scene, its reflected meshes, and their composite.

SBC paper (Popescu, Sacks, Mei 2006), section V: a reflection is drawn for every
diffuse mesh in every reflection group by projecting the mesh's vertices with the
sample-based camera on the GPU and rasterising the reflected ("virtual") triangles.
Three passes, all into float targets of the view's size:

1. **Pre-pass** (visibility case 1 of SBC V-A): every diffuse mesh and every reflector
   with the depth test, into a colour target (diffuse meshes flat at their vertex
   colour, unlit; reflectors at their own colour) and a label target (id, reflectivity):
   id 0 for diffuse meshes (and nothing), reflector index + 1 for reflectors. Blender's
   Python ``gpu`` module has no stencil, so the id texture plays the stencil of Roger &
   Holzschuch 2006, section 3.3.6.
2. **Reflections**, per reflection history and its sheets (``SampleBasedCamera.groups``:
   one history per sheet, a history repeating when its rays cross in space), in two
   kinds of draw:

   a. *vertex projection*: every vertex of the (pre-subdivided, SBC V-B,
      :mod:`.subdivision`) diffuse meshes is projected once per sheet with
      ``sbc_project`` (``glsl/sbc_projection.glsl``); pixel, depth and validity land in
      texel ``gl_VertexID`` of the sheet's layer of a float target;
   b. *triangles*, per sheet: the meshes are drawn un-indexed, every vertex carrying
      its triangle's three corner indices; it reads the three projections and
      collapses the triangle unless every corner projects (SBC V-B: a triangle is drawn
      only when all three vertices project). Projecting per vertex first, instead of
      three corners per drawn vertex, costs one projection per mesh vertex and makes the
      decision identical for the triangle's three vertices. Across the seam between
      two sheets of one history a corner may take its projection from the neighbouring
      sheet, within a few ray-map cells (``glsl/reflection_mesh_vert.glsl``), so seams
      do not open cracks. The depth is SBC V-A's offset (k - 1 + z / D) g: within a
      sheet the point nearer the mirror along the reflected ray wins (case 2), lower
      orders before higher ones (case 3), one depth buffer for all sheets. The fragment
      stage keeps only pixels whose pre-pass id is the sheet's first reflector
      (history[0] + 1): reflections stay inside the visible footprint of their
      reflector, and real objects in front of a mirror stay in front.
3. **Composite** (SBC V-D): on reflector pixels, the reflection where one was drawn,
   else the world colour, mixed with the reflector's own colour by its reflectivity
   (1 = perfect mirror); elsewhere the pre-pass colour (or nothing, for a viewport
   overlay: ``reflectors_only``).

The sample-based camera cannot place a reflection in the last ray-map cell before a
footprint's edge (the silhouette, or an object in front of the mirror): a projection
needs four neighbouring rays. :meth:`ReflectionRenderer.render` ray traces that band,
d pixels wide, on the CPU (:mod:`.band_trace`); :meth:`ReflectionRenderer.draw` (no
read-back, for a viewport) fills it from the nearest reflected pixel instead.
Optionally (``trace_edges``) the pixels next to a drawn reflection that got none are
traced too, which stands in for the subdivision of mixed triangles.

Not done yet: mixed triangles (one or two corners projected in any sheet) are dropped,
not subdivided (SBC V-B); no Fresnel or distance attenuation of the reflectivity (SBC
V-D); non-emissive materials are drawn unlit at their base colour (no lighting, SBC
V-C); creases of a reflector (a lid's rim) leave a line of pixels without reflection.

:class:`ReflectionRenderer` holds one scene's geometry (subdivided once) and its GPU
batches; :meth:`ReflectionRenderer.draw` draws any view with any sample-based camera of
it and composites into the framebuffer that is bound, so a viewport draw handler can
call it with the region's matrices (``operators.capture.view_from_region``);
:meth:`ReflectionRenderer.render` draws offscreen and reads the image back.

Shaders are built on first use and cached, never at import or register time. Push
constants stay far below 128 bytes (:data:`PUSH_CONSTANT_BYTES`); the cameras travel in
textures (``projection.SBCTextures``).
"""

from __future__ import annotations

import contextlib
import functools
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..addon import band_trace, subdivision
from . import projection

_GLSL = Path(__file__).resolve().parent / "glsl"

#: Bytes of push constants per shader (Vulkan guarantees 128): the pre-pass's matrix is
#: the largest; everything bigger (the cameras, the pre-pass images) is in textures.
PUSH_CONSTANT_BYTES = {
    "prepass": 64,  # mat4 view_projection
    # int group, order, layer_offset; ivec2 target_size; float inverse_diameter, order_range
    "project": 4 + 4 + 4 + 8 + 4 + 4,
    # ivec2 projected_size; vec2 view_size; int first_reflector_id, own_layer, n_layers, layer_size; float stitch_px
    "mesh": 8 + 8 + 4 + 4 + 4 + 4 + 4,
    "composite": 16 + 4 + 4 + 8,  # vec4 world_color; int reflectors_only, fill_radius; ivec2 origin
}
#: Float targets hold vertex indices exactly below 2^24.
MAX_VERTICES = 1 << 24
#: Texels of the vertex projection target (16 bytes each): the sheets of one history
#: are projected side by side (for stitching) as far as this allows.
MAX_PROJECTED_TEXELS = 1 << 22
#: A triangle across a seam between sheets joins a corner from another sheet only
#: within this many ray-map cells (times the down-sampling, in pixels) of its own corner.
STITCH_CELLS = 8

_COMPOSITE_VERTEX = """
/* One triangle covering the whole target. */
void main()
{
  gl_Position = vec4(position, 0.0, 1.0);
}
"""


def _source(name: str) -> str:
    return (_GLSL / name).read_text(encoding="utf-8")


def _shader(name: str):
    """The named shader of this module, built on first use and cached."""
    return _BUILDERS[name]()


@functools.cache
def _build_prepass():
    import gpu

    interface = gpu.types.GPUStageInterfaceInfo("curved_reflections_prepass_interface")
    interface.smooth('VEC4', "color_interp")
    interface.flat('VEC2', "label_interp")
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('MAT4', "view_projection")
    info.vertex_in(0, 'VEC3', "position")
    info.vertex_in(1, 'VEC4', "color")
    info.vertex_in(2, 'VEC2', "label")
    info.vertex_out(interface)
    info.fragment_out(0, 'VEC4', "color_out")
    info.fragment_out(1, 'VEC4', "label_out")
    info.vertex_source(_source("reflection_prepass_vert.glsl"))
    info.fragment_source(_source("reflection_prepass_frag.glsl"))
    return gpu.shader.create_from_info(info)


@functools.cache
def _build_project():
    import gpu

    interface = gpu.types.GPUStageInterfaceInfo("curved_reflections_project_interface")
    interface.flat('VEC4', "projected")
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('INT', "group")
    info.push_constant('INT', "order")
    info.push_constant('INT', "layer_offset")
    info.push_constant('IVEC2', "target_size")
    info.push_constant('FLOAT', "inverse_diameter")
    info.push_constant('FLOAT', "order_range")
    projection.declare_samplers(info)
    info.vertex_in(0, 'VEC3', "position")
    info.vertex_out(interface)
    info.fragment_out(0, 'VEC4', "projected_out")
    info.vertex_source(projection.library_source() + _source("reflection_project_vert.glsl"))
    info.fragment_source(_source("reflection_project_frag.glsl"))
    return gpu.shader.create_from_info(info)


@functools.cache
def _build_mesh():
    import gpu

    interface = gpu.types.GPUStageInterfaceInfo("curved_reflections_mesh_interface")
    interface.smooth('VEC4', "color_interp")
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('IVEC2', "projected_size")
    info.push_constant('VEC2', "view_size")
    info.push_constant('INT', "first_reflector_id")
    info.push_constant('INT', "own_layer")
    info.push_constant('INT', "n_layers")
    info.push_constant('INT', "layer_size")
    info.push_constant('FLOAT', "stitch_px")
    info.sampler(0, 'FLOAT_2D', "projected_vertices")
    info.sampler(1, 'FLOAT_2D', "prepass_labels")
    info.vertex_in(0, 'IVEC3', "corners")
    info.vertex_in(1, 'INT', "corner")
    info.vertex_in(2, 'VEC4', "color")
    info.vertex_out(interface)
    info.fragment_out(0, 'VEC4', "color_out")
    info.vertex_source(_source("reflection_mesh_vert.glsl"))
    info.fragment_source(_source("reflection_mesh_frag.glsl"))
    return gpu.shader.create_from_info(info)


@functools.cache
def _build_composite():
    import gpu

    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('VEC4', "world_color")
    info.push_constant('INT', "reflectors_only")
    info.push_constant('INT', "fill_radius")
    info.push_constant('IVEC2', "origin")
    info.sampler(0, 'FLOAT_2D', "prepass_colors")
    info.sampler(1, 'FLOAT_2D', "prepass_labels")
    info.sampler(2, 'FLOAT_2D', "reflection_colors")
    info.sampler(3, 'FLOAT_2D', "traced_colors")
    info.vertex_in(0, 'VEC2', "position")
    info.fragment_out(0, 'VEC4', "color_out")
    info.vertex_source(_COMPOSITE_VERTEX)
    info.fragment_source(_source("reflection_composite_frag.glsl"))
    return gpu.shader.create_from_info(info)


_BUILDERS = {"prepass": _build_prepass, "project": _build_project, "mesh": _build_mesh,
             "composite": _build_composite}


# --- geometry (numpy) ---------------------------------------------------------------


@dataclass(frozen=True)
class DrawGeometry:
    """What the passes draw, as arrays (no GPU needed to build it).

    Pre-pass: every diffuse mesh, then every reflector, in one indexed triangle list;
    positions relative to ``shift``. Reflected meshes: all diffuse meshes subdivided
    (:mod:`.subdivision`) and concatenated, world positions.
    """

    shift: np.ndarray  # (3,) float64
    prepass_positions: np.ndarray  # (P, 3) float32, relative to shift
    prepass_colors: np.ndarray  # (P, 4) float32 linear RGBA
    prepass_labels: np.ndarray  # (P, 2) float32 (id, reflectivity)
    prepass_triangles: np.ndarray  # (Tp, 3) int32
    vertices: np.ndarray  # (V, 3) float64, reflected meshes
    colors: np.ndarray  # (V, 4) float32
    triangles: np.ndarray  # (T, 3) int64
    diameter: float  # bounding-box diagonal of everything: bounds every reflected ray distance
    stats: dict = field(default_factory=dict)


def prepare_geometry(reflectors, meshes, reflector_colors=None, reflectivity=None,
                     edge_fraction: float = subdivision.EDGE_FRACTION) -> DrawGeometry:
    """Arrays of one scene for :class:`ReflectionRenderer`.

    ``reflector_colors`` (R, 3 or 4) linear, default white; ``reflectivity`` (R,) in
    [0, 1], default 1 (perfect mirrors). ``edge_fraction`` sets the pre-subdivision
    (:func:`subdivision.subdivide`); ``None`` draws the meshes as they are.
    """
    start = time.perf_counter()
    reflectors, meshes = list(reflectors), list(meshes)
    n_reflectors = len(reflectors)
    colors = np.ones((n_reflectors, 4), np.float32)
    if reflector_colors is not None:
        given = np.asarray(reflector_colors, dtype=np.float32).reshape(n_reflectors, -1)
        colors[:, :given.shape[1]] = given[:, :4]
    mirror = np.ones(n_reflectors, np.float32) if reflectivity is None else np.clip(
        np.asarray(reflectivity, dtype=np.float32).reshape(n_reflectors), 0.0, 1.0)

    parts = [(m.vertices, m.triangles, m.colors, (0.0, 1.0)) for m in meshes]
    parts += [(r.vertices, r.triangles, colors[k], (k + 1.0, mirror[k])) for k, r in enumerate(reflectors)]
    everything = np.concatenate([p[0] for p in parts]) if parts else np.zeros((1, 3))
    lo, hi = everything.min(axis=0), everything.max(axis=0)
    shift = 0.5 * (lo + hi)
    positions, vertex_colors, labels, triangles, offset = [], [], [], [], 0
    for vertices, tris, color, label in parts:
        positions.append((vertices - shift).astype(np.float32))
        vertex_colors.append(np.broadcast_to(np.asarray(color, np.float32), (len(vertices), 4)))
        labels.append(np.broadcast_to(np.asarray(label, np.float32), (len(vertices), 2)))
        triangles.append(np.asarray(tris, dtype=np.int64) + offset)
        offset += len(vertices)

    centres, radii = subdivision.reflector_spheres(reflectors)
    vertices, mesh_colors, mesh_triangles, offset = [], [], [], 0
    for mesh in meshes:
        v, t, c = mesh.vertices, mesh.triangles, mesh.colors
        if edge_fraction is not None:
            v, t, c = subdivision.subdivide(v, t, c, centres, radii, edge_fraction)
        vertices.append(v)
        mesh_colors.append(c)
        mesh_triangles.append(t + offset)
        offset += len(v)
    if offset >= MAX_VERTICES:
        raise ValueError(f"{offset} reflected vertices: float targets index below 2^24 only")
    geometry = DrawGeometry(
        shift=shift,
        prepass_positions=np.concatenate(positions) if positions else np.zeros((0, 3), np.float32),
        prepass_colors=np.concatenate(vertex_colors) if vertex_colors else np.zeros((0, 4), np.float32),
        prepass_labels=np.concatenate(labels) if labels else np.zeros((0, 2), np.float32),
        prepass_triangles=(np.concatenate(triangles) if triangles else np.zeros((0, 3))).astype(np.int32),
        vertices=np.concatenate(vertices) if vertices else np.zeros((0, 3)),
        colors=np.concatenate(mesh_colors).astype(np.float32) if mesh_colors else np.zeros((0, 4), np.float32),
        triangles=np.concatenate(mesh_triangles) if mesh_triangles else np.zeros((0, 3), np.int64),
        diameter=float(max(np.linalg.norm(hi - lo), 1e-9)),
    )
    geometry.stats.update({
        "mesh_triangles": int(sum(len(m.triangles) for m in meshes)),
        "reflected_triangles": int(len(geometry.triangles)),
        "reflected_vertices": int(len(geometry.vertices)),
        "prepare_seconds": time.perf_counter() - start,
    })
    return geometry


# --- GPU resources ------------------------------------------------------------------


class FrameTargets:
    """Float textures and framebuffers of one frame size (reusable from frame to frame)."""

    def __init__(self, width: int, height: int, n_vertices: int, layers: int = 1):
        import gpu

        self.width, self.height, self.n_vertices = int(width), int(height), int(n_vertices)
        self.layers = max(1, int(layers))
        size = (self.width, self.height)
        self.prepass_colors = gpu.types.GPUTexture(size, format='RGBA32F')
        self.prepass_labels = gpu.types.GPUTexture(size, format='RGBA32F')
        self.prepass_depth = gpu.types.GPUTexture(size, format='DEPTH_COMPONENT32F')
        self.prepass = gpu.types.GPUFrameBuffer(depth_slot=self.prepass_depth,
                                                color_slots=(self.prepass_colors, self.prepass_labels))
        self.reflection_colors = gpu.types.GPUTexture(size, format='RGBA32F')
        self.reflection_depth = gpu.types.GPUTexture(size, format='DEPTH_COMPONENT32F')
        self.reflection = gpu.types.GPUFrameBuffer(depth_slot=self.reflection_depth,
                                                   color_slots=(self.reflection_colors,))
        texels = self.layers * self.n_vertices
        columns = max(1, min(texels, projection.sbc_pack.TEXTURE_WIDTH))
        self.projected_size = (columns, max(1, -(-texels // columns)))
        self.projected = gpu.types.GPUTexture(self.projected_size, format='RGBA32F')
        self.projected_framebuffer = gpu.types.GPUFrameBuffer(color_slots=(self.projected,))
        zero = np.zeros(4, np.float32)
        self.no_trace = gpu.types.GPUTexture((1, 1), format='RGBA32F', data=gpu.types.Buffer('FLOAT', 4, zero))
        self.traced = None  # RGBA32F of the traced band of the last frame, or None
        self._output = None

    def fits(self, width: int, height: int, n_vertices: int, layers: int = 1) -> bool:
        return ((self.width, self.height, self.n_vertices) == (int(width), int(height), int(n_vertices))
                and self.layers >= layers)

    @property
    def output(self):
        """(texture, framebuffer) that :meth:`ReflectionRenderer.render` composites into."""
        if self._output is None:
            import gpu

            texture = gpu.types.GPUTexture((self.width, self.height), format='RGBA32F')
            self._output = (texture, gpu.types.GPUFrameBuffer(color_slots=(texture,)))
        return self._output


def _vertex_buffer(attributes: dict):
    """A GPUVertBuf from {name: (array, comp_type, fetch_mode)}."""
    import gpu

    vertex_format = gpu.types.GPUVertFormat()
    count = None
    for name, (array, comp_type, fetch_mode) in attributes.items():
        width = 1 if array.ndim == 1 else array.shape[1]
        vertex_format.attr_add(id=name, comp_type=comp_type, len=width, fetch_mode=fetch_mode)
        count = len(array)
    buffer = gpu.types.GPUVertBuf(vertex_format, count)
    for name, (array, _, _) in attributes.items():
        buffer.attr_fill(name, np.ascontiguousarray(array))
    return buffer


def _read_texture(texture, width: int, height: int) -> np.ndarray:
    """(H, W, 4) float32 of an RGBA32F texture, rows bottom to top."""
    data = texture.read()
    data.dimensions = width * height * 4
    return np.asarray(data, dtype=np.float32).reshape(height, width, 4)


def _rgba(color) -> tuple:
    values = tuple(float(c) for c in color)[:4]
    return values + (1.0,) * (4 - len(values))


@contextlib.contextmanager
def _saved_state():
    """Restore viewport, depth test, depth writes and blending (a draw handler's state)."""
    import gpu

    saved = (gpu.state.viewport_get(), gpu.state.depth_test_get(), gpu.state.depth_mask_get(),
             gpu.state.blend_get())
    try:
        yield
    finally:
        gpu.state.viewport_set(*saved[0])
        gpu.state.depth_test_set(saved[1])
        gpu.state.depth_mask_set(saved[2])
        gpu.state.blend_set(saved[3])


def _sheet_chunks(histories: list, capacity: int) -> list:
    """Sheet indices grouped by history (first appearance order), in chunks of at most
    ``capacity`` sheets: the sheets projected side by side and stitched together."""
    by_history: dict = {}
    for sheet, history in enumerate(histories):
        by_history.setdefault(tuple(history), []).append(sheet)
    return [sheets[k:k + capacity] for sheets in by_history.values() for k in range(0, len(sheets), capacity)]


class ReflectionRenderer:
    """One scene's reflected geometry and GPU batches; draws it for any view and camera.

    Build it once per scene change (subdivision runs here, once per mesh); call
    :meth:`draw` or :meth:`render` per frame with that frame's view and its
    sample-based camera in textures (``projection.SBCTextures``).
    """

    def __init__(self, reflectors, meshes, reflector_colors=None, reflectivity=None,
                 edge_fraction: float | None = subdivision.EDGE_FRACTION):
        self.geometry = prepare_geometry(reflectors, meshes, reflector_colors, reflectivity, edge_fraction)
        self.stats = dict(self.geometry.stats)
        self._reflectors, self._meshes = list(reflectors), list(meshes)
        self._batches = None
        self._targets = None
        self._tracer = None

    def _make_batches(self) -> dict:
        import gpu

        g = self.geometry
        batches = {}
        if len(g.prepass_triangles):
            buffer = _vertex_buffer({"position": (g.prepass_positions, 'F32', 'FLOAT'),
                                     "color": (g.prepass_colors, 'F32', 'FLOAT'),
                                     "label": (g.prepass_labels, 'F32', 'FLOAT')})
            index = gpu.types.GPUIndexBuf(type='TRIS', seq=g.prepass_triangles)
            batches["prepass"] = gpu.types.GPUBatch(type='TRIS', buf=buffer, elem=index)
        if len(g.triangles):
            points = _vertex_buffer({"position": (g.vertices.astype(np.float32), 'F32', 'FLOAT')})
            batches["points"] = gpu.types.GPUBatch(type='POINTS', buf=points)
            corners = np.repeat(g.triangles.astype(np.int32), 3, axis=0)
            buffer = _vertex_buffer({
                "corners": (corners, 'I32', 'INT'),
                "corner": (np.tile(np.arange(3, dtype=np.int32), len(g.triangles)), 'I32', 'INT'),
                "color": (g.colors[g.triangles.reshape(-1)], 'F32', 'FLOAT'),
            })
            batches["mesh"] = gpu.types.GPUBatch(type='TRIS', buf=buffer)
        screen = _vertex_buffer({"position": (np.array([[-1, -1], [3, -1], [-1, 3]], np.float32), 'F32', 'FLOAT')})
        batches["screen"] = gpu.types.GPUBatch(type='TRIS', buf=screen)
        return batches

    def targets(self, width: int, height: int, layers: int = 1) -> FrameTargets:
        """The frame targets for this size (and at least ``layers`` projection layers),
        reused while they fit."""
        n_vertices = len(self.geometry.vertices)
        if self._targets is None or not self._targets.fits(width, height, n_vertices, layers):
            self._targets = FrameTargets(width, height, n_vertices, layers)
        return self._targets

    def draw(self, view, textures, world_color=(0.0, 0.0, 0.0, 1.0), reflectors_only: bool = False,
             fill_radius: int | None = None) -> FrameTargets:
        """Pre-pass and reflections of ``view`` into the frame targets
        (:meth:`draw_passes`), then the composite into the framebuffer bound by the
        caller (:meth:`composite`). What a viewport draw handler calls, with the
        region's view (``operators.capture.view_from_region``); nothing is read back.

        ``textures`` is the view's sample-based camera as ``projection.SBCTextures``;
        ``world_color`` the linear RGB(A) that reflected rays leaving the scene show;
        ``fill_radius`` the composite's cheap fill of the band along a footprint's edge
        (``None``: the camera's down-sampling), where :meth:`render` traces instead.
        """
        import gpu

        targets = self.draw_passes(view, textures)
        if fill_radius is None:
            fill_radius = textures.packed.downsample
        x, y, width, height = gpu.state.viewport_get()
        # A viewport of the view's size is drawn into where it is; otherwise from (0, 0).
        origin = (x, y) if (width, height) == (targets.width, targets.height) else None
        self.composite(targets, world_color, reflectors_only, fill_radius, origin)
        return targets

    def draw_passes(self, view, textures) -> FrameTargets:
        """The pre-pass and every sheet's reflection into the frame targets of ``view``'s size."""
        import gpu
        from mathutils import Matrix

        if self._batches is None:
            self._batches = self._make_batches()
        batches, g = self._batches, self.geometry
        histories = list(textures.groups)
        chunks = _sheet_chunks(histories, max(1, MAX_PROJECTED_TEXELS // max(1, len(g.vertices))))
        targets = self.targets(view.width, view.height, max((len(c) for c in chunks), default=1))
        width, height = targets.width, targets.height
        stitch_px = STITCH_CELLS * textures.packed.downsample
        translate = np.eye(4)
        translate[:3, 3] = g.shift
        view_projection = np.asarray(view.projection_matrix) @ np.asarray(view.view_matrix) @ translate
        order_range = 1.0 / (max((len(h) for h in histories), default=1) + 1)
        with _saved_state():
            gpu.state.blend_set('NONE')
            gpu.state.face_culling_set('NONE')  # mirrors are two-sided; reflections flip winding
            with targets.prepass.bind():
                gpu.state.viewport_set(0, 0, width, height)
                targets.prepass.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
                if "prepass" in batches:
                    gpu.state.depth_test_set('LESS_EQUAL')
                    gpu.state.depth_mask_set(True)
                    shader = _shader("prepass")
                    shader.bind()
                    shader.uniform_float("view_projection", Matrix(view_projection.tolist()))
                    batches["prepass"].draw(shader)
            with targets.reflection.bind():
                gpu.state.viewport_set(0, 0, width, height)
                targets.reflection.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            if "mesh" in batches:
                for sheets in chunks:
                    self._draw_history(targets, textures, sheets, histories[sheets[0]], order_range, stitch_px)
        targets.traced = None
        return targets

    def composite(self, targets: FrameTargets, world_color=(0.0, 0.0, 0.0, 1.0), reflectors_only: bool = False,
                  fill_radius: int = 0, origin=None) -> None:
        """The composite of the frame targets into the framebuffer bound by the caller;
        traced band colours (``targets.traced``, see :meth:`trace_band`) when present.

        ``origin``: the framebuffer pixel of the view's corner when the caller's viewport
        (left as it is) already covers the view; ``None`` draws at (0, 0)."""
        import gpu

        if self._batches is None:
            self._batches = self._make_batches()
        with _saved_state():
            gpu.state.blend_set('NONE')
            gpu.state.depth_test_set('NONE')
            if origin is None:
                gpu.state.viewport_set(0, 0, targets.width, targets.height)
                origin = (0, 0)
            shader = _shader("composite")
            shader.bind()
            world = tuple(float(c) for c in world_color)[:4]
            shader.uniform_float("world_color", world + (1.0,) * (4 - len(world)))
            shader.uniform_int("reflectors_only", int(bool(reflectors_only)))
            shader.uniform_int("fill_radius", max(0, int(fill_radius)))
            shader.uniform_int("origin", (int(origin[0]), int(origin[1])))
            shader.uniform_sampler("prepass_colors", targets.prepass_colors)
            shader.uniform_sampler("prepass_labels", targets.prepass_labels)
            shader.uniform_sampler("reflection_colors", targets.reflection_colors)
            shader.uniform_sampler("traced_colors", targets.traced if targets.traced is not None else targets.no_trace)
            self._batches["screen"].draw(shader)

    def trace_band(self, view, targets: FrameTargets, max_order: int, world_color, radius: int,
                   edges_of_drawn: bool = False) -> int:
        """Trace the reflector pixels along each footprint's edge that got no reflection
        (:mod:`.band_trace`): reads the pre-pass ids and the reflection coverage back,
        traces those pixels on the CPU and uploads their colours for the composite.
        Returns how many pixels were traced."""
        import gpu

        if self._tracer is None:
            self._tracer = band_trace.BandTracer(self._reflectors, self._meshes)
        labels = _read_texture(targets.prepass_labels, targets.width, targets.height)[..., 0]
        drawn = _read_texture(targets.reflection_colors, targets.width, targets.height)[..., 3] > 0.5
        pixels = band_trace.band_pixels(labels, drawn, radius, edges_of_drawn)
        traced = np.zeros((targets.height, targets.width, 4), np.float32)
        if len(pixels):
            colors = self._tracer.trace(view, pixels + 0.5, max_order, _rgba(world_color))
            traced[pixels[:, 1], pixels[:, 0], :3] = colors[:, :3]
            traced[pixels[:, 1], pixels[:, 0], 3] = 1.0
        data = gpu.types.Buffer('FLOAT', traced.size, traced.reshape(-1))
        targets.traced = gpu.types.GPUTexture((targets.width, targets.height), format='RGBA32F', data=data)
        return int(len(pixels))

    def _draw_history(self, targets: FrameTargets, textures, sheets: list, history, order_range: float,
                      stitch_px: float):
        """Project every vertex in each of ``sheets`` (sheets of one history) into its own
        layer, then draw each sheet's triangles, stitched across the seams between them."""
        import gpu

        batches = self._batches
        columns, rows = targets.projected_size
        n_vertices = len(self.geometry.vertices)
        with targets.projected_framebuffer.bind():
            gpu.state.viewport_set(0, 0, columns, rows)
            targets.projected_framebuffer.clear(color=(0.0, 0.0, 0.0, 0.0))
            gpu.state.depth_test_set('NONE')
            gpu.state.program_point_size_set(True)
            try:
                shader = _shader("project")
                shader.bind()
                shader.uniform_int("order", len(history))
                shader.uniform_int("target_size", (columns, rows))
                shader.uniform_float("inverse_diameter", 1.0 / self.geometry.diameter)
                shader.uniform_float("order_range", order_range)
                textures.bind(shader)
                for layer, group in enumerate(sheets):
                    shader.uniform_int("group", group)
                    shader.uniform_int("layer_offset", layer * n_vertices)
                    batches["points"].draw(shader)
            finally:
                gpu.state.program_point_size_set(False)
        with targets.reflection.bind():
            gpu.state.viewport_set(0, 0, targets.width, targets.height)
            gpu.state.depth_test_set('LESS')
            gpu.state.depth_mask_set(True)
            shader = _shader("mesh")
            shader.bind()
            shader.uniform_int("projected_size", (columns, rows))
            shader.uniform_float("view_size", (float(targets.width), float(targets.height)))
            shader.uniform_int("first_reflector_id", int(history[0]) + 1)
            shader.uniform_int("n_layers", len(sheets))
            shader.uniform_int("layer_size", n_vertices)
            shader.uniform_float("stitch_px", float(stitch_px))
            shader.uniform_sampler("projected_vertices", targets.projected)
            shader.uniform_sampler("prepass_labels", targets.prepass_labels)
            for layer in range(len(sheets)):
                shader.uniform_int("own_layer", layer)
                batches["mesh"].draw(shader)

    def render(self, view, sbc_or_textures, world_color=(0.0, 0.0, 0.0, 1.0), trace: bool = True,
               fill_radius: int | None = None, trace_edges: bool = False) -> np.ndarray:
        """Draw ``view`` offscreen and read it back: (H, W, 4) float32 linear RGBA, rows bottom to top.

        ``sbc_or_textures``: a ``SampleBasedCamera`` built for this view, or its
        ``projection.SBCTextures``. With ``trace`` the band along each footprint's edge
        that the camera cannot reach (d pixels wide) is ray traced (:meth:`trace_band`);
        without, it gets the composite's fill (``fill_radius``, ``None``: d). With
        ``trace_edges`` also the reflector pixels within d of a drawn reflection that got
        none: the staircase left by dropped mixed triangles (SBC V-B), seams and creases;
        exact there, but no longer a purely feed-forward image (measured on the demo
        scenes at 320x240: 15-18 % of the mirror pixels traced, disagreement with Cycles
        1.4-2.1 % instead of 1.7-5.9 %).
        """
        start = time.perf_counter()
        textures = sbc_or_textures
        if not isinstance(textures, projection.SBCTextures):
            textures = projection.SBCTextures(sbc_or_textures)
        uploaded = time.perf_counter()
        downsample = textures.packed.downsample
        targets = self.draw_passes(view, textures)
        drawn = time.perf_counter()
        traced = 0
        if trace and textures.n_groups:
            max_order = max(len(h) for h in textures.groups)
            traced = self.trace_band(view, targets, max_order, world_color, downsample, trace_edges)
            fill_radius = 0
        elif fill_radius is None:
            fill_radius = downsample
        band = time.perf_counter()
        texture, framebuffer = targets.output
        with framebuffer.bind():
            self.composite(targets, world_color, False, fill_radius)
        image = _read_texture(texture, targets.width, targets.height)
        end = time.perf_counter()
        self.stats.update({"upload_seconds": uploaded - start, "pass_seconds": drawn - uploaded,
                           "band_seconds": band - drawn, "composite_seconds": end - band,
                           "draw_seconds": end - start, "traced_pixels": traced})
        return image


def render_offscreen(reflectors, meshes, view, sbc, world_color=(0.0, 0.0, 0.0, 1.0), reflector_colors=None,
                     reflectivity=None, edge_fraction: float | None = subdivision.EDGE_FRACTION):
    """One offscreen frame of ``view`` with reflections: ``(image, renderer)``, the image
    (H, W, 4) float32 linear RGBA, the renderer's ``stats`` the timings and counts.

    ``sbc`` is the view's sample-based camera (built with bounds from
    ``addon.scene.scene_bounds`` of the same reflectors and meshes, with a margin).
    """
    renderer = ReflectionRenderer(reflectors, meshes, reflector_colors, reflectivity, edge_fraction)
    return renderer.render(view, sbc, world_color), renderer
