# SPDX-License-Identifier: GPL-3.0-or-later
"""Drawing curved reflections: the scene, its reflected meshes, and their composite.

SBC paper (Popescu, Sacks, Mei 2006), section V: a reflection is drawn for every
diffuse mesh in every reflection group by projecting the mesh's vertices with the
sample-based camera on the GPU and rasterising the reflected ("virtual") triangles.
Three passes, all into float targets of the view's size:

1. **Pre-pass** (visibility case 1 of SBC V-A): every diffuse mesh and every reflector
   with the depth test, into a colour target (diffuse meshes shaded as their
   reflections are, below, with the desired view's eye vector; reflectors at their own
   colour) and a label target (id, reflection weight, attenuation distance): id 0 for
   diffuse meshes (and nothing), reflector index + 1 for reflectors. Blender's Python
   ``gpu`` module has no stencil, so the id texture plays the stencil of Roger &
   Holzschuch 2006, section 3.3.6. The weight is the reflectivity, times Schlick's
   Fresnel term where the reflector asks for it (SBC V-D).
2. **Reflections**, per reflection history and its sheets (``SampleBasedCamera.groups``:
   one history per sheet, a history repeating when its rays cross in space), in three
   kinds of draw:

   a. *vertex projection*: every vertex of the (pre-subdivided, SBC V-B,
      :mod:`.subdivision`) diffuse meshes is projected once per sheet with
      ``sbc_project`` (``glsl/sbc_projection.glsl``); pixel, depth and validity, and
      the eye vector and reflected distance, land in texel ``gl_VertexID`` of the
      sheet's layer of two float targets;
   b. *triangles*, per sheet: the meshes are drawn un-indexed, every vertex carrying
      its triangle's three corner indices; it reads the three projections and
      collapses the triangle unless every corner projects. Projecting per vertex first,
      instead of three corners per drawn vertex, costs one projection per mesh vertex
      and makes the decision identical for the triangle's three vertices. Across the
      seam between two sheets of one history a corner may take its projection from the
      neighbouring sheet, within a few ray-map cells (``glsl/reflection_mesh_vert.glsl``),
      so seams do not open cracks. The depth is SBC V-A's offset (k - 1 + z / D) g:
      within a sheet the point nearer the mirror along the reflected ray wins (case 2),
      lower orders before higher ones (case 3), one depth buffer for all sheets. The
      fragment stage keeps only pixels whose pre-pass id is the sheet's first reflector
      (history[0] + 1): reflections stay inside the visible footprint of their
      reflector, and real objects in front of a mirror stay in front;
   c. *mixed triangles* (SBC V-B: one or two corners project): read back from the
      vertex projections, they are drawn instanced as a barycentric sub-grid whose every
      sub-vertex is projected on its own (``glsl/reflection_mixed_vert.glsl``);
      sub-triangles with a corner that does not project are discarded, so the
      reflection ends within about a sub-triangle (about 1 px, :data:`MIXED_SUB_PX`) of
      where projection ends instead of at the last whole triangle.

   Shading (SBC V-C, ``glsl/reflection_shading.glsl``): a reflected vertex keeps its
   mesh's colour, normal and UVs (times the mesh's image texture, if any); emission
   is shown unlit, anything else is lit by a headlight along the *true* eye vector,
   from the vertex toward its reflector point: ambient + Lambert, two-sided.
3. **Composite** (SBC V-D): on reflector pixels, the reflection where one was drawn,
   faded toward the world colour by min(1, (d / A)^2) for its distance d from the mirror
   along the reflected ray when the reflector has a fade distance A, else the world
   colour; mixed with the reflector's own colour by the reflection weight (1 = perfect
   mirror); elsewhere the pre-pass colour (or nothing, for a viewport overlay:
   ``reflectors_only``).

The sample-based camera cannot place a reflection in the last ray-map cell before a
footprint's edge (the silhouette, or an object in front of the mirror), nor between
ray-map cells of different reflection histories inside a footprint (where another
mirror's reflection begins): a projection needs four neighbouring rays of one group.
:meth:`ReflectionRenderer.render` ray traces those pixels, when they got no reflection,
on the CPU (:mod:`.band_trace`, shaded alike); :meth:`ReflectionRenderer.draw` (no
read-back of the image, for a viewport) fills the band from the nearest reflected pixel
instead. Optionally (``trace_edges``) every pixel next to a drawn reflection that got
none is traced too.

Not done: creases of a reflector (a lid's rim) can leave a line of pixels without (or
with a wrong) reflection, where the engine's rays straddle the crease; for reflections
of order k > 1 the eye vector of lighting runs to the first reflector point, not the
last.

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
    "prepass": 64 + 16 + 4,  # mat4 view_projection; vec4 camera; int use_image
    # mat4 inverse_view_projection; vec2 view_size; int group, order, layer_offset; ivec2 target_size;
    # float inverse_diameter, order_range
    "project": 64 + 8 + 4 + 4 + 4 + 8 + 4 + 4,
    # ivec2 projected_size; vec2 view_size; int first_reflector_id, own_layer, n_layers, layer_size;
    # float stitch_px; int use_image
    "mesh": 8 + 8 + 4 + 4 + 4 + 4 + 4 + 4,
    # mat4 inverse_view_projection; vec2 view_size; int first_reflector_id, order; float inverse_diameter,
    # order_range; int use_image, instance_offset
    "mixed": 64 + 8 + 4 + 4 + 4 + 4 + 4 + 4,
    "composite": 16 + 4 + 4 + 8,  # vec4 world_color; int reflectors_only, fill_radius; ivec2 origin
}
#: A mixed triangle (SBC V-B) is drawn as a triangular grid of n sub-triangles along each
#: edge (n^2 in all), each sub-vertex projected on its own; n is a power of two up to this,
#: chosen so that sub-triangles span about MIXED_SUB_PX pixels. 0 drops mixed triangles
#: (the paper's baseline).
MIXED_SUBDIVISIONS = 32
MIXED_SUB_PX = 1.0
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


def _shading_source() -> str:
    """``glsl/reflection_shading.glsl`` behind its ``#define``."""
    return f"#define SHADE_AMBIENT {band_trace.SHADE_AMBIENT:.9e}\n" + _source("reflection_shading.glsl")


@functools.cache
def _build_prepass():
    import gpu

    interface = gpu.types.GPUStageInterfaceInfo("curved_reflections_prepass_interface")
    interface.smooth('VEC4', "color_interp")
    interface.flat('VEC4', "label_interp")
    interface.smooth('VEC3', "normal_interp")
    interface.flat('FLOAT', "lit_interp")
    interface.smooth('VEC2', "uv_interp")
    interface.smooth('VEC3', "position_interp")
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('MAT4', "view_projection")
    info.push_constant('VEC4', "camera")
    info.push_constant('INT', "use_image")
    info.sampler(0, 'FLOAT_2D', "image")
    info.vertex_in(0, 'VEC3', "position")
    info.vertex_in(1, 'VEC4', "color")
    info.vertex_in(2, 'VEC4', "label")
    info.vertex_in(3, 'VEC4', "normal_lit")
    info.vertex_in(4, 'VEC2', "uv")
    info.vertex_out(interface)
    info.fragment_out(0, 'VEC4', "color_out")
    info.fragment_out(1, 'VEC4', "label_out")
    info.vertex_source(_source("reflection_prepass_vert.glsl"))
    info.fragment_source(_shading_source() + _source("reflection_prepass_frag.glsl"))
    return gpu.shader.create_from_info(info)


@functools.cache
def _build_project():
    import gpu

    interface = gpu.types.GPUStageInterfaceInfo("curved_reflections_project_interface")
    interface.flat('VEC4', "projected")
    interface.flat('VEC4', "projected_eye")
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('MAT4', "inverse_view_projection")
    info.push_constant('VEC2', "view_size")
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
    info.fragment_out(1, 'VEC4', "eye_out")
    info.vertex_source(projection.library_source() + _shading_source() + _source("reflection_project_vert.glsl"))
    info.fragment_source(_source("reflection_project_frag.glsl"))
    return gpu.shader.create_from_info(info)


def _reflected_interface(name: str, subdivided: bool):
    import gpu

    interface = gpu.types.GPUStageInterfaceInfo(name)
    interface.smooth('VEC4', "color_interp")
    interface.smooth('VEC3', "normal_interp")
    interface.smooth('VEC3', "eye_interp")
    interface.smooth('VEC2', "uv_interp")
    interface.smooth('FLOAT', "distance_interp")
    interface.flat('FLOAT', "lit_interp")
    if subdivided:
        interface.no_perspective('FLOAT', "valid_interp")
    return interface


@functools.cache
def _build_mesh():
    import gpu

    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('IVEC2', "projected_size")
    info.push_constant('VEC2', "view_size")
    info.push_constant('INT', "first_reflector_id")
    info.push_constant('INT', "own_layer")
    info.push_constant('INT', "n_layers")
    info.push_constant('INT', "layer_size")
    info.push_constant('FLOAT', "stitch_px")
    info.push_constant('INT', "use_image")
    info.sampler(0, 'FLOAT_2D', "projected_vertices")
    info.sampler(1, 'FLOAT_2D', "prepass_labels")
    info.sampler(2, 'FLOAT_2D', "projected_eyes")
    info.sampler(3, 'FLOAT_2D', "image")
    info.vertex_in(0, 'IVEC3', "corners")
    info.vertex_in(1, 'INT', "corner")
    info.vertex_in(2, 'VEC4', "color")
    info.vertex_in(3, 'VEC4', "normal_lit")
    info.vertex_in(4, 'VEC2', "uv")
    info.vertex_out(_reflected_interface("curved_reflections_mesh_interface", False))
    info.fragment_out(0, 'VEC4', "color_out")
    info.vertex_source(_source("reflection_mesh_vert.glsl"))
    info.fragment_source(_shading_source() + _source("reflection_mesh_frag.glsl"))
    return gpu.shader.create_from_info(info)


@functools.cache
def _build_mixed():
    import gpu

    info = gpu.types.GPUShaderCreateInfo()
    info.define("SUBDIVIDED")
    info.push_constant('MAT4', "inverse_view_projection")
    info.push_constant('VEC2', "view_size")
    info.push_constant('INT', "first_reflector_id")
    info.push_constant('INT', "order")
    info.push_constant('FLOAT', "inverse_diameter")
    info.push_constant('FLOAT', "order_range")
    info.push_constant('INT', "use_image")
    info.push_constant('INT', "instance_offset")
    projection.declare_samplers(info)
    n = len(projection.SAMPLERS)
    info.sampler(n, 'FLOAT_2D', "prepass_labels")
    info.sampler(n + 1, 'FLOAT_2D', "image")
    info.sampler(n + 2, 'FLOAT_2D', "mixed_instances")
    info.sampler(n + 3, 'FLOAT_2D', "vertex_positions")
    info.sampler(n + 4, 'FLOAT_2D', "vertex_colors")
    info.sampler(n + 5, 'FLOAT_2D', "vertex_normals")
    info.vertex_in(0, 'VEC2', "barycentric")
    info.vertex_out(_reflected_interface("curved_reflections_mixed_interface", True))
    info.fragment_out(0, 'VEC4', "color_out")
    info.vertex_source(projection.library_source() + _shading_source() + _source("reflection_mixed_vert.glsl"))
    info.fragment_source(_shading_source() + _source("reflection_mesh_frag.glsl"))
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


_BUILDERS = {"prepass": _build_prepass, "project": _build_project, "mesh": _build_mesh, "mixed": _build_mixed,
             "composite": _build_composite}


# --- geometry (numpy) ---------------------------------------------------------------


@dataclass(frozen=True)
class DrawGeometry:
    """What the passes draw, as arrays (no GPU needed to build it).

    Pre-pass: every diffuse mesh, then every reflector, in one indexed triangle list;
    positions relative to ``shift``; its triangles sorted by image, ``prepass_ranges``
    the (image index or -1, first triangle, count) runs. Reflected meshes: all diffuse
    meshes subdivided (:mod:`.subdivision`) and concatenated, world positions, their
    triangles sorted by image likewise (``ranges``). ``images`` are the meshes' image
    textures, (H, W, 4) float32 linear, rows bottom to top.
    """

    shift: np.ndarray  # (3,) float64
    prepass_positions: np.ndarray  # (P, 3) float32, relative to shift
    prepass_colors: np.ndarray  # (P, 4) float32 linear RGBA
    prepass_labels: np.ndarray  # (P, 4) float32 (id, reflectivity, Fresnel F0 or -1, attenuation distance)
    prepass_normals: np.ndarray  # (P, 4) float32 (normal, lit)
    prepass_uvs: np.ndarray  # (P, 2) float32
    prepass_triangles: np.ndarray  # (Tp, 3) int32
    vertices: np.ndarray  # (V, 3) float64, reflected meshes
    colors: np.ndarray  # (V, 4) float32
    triangles: np.ndarray  # (T, 3) int64
    diameter: float  # bounding-box diagonal of everything: bounds every reflected ray distance
    normals: np.ndarray = None  # (V, 3) float32 unit (zero where undefined)
    lit: np.ndarray = None  # (V,) float32: 1 lit, 0 emission (unlit)
    uvs: np.ndarray = None  # (V, 2) float32
    images: tuple = ()
    prepass_ranges: tuple = ()
    ranges: tuple = ()
    stats: dict = field(default_factory=dict)


def _sorted_by_image(triangles: np.ndarray, image: np.ndarray) -> tuple[np.ndarray, tuple]:
    """Triangles sorted by image index (stable) and the (image, first, count) runs."""
    order = np.argsort(image, kind="stable")
    image = image[order]
    starts = np.flatnonzero(np.r_[True, image[1:] != image[:-1]]) if len(image) else np.zeros(0, int)
    counts = np.diff(np.r_[starts, len(image)])
    return triangles[order], tuple((int(image[k]), int(k), int(c)) for k, c in zip(starts, counts))


def _mesh_attributes(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normals (N, 3) (the mesh's, else smooth ones from its faces), UVs (N, 2) and lit (N,)."""
    from ..addon.scene import vertex_normals

    normals = mesh.normals if getattr(mesh, "normals", None) is not None else vertex_normals(
        mesh.vertices, mesh.triangles)
    uvs = mesh.uvs if mesh.uvs is not None else np.zeros((len(mesh.vertices), 2))
    lit = np.full(len(mesh.vertices), 0.0 if mesh.emissive else 1.0, np.float32)
    return np.asarray(normals, np.float64), np.asarray(uvs, np.float64), lit


def prepare_geometry(reflectors, meshes, reflector_colors=None, reflectivity=None,
                     edge_fraction: float = subdivision.EDGE_FRACTION, fresnel_f0=None,
                     attenuation_distance=None) -> DrawGeometry:
    """Arrays of one scene for :class:`ReflectionRenderer`.

    ``reflector_colors`` (R, 3 or 4) linear, default white; ``reflectivity`` (R,) in
    [0, 1], default 1 (perfect mirrors); ``fresnel_f0`` (R,) Schlick's reflectance at
    normal incidence, NaN or negative for no Fresnel (default none); ``attenuation_distance``
    (R,) the distance over which reflections fade to the world (0 or default: none).
    SBC paper section V-D. ``edge_fraction`` sets the pre-subdivision
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
    f0 = np.full(n_reflectors, -1.0, np.float32) if fresnel_f0 is None else np.asarray(
        fresnel_f0, dtype=np.float32).reshape(n_reflectors)
    f0 = np.where(np.isfinite(f0) & (f0 >= 0), np.clip(f0, 0.0, 1.0), -1.0).astype(np.float32)
    fade = np.zeros(n_reflectors, np.float32) if attenuation_distance is None else np.maximum(
        np.asarray(attenuation_distance, dtype=np.float32).reshape(n_reflectors), 0.0)

    images, image_of_mesh = [], []
    for mesh in meshes:
        image = getattr(mesh, "image", None)
        image_of_mesh.append(-1 if image is None else len(images))
        if image is not None:
            images.append(np.ascontiguousarray(image, dtype=np.float32))
    attributes = [_mesh_attributes(m) for m in meshes]

    parts = [(m.vertices, m.triangles, m.colors, (0.0, 1.0, -1.0, 0.0), np.c_[n, lit], uv, image)
             for m, (n, uv, lit), image in zip(meshes, attributes, image_of_mesh)]
    parts += [(r.vertices, r.triangles, colors[k], (k + 1.0, mirror[k], f0[k], fade[k]), np.c_[r.normals, np.zeros(
        len(r.vertices))], np.zeros((len(r.vertices), 2)), -1) for k, r in enumerate(reflectors)]
    everything = np.concatenate([p[0] for p in parts]) if parts else np.zeros((1, 3))
    lo, hi = everything.min(axis=0), everything.max(axis=0)
    shift = 0.5 * (lo + hi)
    positions, vertex_colors, labels, normals, uvs, triangles, tri_image, offset = [], [], [], [], [], [], [], 0
    for vertices, tris, color, label, normal, uv, image in parts:
        positions.append((vertices - shift).astype(np.float32))
        vertex_colors.append(np.broadcast_to(np.asarray(color, np.float32), (len(vertices), 4)))
        labels.append(np.broadcast_to(np.asarray(label, np.float32), (len(vertices), 4)))
        normals.append(np.asarray(normal, np.float32))
        uvs.append(np.asarray(uv, np.float32))
        triangles.append(np.asarray(tris, dtype=np.int64) + offset)
        tri_image.append(np.full(len(tris), image))
        offset += len(vertices)
    prepass_triangles, prepass_ranges = _sorted_by_image(
        (np.concatenate(triangles) if triangles else np.zeros((0, 3))).astype(np.int32),
        np.concatenate(tri_image) if tri_image else np.zeros(0, int))

    centres, radii = subdivision.reflector_spheres(reflectors)
    vertices, packed, mesh_triangles, mesh_image, offset = [], [], [], [], 0
    for mesh, (normal, uv, lit), image in zip(meshes, attributes, image_of_mesh):
        # Colour, normal, UV and lit are interpolated together at new midpoints.
        v, t, c = mesh.vertices, mesh.triangles, np.c_[mesh.colors, normal, uv, lit].astype(np.float32)
        if edge_fraction is not None:
            v, t, c = subdivision.subdivide(v, t, c, centres, radii, edge_fraction)
        vertices.append(v)
        packed.append(c)
        mesh_triangles.append(t + offset)
        mesh_image.append(np.full(len(t), image))
        offset += len(v)
    if offset >= MAX_VERTICES:
        raise ValueError(f"{offset} reflected vertices: float targets index below 2^24 only")
    packed = np.concatenate(packed) if packed else np.zeros((0, 10), np.float32)
    vertex_normals = packed[:, 4:7]
    length = np.linalg.norm(vertex_normals, axis=1, keepdims=True)
    vertex_normals = np.divide(vertex_normals, length, out=np.zeros_like(vertex_normals), where=length > 0)
    mesh_triangles, ranges = _sorted_by_image(
        np.concatenate(mesh_triangles) if mesh_triangles else np.zeros((0, 3), np.int64),
        np.concatenate(mesh_image) if mesh_image else np.zeros(0, int))
    geometry = DrawGeometry(
        shift=shift,
        prepass_positions=np.concatenate(positions) if positions else np.zeros((0, 3), np.float32),
        prepass_colors=np.concatenate(vertex_colors) if vertex_colors else np.zeros((0, 4), np.float32),
        prepass_labels=np.concatenate(labels) if labels else np.zeros((0, 4), np.float32),
        prepass_normals=np.concatenate(normals) if normals else np.zeros((0, 4), np.float32),
        prepass_uvs=np.concatenate(uvs) if uvs else np.zeros((0, 2), np.float32),
        prepass_triangles=prepass_triangles,
        vertices=np.concatenate(vertices) if vertices else np.zeros((0, 3)),
        colors=np.ascontiguousarray(packed[:, :4]),
        triangles=mesh_triangles,
        diameter=float(max(np.linalg.norm(hi - lo), 1e-9)),
        normals=vertex_normals.astype(np.float32),
        lit=np.ascontiguousarray(packed[:, 9]),
        uvs=np.ascontiguousarray(packed[:, 7:9]),
        images=tuple(images),
        prepass_ranges=prepass_ranges,
        ranges=ranges,
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
        self.projected_eyes = gpu.types.GPUTexture(self.projected_size, format='RGBA32F')
        self.projected_framebuffer = gpu.types.GPUFrameBuffer(color_slots=(self.projected, self.projected_eyes))
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


def _data_texture(values: np.ndarray, width: int | None = None):
    """An RGBA32F texture of ``values`` (N, <= 4) one texel each, rows of ``width``
    texels (default: up to the packer's texture width), or of an (H, W, 4) image."""
    import gpu

    values = np.asarray(values, dtype=np.float32)
    if values.ndim == 3:
        height, width = values.shape[:2]
        texels = values.reshape(-1, 4)
    else:
        texels = np.zeros((max(1, len(values)), 4), np.float32)
        texels[:len(values), :values.shape[1]] = values
        width = width or max(1, min(len(texels), projection.sbc_pack.TEXTURE_WIDTH))
        height = -(-len(texels) // width)
        texels = np.concatenate([texels, np.zeros((width * height - len(texels), 4), np.float32)])
    data = gpu.types.Buffer('FLOAT', texels.size, np.ascontiguousarray(texels).reshape(-1))
    return gpu.types.GPUTexture((width, height), format='RGBA32F', data=data)


def _read_texture(texture, width: int, height: int) -> np.ndarray:
    """(H, W, 4) float32 of an RGBA32F texture, rows bottom to top."""
    data = texture.read()
    data.dimensions = width * height * 4
    return np.asarray(data, dtype=np.float32).reshape(height, width, 4)


def _camera(view, shift) -> tuple:
    """The pre-pass's ``camera``: the eye relative to ``shift`` (w 1), or for an
    orthographic view the unit direction toward the viewer (w 0)."""
    inverse = np.linalg.inv(np.asarray(view.view_matrix, dtype=np.float64))
    if abs(float(np.asarray(view.projection_matrix)[3, 3]) - 1.0) < 1e-12:  # orthographic
        return (*inverse[:3, 2], 0.0)
    return (*(inverse[:3, 3] - shift), 1.0)


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
                 edge_fraction: float | None = subdivision.EDGE_FRACTION, *, fresnel_f0=None,
                 attenuation_distance=None, mixed_subdivisions: int = MIXED_SUBDIVISIONS):
        self.geometry = prepare_geometry(reflectors, meshes, reflector_colors, reflectivity, edge_fraction,
                                         fresnel_f0, attenuation_distance)
        self.mixed_subdivisions = int(mixed_subdivisions)
        self.stats = dict(self.geometry.stats)
        self._reflectors, self._meshes = list(reflectors), list(meshes)
        self._batches = None
        self._targets = None
        self._tracer = None

    def _make_batches(self) -> dict:
        """Vertex buffers, the vertex data textures of the mixed-triangle pass and the images."""
        import gpu

        g = self.geometry
        batches = {}
        if len(g.prepass_triangles):
            buffer = _vertex_buffer({"position": (g.prepass_positions, 'F32', 'FLOAT'),
                                     "color": (g.prepass_colors, 'F32', 'FLOAT'),
                                     "label": (g.prepass_labels, 'F32', 'FLOAT'),
                                     "normal_lit": (g.prepass_normals, 'F32', 'FLOAT'),
                                     "uv": (g.prepass_uvs, 'F32', 'FLOAT')})
            batches["prepass"] = [
                (image, gpu.types.GPUBatch(type='TRIS', buf=buffer, elem=gpu.types.GPUIndexBuf(
                    type='TRIS', seq=g.prepass_triangles[first:first + count])))
                for image, first, count in g.prepass_ranges]
        if len(g.triangles):
            points = _vertex_buffer({"position": (g.vertices.astype(np.float32), 'F32', 'FLOAT')})
            batches["points"] = gpu.types.GPUBatch(type='POINTS', buf=points)
            corners = np.repeat(g.triangles.astype(np.int32), 3, axis=0)
            flat = g.triangles.reshape(-1)
            buffer = _vertex_buffer({
                "corners": (corners, 'I32', 'INT'),
                "corner": (np.tile(np.arange(3, dtype=np.int32), len(g.triangles)), 'I32', 'INT'),
                "color": (g.colors[flat], 'F32', 'FLOAT'),
                "normal_lit": (np.c_[g.normals, g.lit][flat].astype(np.float32), 'F32', 'FLOAT'),
                "uv": (g.uvs[flat], 'F32', 'FLOAT'),
            })
            batches["mesh"] = gpu.types.GPUBatch(type='TRIS', buf=buffer)
            # Mixed triangles (SBC V-B): the vertex data as textures, one texel per vertex.
            batches["vertex_positions"] = _data_texture(np.c_[g.vertices, g.uvs[:, 0]])
            batches["vertex_colors"] = _data_texture(np.c_[g.colors[:, :3], g.lit])
            batches["vertex_normals"] = _data_texture(np.c_[g.normals, g.uvs[:, 1]])
        batches["images"] = [_data_texture(image, image.shape[1]) for image in g.images]
        batches["no_image"] = _data_texture(np.ones((1, 4)))
        screen = _vertex_buffer({"position": (np.array([[-1, -1], [3, -1], [-1, 3]], np.float32), 'F32', 'FLOAT')})
        batches["screen"] = gpu.types.GPUBatch(type='TRIS', buf=screen)
        return batches

    def _image(self, index: int):
        return self._batches["images"][index] if index >= 0 else self._batches["no_image"]

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
                    shader.uniform_float("camera", _camera(view, g.shift))
                    for image, batch in batches["prepass"]:
                        shader.uniform_int("use_image", int(image >= 0))
                        shader.uniform_sampler("image", self._image(image))
                        batch.draw(shader)
            with targets.reflection.bind():
                gpu.state.viewport_set(0, 0, width, height)
                targets.reflection.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            self.stats["mixed_triangles"] = 0
            if "mesh" in batches:
                world_to_clip = np.asarray(view.projection_matrix) @ np.asarray(view.view_matrix)
                inverse = Matrix(np.linalg.inv(world_to_clip).tolist())
                mixed = 0
                for sheets in chunks:
                    mixed += self._draw_history(targets, textures, sheets, histories[sheets[0]], order_range,
                                                stitch_px, inverse)
                self.stats["mixed_triangles"] = mixed
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
                   edges_of_drawn: bool = False, ray_map=None) -> int:
        """Trace the reflector pixels along each footprint's edge that got no reflection
        (:mod:`.band_trace`): reads the pre-pass ids and the reflection coverage back,
        traces those pixels on the CPU and uploads their colours for the composite. With
        the camera's ``ray_map``, also those between ray-map cells of different histories
        (:func:`band_trace.history_boundary`: the edge of a second-order reflection inside
        a footprint). Returns how many pixels were traced."""
        import gpu

        if self._tracer is None:
            self._tracer = band_trace.BandTracer(self._reflectors, self._meshes)
        labels = _read_texture(targets.prepass_labels, targets.width, targets.height)[..., 0]
        drawn = _read_texture(targets.reflection_colors, targets.width, targets.height)[..., 3] > 0.5
        boundary = None if ray_map is None else band_trace.history_boundary(
            ray_map, targets.width, targets.height, max_order)
        pixels = band_trace.band_pixels(labels, drawn, radius, edges_of_drawn, boundary)
        traced = np.zeros((targets.height, targets.width, 4), np.float32)
        if len(pixels):
            colors = self._tracer.trace(view, pixels + 0.5, max_order, _rgba(world_color))
            traced[pixels[:, 1], pixels[:, 0], :3] = colors[:, :3]
            # As a drawn reflection's: 1 + the distance from the mirror (attenuation, SBC V-D).
            traced[pixels[:, 1], pixels[:, 0], 3] = 1.0 + np.minimum(colors[:, 3], 1e30)
        data = gpu.types.Buffer('FLOAT', traced.size, traced.reshape(-1))
        targets.traced = gpu.types.GPUTexture((targets.width, targets.height), format='RGBA32F', data=data)
        return int(len(pixels))

    def _draw_history(self, targets: FrameTargets, textures, sheets: list, history, order_range: float,
                      stitch_px: float, inverse_view_projection) -> int:
        """Project every vertex in each of ``sheets`` (sheets of one history) into its own
        layer, then draw each sheet's triangles, stitched across the seams between them,
        and its mixed triangles subdivided (:meth:`_draw_mixed`). Returns how many mixed
        triangles were drawn."""
        import gpu

        batches = self._batches
        columns, rows = targets.projected_size
        n_vertices = len(self.geometry.vertices)
        view_size = (float(targets.width), float(targets.height))
        with targets.projected_framebuffer.bind():
            gpu.state.viewport_set(0, 0, columns, rows)
            targets.projected_framebuffer.clear(color=(0.0, 0.0, 0.0, 0.0))
            gpu.state.depth_test_set('NONE')
            gpu.state.program_point_size_set(True)
            try:
                shader = _shader("project")
                shader.bind()
                shader.uniform_float("inverse_view_projection", inverse_view_projection)
                shader.uniform_float("view_size", view_size)
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
            shader.uniform_float("view_size", view_size)
            shader.uniform_int("first_reflector_id", int(history[0]) + 1)
            shader.uniform_int("n_layers", len(sheets))
            shader.uniform_int("layer_size", n_vertices)
            shader.uniform_float("stitch_px", float(stitch_px))
            shader.uniform_sampler("projected_vertices", targets.projected)
            shader.uniform_sampler("projected_eyes", targets.projected_eyes)
            shader.uniform_sampler("prepass_labels", targets.prepass_labels)
            for layer in range(len(sheets)):
                shader.uniform_int("own_layer", layer)
                for image, first, count in self.geometry.ranges:
                    shader.uniform_int("use_image", int(image >= 0))
                    shader.uniform_sampler("image", self._image(image))
                    batches["mesh"].draw_range(shader, elem_start=3 * first, elem_count=3 * count)
        if self.mixed_subdivisions <= 0:
            return 0
        return self._draw_mixed(targets, textures, sheets, history, order_range, inverse_view_projection)

    def _draw_mixed(self, targets: FrameTargets, textures, sheets: list, history, order_range: float,
                    inverse_view_projection) -> int:
        """Mixed triangles of ``sheets`` (SBC V-B), each as a sub-grid whose vertices are
        projected on their own (``glsl/reflection_mixed_vert.glsl``).

        Which triangles are mixed is read back from the vertex projections: one or two
        corners project in the sheet and not every corner projects in some sheet of the
        history (those the triangle pass stitches). The read-back is the projection
        target's texels of these sheets, 16 bytes per vertex and sheet.
        """
        import gpu

        g, batches = self.geometry, self._batches
        n_vertices = len(g.vertices)
        projected = _read_texture(targets.projected, *targets.projected_size).reshape(-1, 4)
        projected = projected[:len(sheets) * n_vertices].reshape(len(sheets), n_vertices, 4)
        valid = projected[..., 3] > 0.5
        somewhere = valid.any(axis=0)[g.triangles].all(axis=1)
        # Pixels per world unit in each sheet, the largest over the edges of fully projected
        # triangles (conservative: the median let magnified parts of a sheet go coarse); a
        # mixed triangle's size in pixels is estimated from its longest edge.
        edge = np.linalg.norm(g.vertices[g.triangles[:, 1]] - g.vertices[g.triangles[:, 0]], axis=1)
        longest = np.max([np.linalg.norm(g.vertices[g.triangles[:, k]] - g.vertices[g.triangles[:, (k + 1) % 3]],
                                         axis=1) for k in range(3)], axis=0)
        instances, runs = [], []
        for image, first, count in g.ranges:
            triangles = g.triangles[first:first + count]
            by_level: dict = {}
            for layer, group in enumerate(sheets):
                own = valid[layer][triangles]
                full = own.all(axis=1) & (edge[first:first + count] > 0)
                pixels = projected[layer][triangles[full], :2]
                scale = (np.max(np.linalg.norm(pixels[:, 1] - pixels[:, 0], axis=1) / edge[first:first + count][full])
                         if full.any() else np.inf)
                chosen = np.flatnonzero(own.any(axis=1) & ~own.all(axis=1) & ~somewhere[first:first + count])
                if len(chosen) == 0:
                    continue
                size_px = scale * longest[first:first + count][chosen]
                wanted = np.clip(np.nan_to_num(size_px / MIXED_SUB_PX, posinf=1e9), 1, self.mixed_subdivisions)
                level = np.minimum(np.ceil(np.log2(wanted)).astype(np.int64),
                                   int(np.log2(max(1, self.mixed_subdivisions))))
                corners = triangles[chosen]
                anchor = projected[layer][corners[np.arange(len(chosen)), own[chosen].argmax(axis=1)], :2]
                texels = np.zeros((len(chosen), 2, 4), np.float32)
                texels[:, 0, :3] = corners
                texels[:, 0, 3] = group
                texels[:, 1, :2] = anchor
                for value in np.unique(level):
                    by_level.setdefault(int(value), []).append(texels[level == value])
            for value, parts in by_level.items():
                start = sum(len(i) for i in instances) // 2
                block = np.concatenate(parts)
                instances.append(block.reshape(-1, 4))
                runs.append((image, 1 << value, start, len(block)))
        if not instances:
            return 0
        instance_texture = _data_texture(np.concatenate(instances), 2 * 2048)
        with targets.reflection.bind():
            gpu.state.viewport_set(0, 0, targets.width, targets.height)
            gpu.state.depth_test_set('LESS')
            gpu.state.depth_mask_set(True)
            shader = _shader("mixed")
            shader.bind()
            shader.uniform_float("inverse_view_projection", inverse_view_projection)
            shader.uniform_float("view_size", (float(targets.width), float(targets.height)))
            shader.uniform_int("first_reflector_id", int(history[0]) + 1)
            shader.uniform_int("order", len(history))
            shader.uniform_float("inverse_diameter", 1.0 / g.diameter)
            shader.uniform_float("order_range", order_range)
            textures.bind(shader)
            shader.uniform_sampler("prepass_labels", targets.prepass_labels)
            shader.uniform_sampler("mixed_instances", instance_texture)
            for name in ("vertex_positions", "vertex_colors", "vertex_normals"):
                shader.uniform_sampler(name, batches[name])
            for image, n, first, count in runs:
                shader.uniform_int("use_image", int(image >= 0))
                shader.uniform_sampler("image", self._image(image))
                shader.uniform_int("instance_offset", first)
                self._sub_grid(n).draw_instanced(shader, instance_start=0, instance_count=count)
        return sum(run[3] for run in runs)

    def _sub_grid(self, n: int):
        """The batch of an n x n barycentric sub-grid (:func:`subdivision.barycentric_grid`)."""
        import gpu

        key = f"sub_grid_{n}"
        if key not in self._batches:
            grid, sub_triangles = subdivision.barycentric_grid(n)
            self._batches[key] = gpu.types.GPUBatch(
                type='TRIS', buf=_vertex_buffer({"barycentric": (grid.astype(np.float32), 'F32', 'FLOAT')}),
                elem=gpu.types.GPUIndexBuf(type='TRIS', seq=sub_triangles.astype(np.int32)))
        return self._batches[key]

    def render(self, view, sbc_or_textures, world_color=(0.0, 0.0, 0.0, 1.0), trace: bool = True,
               fill_radius: int | None = None, trace_edges: bool = False) -> np.ndarray:
        """Draw ``view`` offscreen and read it back: (H, W, 4) float32 linear RGBA, rows bottom to top.

        ``sbc_or_textures``: a ``SampleBasedCamera`` built for this view, or its
        ``projection.SBCTextures``. With ``trace`` the band along each footprint's edge
        that the camera cannot reach (d pixels wide) is ray traced (:meth:`trace_band`);
        without, it gets the composite's fill (``fill_radius``, ``None``: d). With
        ``trace_edges`` also the reflector pixels within d of a drawn reflection that got
        none: seams and creases; exact there, but no longer a purely feed-forward image
        (15-18 % of the mirror pixels of the demo scenes are traced). When
        ``sbc_or_textures`` is the camera itself, the pixels between ray-map cells of
        different histories are traced too (:func:`band_trace.history_boundary`).
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
            traced = self.trace_band(view, targets, max_order, world_color, downsample, trace_edges,
                                     getattr(sbc_or_textures, "ray_map", None))
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
