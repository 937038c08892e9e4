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
   one history per sheet, a history repeating when its rays cross in space). Made
   **once per camera** (:meth:`ReflectionRenderer.projection`, cached; a mesh change
   means a new renderer) and drawn every frame:

   a. *vertex projection* (GPU): every vertex of the (pre-subdivided, SBC V-B,
      :mod:`.subdivision`) diffuse meshes is projected per sheet with ``sbc_project``
      (``glsl/sbc_projection.glsl``, ``glsl/reflection_project_vert.glsl``): pixel,
      depth and validity, eye vector and reflected distance land in texel
      ``gl_VertexID`` of the sheet's layer of two float targets, read back. Only the
      vertex chunks (runs of :data:`CHUNK_VERTICES` Morton-sorted vertices) that meet
      the sheet's bounds are projected (:mod:`..addon.sheet_bounds`); the others could
      not project there.
   b. *triangles* (CPU, from the read-back), per sheet: those with a corner projected in
      the sheet and every corner projected, in it or, across the seam between two sheets
      of one history, in another sheet within a few ray-map cells of the triangle's own
      corner (:data:`STITCH_CELLS`; so seams do not open cracks, and a corner is not
      joined to its second image across the mirror). The depth is SBC V-A's offset
      (k - 1 + z / D) g: within a sheet the point nearer the mirror along the reflected
      ray wins (case 2), lower orders before higher ones (case 3), one depth buffer.
   c. *mixed triangles* (SBC V-B: one or two corners project, none stitched): each is
      cut into a barycentric sub-grid whose sub-vertices are projected on their own (a
      second GPU projection pass); sub-triangles with a sub-vertex that does not project
      are dropped, so the reflection ends within about a sub-triangle (about 1 px,
      :data:`MIXED_SUB_PX`) of where projection ends instead of at the last whole
      triangle. Inside, a block of :data:`MIXED_COARSE_FACTOR` ^ 2 sub-triangles that
      all project is kept as one triangle over its projected corners.
   d. *per frame* (``glsl/reflection_mesh_vert.glsl``): all of it is one vertex buffer
      whose vertices hold their **first reflector point in world space**, their depth,
      eye vector, distance and mesh data; one draw places each vertex where the current
      view sees its reflector point (in the camera's own view, exactly its projected
      pixel). The fragment stage keeps only pixels whose pre-pass id is the vertex's
      first reflector (history[0] + 1): reflections stay inside the visible footprint of
      their reflector, and real objects in front of a mirror stay in front. From a moved
      view (a new camera still building) the reflection thus stays on the mirror in
      world space, nearly right, instead of lagging as pixels of the old view.

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

Drawn from a view other than the camera's, the cached reflection is exact only at the
reflector points: a reflected triangle is interpolated affinely between them (as in the
camera's view), the reflection does not slide over the mirror as a new camera would
make it (until that camera lands), and a triangle with a reflector point behind the
view is dropped.

Not done: creases of a reflector (a lid's rim) can leave a line of pixels without (or
with a wrong) reflection, where the engine's rays straddle the crease; for reflections
of order k > 1 the eye vector of lighting runs to the first reflector point, not the
last.

:class:`ReflectionRenderer` holds one scene's geometry (subdivided once), its GPU
batches and the projections of the last cameras drawn; :meth:`ReflectionRenderer.draw`
draws any view with any sample-based camera of it and composites into the framebuffer
that is bound, so a viewport draw handler can call it with the region's matrices
(``operators.capture.view_from_region``); :meth:`ReflectionRenderer.render` draws
offscreen and reads the image back.

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

from ..addon import band_trace, sheet_bounds, subdivision
from . import projection
from .iterative_draw import IterativePass
from .morph_pass import DEFAULT_BUDGET_MB, MorphPass
from .reflected_meshes import ReflectedMeshes

_GLSL = Path(__file__).resolve().parent / "glsl"

#: Bytes of push constants per shader (Vulkan guarantees 128): the pre-pass's matrix is
#: the largest; everything bigger (the cameras, the pre-pass images) is in textures.
PUSH_CONSTANT_BYTES = {
    "prepass": 64 + 16 + 4,  # mat4 view_projection; vec4 camera; int use_image
    # mat4 inverse_view_projection; vec2 view_size; int group, order, layer_offset; ivec2 target_size;
    # float inverse_diameter, order_range
    "project": 64 + 8 + 4 + 4 + 4 + 8 + 4 + 4,
    "reflected": 64 + 8 + 4 + 4,  # mat4 view_projection; vec2 view_size; int use_camera_pixel, use_image
    "composite": 16 + 4 + 4 + 8,  # vec4 world_color; int reflectors_only, fill_radius; ivec2 origin
}
#: A mixed triangle (SBC V-B) is drawn as a triangular grid of n sub-triangles along each
#: edge (n^2 in all), each sub-vertex projected on its own; n is a power of two up to this,
#: chosen so that sub-triangles span about MIXED_SUB_PX pixels. 0 drops mixed triangles
#: (the paper's baseline).
MIXED_SUBDIVISIONS = 32
MIXED_SUB_PX = 1.0
#: Inside a mixed triangle, a block of MIXED_COARSE_FACTOR^2 sub-triangles that all
#: project is drawn as one (sub-grids of at least twice this many steps).
MIXED_COARSE_FACTOR = 4
#: Float targets hold vertex indices exactly below 2^24.
MAX_VERTICES = 1 << 24
#: Depth range of the iterative search's first-order reflections (as SBC V-A's g for
#: max order 1); they never share pixels with another method's, the pre-pass ids keep
#: each reflection on its own mirror.
ITERATIVE_ORDER_RANGE = 0.5
#: Texels of the vertex projection target (16 bytes each): the sheets of one history
#: are projected side by side (for stitching) as far as this allows.
MAX_PROJECTED_TEXELS = 1 << 22
#: A triangle across a seam between sheets joins a corner from another sheet only
#: within this many ray-map cells (times the down-sampling, in pixels) of its own corner.
STITCH_CELLS = 8
#: A render traces the band along the mirrors' edges that no reflection reached; where
#: that "band" is more than this share of the image (the camera's near plane cutting a
#: mirror, the eye on its surface), it is filled by the composite instead of traced, so
#: that no view costs many times an ordinary one (the demo scenes trace 1-9 %).
MAX_TRACED_FRACTION = 0.25

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


def reflected_interface(name: str, searched: bool = False):
    """The varyings of a reflected-mesh vertex stage, read by ``glsl/reflection_mesh_frag.glsl``;
    ``searched`` adds the iterative search's interpolated validity."""
    import gpu

    interface = gpu.types.GPUStageInterfaceInfo(name)
    interface.smooth('VEC4', "color_interp")
    interface.smooth('VEC3', "normal_interp")
    interface.smooth('VEC3', "eye_interp")
    interface.smooth('VEC2', "uv_interp")
    interface.smooth('FLOAT', "distance_interp")
    interface.flat('FLOAT', "lit_interp")
    interface.flat('FLOAT', "reflector_interp")
    if searched:
        interface.smooth('FLOAT', "valid_interp")
    return interface


def reflected_fragment_source(defines: str = "") -> str:
    """``glsl/reflection_mesh_frag.glsl`` behind ``defines`` and the shading functions."""
    return defines + _shading_source() + _source("reflection_mesh_frag.glsl")


@functools.cache
def _build_reflected():
    import gpu

    interface = reflected_interface("curved_reflections_reflected_interface")
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('MAT4', "view_projection")
    info.push_constant('VEC2', "view_size")
    info.push_constant('INT', "use_camera_pixel")
    info.push_constant('INT', "use_image")
    info.sampler(0, 'FLOAT_2D', "prepass_labels")
    info.sampler(1, 'FLOAT_2D', "image")
    info.vertex_in(0, 'VEC4', "world_depth")
    info.vertex_in(1, 'VEC4', "pixel_reflector")
    info.vertex_in(2, 'VEC4', "eye_distance")
    info.vertex_in(3, 'VEC4', "color")
    info.vertex_in(4, 'VEC4', "normal_lit")
    info.vertex_in(5, 'VEC2', "uv")
    info.vertex_out(interface)
    info.fragment_out(0, 'VEC4', "color_out")
    info.vertex_source(_source("reflection_mesh_vert.glsl"))
    info.fragment_source(reflected_fragment_source())
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


_BUILDERS = {"prepass": _build_prepass, "project": _build_project, "reflected": _build_reflected,
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
    vertices = np.concatenate(vertices) if vertices else np.zeros((0, 3))
    mesh_triangles = np.concatenate(mesh_triangles) if mesh_triangles else np.zeros((0, 3), np.int64)
    # Vertices along a Morton curve: runs of them are compact chunks for per-sheet culling.
    order = sheet_bounds.morton_order(vertices)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    vertices, packed, mesh_triangles = vertices[order], packed[order], rank[mesh_triangles]
    vertex_normals = packed[:, 4:7]
    length = np.linalg.norm(vertex_normals, axis=1, keepdims=True)
    vertex_normals = np.divide(vertex_normals, length, out=np.zeros_like(vertex_normals), where=length > 0)
    mesh_triangles, ranges = _sorted_by_image(
        mesh_triangles, np.concatenate(mesh_image) if mesh_image else np.zeros(0, int))
    geometry = DrawGeometry(
        shift=shift,
        prepass_positions=np.concatenate(positions) if positions else np.zeros((0, 3), np.float32),
        prepass_colors=np.concatenate(vertex_colors) if vertex_colors else np.zeros((0, 4), np.float32),
        prepass_labels=np.concatenate(labels) if labels else np.zeros((0, 4), np.float32),
        prepass_normals=np.concatenate(normals) if normals else np.zeros((0, 4), np.float32),
        prepass_uvs=np.concatenate(uvs) if uvs else np.zeros((0, 2), np.float32),
        prepass_triangles=prepass_triangles,
        vertices=vertices,
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

    def __init__(self, width: int, height: int):
        import gpu

        self.width, self.height = int(width), int(height)
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
        zero = np.zeros(4, np.float32)
        self.no_trace = gpu.types.GPUTexture((1, 1), format='RGBA32F', data=gpu.types.Buffer('FLOAT', 4, zero))
        self.traced = None  # RGBA32F of the traced band of the last frame, or None
        self._output = None

    def fits(self, width: int, height: int) -> bool:
        return (self.width, self.height) == (int(width), int(height))

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


def _points_batch(positions: np.ndarray):
    """A POINTS batch of (N, 3) float32 positions (the projection pass's input)."""
    import gpu

    return gpu.types.GPUBatch(type='POINTS', buf=_vertex_buffer({"position": (positions, 'F32', 'FLOAT')}))


def _runs(values: np.ndarray) -> list:
    """(value, first, count) of each run of equal consecutive ``values``."""
    values = np.asarray(values)
    if len(values) == 0:
        return []
    starts = np.flatnonzero(np.r_[True, values[1:] != values[:-1]])
    counts = np.diff(np.r_[starts, len(values)])
    return [(int(values[k]), int(k), int(n)) for k, n in zip(starts, counts)]


#: Vertices per chunk of the per-sheet culling: runs of the Morton-sorted vertices
#: (:func:`sheet_bounds.morton_order`), each with its AABB.
CHUNK_VERTICES = 512
#: Cameras whose projections a renderer keeps (a viewport region each, as operators/live.py's MAX_VIEWS).
CACHED_PROJECTIONS = 8


def _same_view(a, b) -> bool:
    """Whether two views are exactly the same (size and matrices)."""
    return a is b or ((a.width, a.height) == (b.width, b.height)
                      and np.array_equal(np.asarray(a.view_matrix), np.asarray(b.view_matrix))
                      and np.array_equal(np.asarray(a.projection_matrix), np.asarray(b.projection_matrix)))


def reflected_depth(order: int, distance: np.ndarray, setup: dict) -> np.ndarray:
    """The depth that orders reflections, as ``glsl/reflection_project_vert.glsl`` writes it:
    (k - 1 + z / D) g (SBC paper V-A), z the distance along the reflected ray."""
    return (order - 1 + np.clip(distance * setup["inverse_diameter"], 0.0, 1.0)) * setup["order_range"]


def _polish_readback(camera, positions, draws: list, points: np.ndarray, eyes: np.ndarray, setup: dict) -> None:
    """Polish, in place, the GPU pass's first-order answers of ray-list leaves and fold
    cells on the true reflected rays, as the camera's numpy projection does
    (``SampleBasedCamera.polish_answers``; the GLSL twin interpolates only): new pixel,
    depth, eye vector and distance where polished, not projected where polishing fails."""
    for group, order, offset, first, count in draws:
        if len(camera.histories[group]) != 1:
            continue
        answered = np.flatnonzero(points[offset + first:offset + first + count, 3] > 0.5)
        if len(answered) == 0:
            continue
        texels = offset + first + answered
        position = np.asarray(positions[first + answered], dtype=np.float64)
        pixels, reflector_points, distance, ok = camera.polish_answers(
            group, points[texels, :2], position, np.rint(points[texels, 3]).astype(np.int8))
        points[texels[~ok]] = 0.0
        eyes[texels[~ok]] = 0.0
        polished = np.flatnonzero(ok & np.isfinite(distance))
        moved = texels[polished]
        points[moved, :3] = np.c_[pixels[polished], reflected_depth(order, distance[polished], setup)]
        eyes[moved] = np.c_[reflector_points[polished] - position[polished], distance[polished]]


def _subdivision_caps(source, sheets: list):
    """The largest mixed-triangle sub-grid each of ``sheets`` allows (``None``: the
    renderer's): a source whose points cost much more to project than the GPU pass
    (``MorphSource``) caps it."""
    caps = getattr(source, "sheet_subdivisions", None)
    return None if caps is None else [caps[sheet] for sheet in sheets]


def _culling(source, camera, diameter: float):
    """Per-sheet k-DOPs and bounding cones of ``source`` that cull vertex chunks
    (:mod:`..addon.sheet_bounds`; a ``None`` entry culls nothing), or ``None``."""
    if isinstance(source, SheetSources):
        return source.culling(diameter)
    if camera is None:
        return None
    return sheet_bounds.sheet_kdops(camera, diameter), getattr(camera, "cones", None)


class SheetSources:
    """Sheets of several projection sources drawn as one camera: a runtime camera's
    textures with some of its sheets left out (reflectors drawn from a morphing grid
    instead) and morphing grids (:class:`.morph_source.MorphSource`).

    ``parts``: (source, indices of its sheets kept, the ``SampleBasedCamera`` of a
    camera's textures or ``None``); ``view``: the view all of them project in. Sheets of
    one reflection history must stay consecutive (a history is in one part only).
    """

    def __init__(self, parts, view):
        self.parts = [(source, [int(k) for k in kept], camera) for source, kept, camera in parts if len(kept)]
        self.view = view
        self.groups = [source.groups[k] for source, kept, _ in self.parts for k in kept]
        self.downsample = max((source.downsample for source, _, _ in self.parts), default=1)
        self.sheet_subdivisions = [cap for source, kept, _ in self.parts
                                   for cap in (_subdivision_caps(source, kept) or [MIXED_SUBDIVISIONS] * len(kept))]

    def project(self, renderer, positions, batch, draws: list, n_texels: int, setup: dict, static: bool = False):
        """Each part projects its own sheets' draws; texels not drawn are 0 in every part."""
        points = np.zeros((n_texels, 4), np.float32)
        eyes = np.zeros((n_texels, 4), np.float32)
        offset = 0
        for source, kept, camera in self.parts:
            mine = [(kept[group - offset],) + tuple(rest) for group, *rest in draws
                    if offset <= group < offset + len(kept)]
            offset += len(kept)
            if mine:
                part_points, part_eyes = renderer._project_points(source, positions, batch, mine, n_texels, setup,
                                                                  static, camera)
                points += part_points
                eyes += part_eyes
        return points, eyes

    def culling(self, diameter: float):
        kdops, cones = [], []
        for source, kept, camera in self.parts:
            own = _culling(source, camera, diameter)
            kdops += [None if own is None else own[0][k] for k in kept]
            cones += [None if own is None or own[1] is None else own[1][k] for k in kept]
        return kdops, cones


@dataclass
class CachedProjection:
    """The reflected triangles of one sample-based camera over the renderer's meshes.

    Made once per camera (or per mesh change: a new renderer) by
    :meth:`ReflectionRenderer.projection`, drawn every frame. Every vertex of a drawn
    reflected triangle holds its first reflector point in world space, its depth (order
    and distance along the reflected ray, SBC V-A), its camera-view pixel, its eye vector
    and reflected distance (SBC V-C, V-D) and its mesh's colour, normal and UVs.
    """

    source: object  # the projection.SBCTextures or other source it was made from (identity = the cache key)
    camera_view: object  # the view the camera was built for
    batch: object  # GPUBatch of the triangles (un-indexed), or None when nothing is reflected
    runs: tuple  # (image index or -1, first vertex, vertex count), in drawing order
    triangles: int
    mixed_triangles: int
    stats: dict = field(default_factory=dict)
    camera: object = None  # the SampleBasedCamera, when :meth:`ReflectionRenderer.render` was given it
    #: Reflectors whose first-order sheets it leaves to the passes run every frame (the
    #: iterative search; the morphing grids covering ``camera_view``).
    per_frame: frozenset = frozenset()


@functools.cache
def _coarse_cover(n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """For the n x n and m x m barycentric sub-grids (m divides n): the m-grid sub-triangle
    holding each n-grid sub-triangle (n^2,), and the m-grid sub-triangles as n-grid vertex
    indices (m^2, 3): a coarse sub-triangle's corners are points of the fine grid."""
    fine_points, fine_triangles = subdivision.barycentric_grid(n)
    coarse_points, coarse_triangles = subdivision.barycentric_grid(m)

    def grid_ij(points, size):
        i = np.rint(points[:, 1] * size).astype(np.int64)
        return i, size - np.rint(points[:, 0] * size).astype(np.int64) - i

    def cell_key(i, j, triangles, scale):
        ci, cj = i[triangles].mean(axis=1) / scale, j[triangles].mean(axis=1) / scale
        a, b = np.floor(ci).astype(np.int64), np.floor(cj).astype(np.int64)
        return ((a * m + b) * 2 + ((ci - a) + (cj - b) > 1.0)).astype(np.int64)

    fi, fj = grid_ij(fine_points, n)
    ci, cj = grid_ij(coarse_points, m)
    lookup = np.full(2 * m * m, -1, np.int64)
    lookup[cell_key(ci, cj, coarse_triangles, 1)] = np.arange(len(coarse_triangles))
    coarse_of_fine = lookup[cell_key(fi, fj, fine_triangles, n // m)]
    index = np.full((n + 1, n + 1), -1, np.int64)
    index[fi, fj] = np.arange(len(fi))
    factor = n // m
    coarse_in_fine = index[ci[coarse_triangles] * factor, cj[coarse_triangles] * factor]
    return coarse_of_fine, coarse_in_fine


class ReflectionRenderer:
    """One scene's reflected geometry and GPU batches; draws it for any view and camera.

    Build it once per scene change (subdivision runs here, once per mesh). The projection
    of the meshes with a sample-based camera is made once per camera
    (:meth:`projection`, cached until another camera's textures are drawn) and
    :meth:`draw` or :meth:`render` draws any view with it. ``cull``: project in each
    sheet only the vertex chunks that meet the sheet's k-DOP (:mod:`..addon.sheet_bounds`;
    needs the camera itself, not only its textures). ``polish``: the GPU's ray-list and
    fold-cell answers are polished on the true rays on the CPU (needs the camera too;
    exact, but the numpy BVH makes it seconds per camera: the live viewport turns it off).
    ``iterative``: the star-shaped reflectors the iterative search draws every frame
    (:mod:`.iterative_draw`); a camera's sheets of their first-order reflections are not
    projected, and with no other reflector the renderer draws with no camera at all.
    ``morph``: (``MorphingGrid``, object matrix) of the reflectors drawn from their baked
    grids every frame where the view is inside the grid (:mod:`.morph_pass`, node images
    kept on the GPU within ``morph_budget_mb``); likewise left out of a camera's
    projection made for a view inside the grid.
    """

    def __init__(self, reflectors, meshes, reflector_colors=None, reflectivity=None,
                 edge_fraction: float | None = subdivision.EDGE_FRACTION, *, fresnel_f0=None,
                 attenuation_distance=None, mixed_subdivisions: int = MIXED_SUBDIVISIONS, cull: bool = True,
                 polish: bool = True, iterative=(), morph=(), morph_budget_mb: float = DEFAULT_BUDGET_MB):
        self.geometry = prepare_geometry(reflectors, meshes, reflector_colors, reflectivity, edge_fraction,
                                         fresnel_f0, attenuation_distance)
        #: The diffuse meshes on the GPU, placed by the per-frame passes' answers.
        self.meshes = ReflectedMeshes(self.geometry)
        #: The star-shaped reflectors drawn by the iterative search every frame
        #: (``addon.methods.iterative.IterativeReflector`` each); the others by ``textures``.
        self.iterative = IterativePass(self.geometry, iterative, self.meshes)
        #: The reflectors drawn from their morphing grids every frame (views inside a grid).
        self.morph = MorphPass(self.geometry, morph, self.meshes, morph_budget_mb)
        self.mixed_subdivisions = int(mixed_subdivisions)
        self.cull = bool(cull)
        self.polish = bool(polish)
        self.stats = dict(self.geometry.stats)
        #: Names this renderer's vertices for sources that keep work for them (MorphSource).
        self.vertices_token = object()
        self.counts = {"projections": 0, "frames": 0}
        self._reflectors, self._meshes = list(reflectors), list(meshes)
        self._batches = None
        self._targets = None
        self._tracer = None
        self._projection = None  # the last one drawn
        self._cache: dict = {}  # id(textures) -> CachedProjection, least recently drawn first
        g = self.geometry
        self._triangle_image = np.full(len(g.triangles), -1, np.int64)
        for image, first, count in g.ranges:
            self._triangle_image[first:first + count] = image
        self._chunk_boxes = sheet_bounds.chunk_boxes(g.vertices, CHUNK_VERTICES) if len(g.vertices) else None

    def _make_batches(self) -> dict:
        """Vertex buffers of the pre-pass and of the projection's points, and the images."""
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
            batches["points"] = _points_batch(g.vertices.astype(np.float32))
        batches["images"] = [_data_texture(image, image.shape[1]) for image in g.images]
        batches["no_image"] = _data_texture(np.ones((1, 4)))
        screen = _vertex_buffer({"position": (np.array([[-1, -1], [3, -1], [-1, 3]], np.float32), 'F32', 'FLOAT')})
        batches["screen"] = gpu.types.GPUBatch(type='TRIS', buf=screen)
        return batches

    def _image(self, index: int):
        return self._batches["images"][index] if index >= 0 else self._batches["no_image"]

    def targets(self, width: int, height: int) -> FrameTargets:
        """The frame targets for this size, reused while they fit."""
        if self._targets is None or not self._targets.fits(width, height):
            self._targets = FrameTargets(width, height)
        return self._targets

    def per_frame_reflectors(self, view) -> frozenset:
        """The reflectors whose first-order reflections of ``view`` the per-frame passes
        draw: the searched ones, and those whose grid covers the view."""
        return frozenset(self.iterative.reflector_indices) | frozenset(
            self.morph.grids[k][0].reflector_index for k, _ in self.morph.covering(view))

    def invalidate(self) -> None:
        """Forget the cached projections: the next draw projects again."""
        self._projection = None
        self._cache.clear()

    def draw(self, view, textures, world_color=(0.0, 0.0, 0.0, 1.0), reflectors_only: bool = False,
             fill_radius: int | None = None, camera=None) -> FrameTargets:
        """Pre-pass and reflections of ``view`` into the frame targets
        (:meth:`draw_passes`), then the composite into the framebuffer bound by the
        caller (:meth:`composite`). What a viewport draw handler calls, with the
        region's view (``operators.capture.view_from_region``); nothing is read back.

        ``textures`` is a sample-based camera as ``projection.SBCTextures``, ``camera``
        the camera itself (optional; see :meth:`draw_passes`); ``world_color`` the
        linear RGB(A) that reflected rays leaving the scene show; ``fill_radius`` the
        composite's cheap fill of the band along a footprint's edge (``None``: the
        camera's down-sampling), where :meth:`render` traces instead.
        """
        import gpu

        targets = self.draw_passes(view, textures, camera, warm=True)
        if fill_radius is None:
            fill_radius = 0 if textures is None else textures.downsample
        x, y, width, height = gpu.state.viewport_get()
        # A viewport of the view's size is drawn into where it is; otherwise from (0, 0).
        origin = (x, y) if (width, height) == (targets.width, targets.height) else None
        self.composite(targets, world_color, reflectors_only, fill_radius, origin)
        return targets

    def draw_passes(self, view, textures, camera=None, warm: bool = False) -> FrameTargets:
        """The pre-pass and the reflected triangles of ``view`` into its frame targets.

        The reflected triangles come from :meth:`projection` of ``textures``: made now
        when these textures are not the cached ones, else reused. The projection is made
        in the camera's own view: ``camera.ray_map.view`` when the camera is given, else
        ``view`` (which must then be the camera's view). A ``view`` other than the
        camera's (the viewport moved, a new camera is being built) draws the cached
        first reflector points where ``view`` sees them. The iterative search's
        reflectors are searched for ``view`` itself; ``warm`` starts each vertex from
        its last answer (the viewport's :meth:`draw` does; a render does not, so that
        its image depends on its view alone).
        """
        import gpu
        from mathutils import Matrix

        if self._batches is None:
            self._batches = self._make_batches()
        batches, g = self._batches, self.geometry
        camera_view = camera.ray_map.view if camera is not None else getattr(textures, "view", view)
        cached = None if textures is None else self.projection(textures, camera_view, camera)
        targets = self.targets(view.width, view.height)
        width, height = targets.width, targets.height
        translate = np.eye(4)
        translate[:3, 3] = g.shift
        view_projection = Matrix((np.asarray(view.projection_matrix) @ np.asarray(view.view_matrix)
                                  @ translate).tolist())
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
                    shader.uniform_float("view_projection", view_projection)
                    shader.uniform_float("camera", _camera(view, g.shift))
                    for image, batch in batches["prepass"]:
                        shader.uniform_int("use_image", int(image >= 0))
                        shader.uniform_sampler("image", self._image(image))
                        batch.draw(shader)
            self.iterative.search(view, warm)
            # A grid's reflector is blended here unless the camera's projection draws it.
            self.morph.blend(view, skip=set() if cached is None else
                             set(self.morph.reflector_indices) - cached.per_frame)
            answers = self.iterative.answers() + self.morph.answers()
            with targets.reflection.bind():
                gpu.state.viewport_set(0, 0, width, height)
                targets.reflection.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
                if answers:
                    gpu.state.depth_test_set('LESS')
                    gpu.state.depth_mask_set(True)
                    self.meshes.draw(view_projection, targets.prepass_labels,
                                     {"inverse_diameter": 1.0 / g.diameter, "order_range": ITERATIVE_ORDER_RANGE},
                                     self._image, answers)
                if cached is not None and cached.batch is not None:
                    gpu.state.depth_test_set('LESS')
                    gpu.state.depth_mask_set(True)
                    shader = _shader("reflected")
                    shader.bind()
                    shader.uniform_float("view_projection", view_projection)
                    shader.uniform_float("view_size", (float(width), float(height)))
                    shader.uniform_int("use_camera_pixel", int(_same_view(view, cached.camera_view)))
                    shader.uniform_sampler("prepass_labels", targets.prepass_labels)
                    for image, first, count in cached.runs:
                        shader.uniform_int("use_image", int(image >= 0))
                        shader.uniform_sampler("image", self._image(image))
                        cached.batch.draw_range(shader, elem_start=first, elem_count=count)
        self.stats["mixed_triangles"] = 0 if cached is None else cached.mixed_triangles
        self.counts["frames"] += 1
        targets.traced = None
        return targets

    def projection(self, textures, camera_view, camera=None) -> CachedProjection:
        """The reflected triangles of ``textures``'s camera, built in ``camera_view``:
        the cached ones when they were made from these textures (the last
        :data:`CACHED_PROJECTIONS` cameras drawn are kept: one per viewport region),
        else made now."""
        key = id(textures)
        cached = self._cache.pop(key, None)
        if cached is None or cached.source is not textures:
            while len(self._cache) >= CACHED_PROJECTIONS:
                self._cache.pop(next(iter(self._cache)))
            cached = self._project(textures, camera_view, camera)
            self.stats.update(cached.stats)
        self._cache[key] = cached  # most recently used last
        self._projection = cached
        return cached

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
                   edges_of_drawn: bool = False, ray_map=None, camera=None, holes_of=()) -> int:
        """Trace the reflector pixels along each footprint's edge that got no reflection
        (:mod:`.band_trace`): reads the pre-pass ids and the reflection coverage back,
        traces those pixels on the CPU and uploads their colours for the composite. With
        the camera's ``ray_map``, also those between ray-map cells of different histories
        (:func:`band_trace.history_boundary`: the edge of a second-order reflection inside
        a footprint). With the ``camera`` itself, also the pixels without a drawn
        reflection in cells where its projection is unreliable
        (:func:`band_trace.unreliable_cells`: ray-list leaves, fold and mixed cells).
        ``holes_of``: reflector indices (drawn from morphing grids) every pixel of which
        without a drawn reflection is traced: where the blend has no answer (the parts of
        the mirror not all four nodes see, and triangles with such a corner), but also
        where the mirror shows the world, so it costs many rays.
        More than :data:`MAX_TRACED_FRACTION` of the image is not a band: then nothing is
        traced (``stats["untraced_pixels"]``, and ``targets.traced`` stays None: the
        composite fills), except for ``holes_of``, which the caller asked for.
        Returns how many pixels were traced."""
        import gpu

        if self._tracer is None:
            self._tracer = band_trace.BandTracer(self._reflectors, self._meshes)
        labels = _read_texture(targets.prepass_labels, targets.width, targets.height)[..., 0]
        # The iterative search reaches a mirror's silhouette: its reflectors have no band.
        labels = np.where(np.isin(np.rint(labels) - 1, self.iterative.reflector_indices), 0.0, labels)
        drawn = _read_texture(targets.reflection_colors, targets.width, targets.height)[..., 3] > 0.5
        boundary = None if ray_map is None else band_trace.history_boundary(
            ray_map, targets.width, targets.height, max_order)
        if camera is not None:
            # Cells where the camera knows it may not project (ray lists, folds, mixed).
            unreliable = band_trace.cell_pixels_mask(
                band_trace.unreliable_cells(camera.ray_map, camera.trees, camera.mixed, camera.folds),
                camera.ray_map.downsample, targets.width, targets.height)
            boundary = unreliable if boundary is None else boundary | unreliable
        if len(holes_of):
            holes = np.isin(np.rint(labels) - 1, list(holes_of))
            boundary = holes if boundary is None else boundary | holes
        pixels = band_trace.band_pixels(labels, drawn, radius, edges_of_drawn, boundary)
        self.stats["untraced_pixels"] = 0
        if not len(holes_of) and len(pixels) > MAX_TRACED_FRACTION * targets.width * targets.height:
            # Not a band but most of the mirror (the near plane cutting it, the eye on it):
            # tracing it would cost many frames' time; the composite fills it instead.
            self.stats["untraced_pixels"] = int(len(pixels))
            targets.traced = None
            return 0
        traced = np.zeros((targets.height, targets.width, 4), np.float32)
        if len(pixels):
            colors = self._tracer.trace(view, pixels + 0.5, max_order, _rgba(world_color))
            traced[pixels[:, 1], pixels[:, 0], :3] = colors[:, :3]
            # As a drawn reflection's: 1 + the distance from the mirror (attenuation, SBC V-D).
            traced[pixels[:, 1], pixels[:, 0], 3] = 1.0 + np.minimum(colors[:, 3], 1e30)
        data = gpu.types.Buffer('FLOAT', traced.size, traced.reshape(-1))
        targets.traced = gpu.types.GPUTexture((targets.width, targets.height), format='RGBA32F', data=data)
        return int(len(pixels))

    def _vertex_runs(self, kdops, sheet: int) -> list:
        """(first, count) runs of vertices to project in ``sheet``: all of them without
        culling, else the chunks meeting the sheet's k-DOP, neighbouring chunks merged."""
        n = len(self.geometry.vertices)
        if kdops is None or kdops[0][sheet] is None:  # no culling, or a sheet without bounds (SheetSources)
            return [(0, n)]
        lo, hi = self._chunk_boxes
        kdop, cone = kdops[0][sheet], None if kdops[1] is None else kdops[1][sheet]
        meeting = sheet_bounds.chunks_meeting(lo, hi, kdop)
        if cone is not None:
            meeting &= sheet_bounds.chunks_in_cone(lo, hi, cone)
        chosen = np.flatnonzero(meeting)
        if len(chosen) == 0:
            return []
        breaks = np.flatnonzero(np.diff(chosen) > 1)
        starts = chosen[np.r_[0, breaks + 1]]
        ends = chosen[np.r_[breaks, len(chosen) - 1]] + 1
        return [(int(a) * CHUNK_VERTICES, int(min(b * CHUNK_VERTICES, n) - a * CHUNK_VERTICES))
                for a, b in zip(starts, ends)]

    def _project(self, textures, camera_view, camera) -> CachedProjection:
        """Project the meshes with the camera of ``textures`` (SBC V-A) and decide, from
        the read-back, which reflected triangles are drawn (V-B): per sheet, those with
        every corner projected in it or, across a seam, in another sheet of its history
        within :data:`STITCH_CELLS` cells; mixed triangles (one or two corners projected,
        none stitched) as sub-grids of about :data:`MIXED_SUB_PX` whose sub-vertices are
        projected on their own, keeping the sub-triangles whose three sub-vertices project.
        """
        import gpu
        from mathutils import Matrix

        start = time.perf_counter()
        self.counts["projections"] += 1
        if self._batches is None:
            self._batches = self._make_batches()
        g = self.geometry
        histories = list(textures.groups)
        n_vertices = len(g.vertices)
        if n_vertices == 0 or not histories or "points" not in self._batches:
            return CachedProjection(textures, camera_view, None, (), 0, 0, {
                "projection_seconds": 0.0, "projected_vertices": 0, "unculled_vertices": 0, "mixed_sub_triangles": 0},
                per_frame=self.per_frame_reflectors(camera_view))
        world_to_clip = np.asarray(camera_view.projection_matrix) @ np.asarray(camera_view.view_matrix)
        setup = {"inverse_view_projection": Matrix(np.linalg.inv(world_to_clip).tolist()),
                 "view_size": (float(camera_view.width), float(camera_view.height)),
                 "order_range": 1.0 / (max(len(h) for h in histories) + 1)}
        setup["inverse_diameter"] = 1.0 / g.diameter
        stitch_px = STITCH_CELLS * textures.downsample
        kdops = _culling(textures, camera, g.diameter) if self.cull else None
        pieces, mixed_blocks, projected = [], [], 0
        per_frame = self.per_frame_reflectors(camera_view)
        for sheets in _sheet_chunks(histories, max(1, MAX_PROJECTED_TEXELS // n_vertices)):
            history = histories[sheets[0]]
            if len(history) == 1 and history[0] in per_frame:
                continue  # the iterative search or a grid draws these first-order reflections every frame
            draws = []
            for layer, sheet in enumerate(sheets):
                for first, count in self._vertex_runs(kdops, sheet):
                    draws.append((sheet, len(history), layer * n_vertices, first, count))
                    projected += count
            points, eyes = self._project_points(textures, g.vertices, self._batches["points"], draws,
                                                len(sheets) * n_vertices, setup, static=True, camera=camera)
            points = points.reshape(len(sheets), n_vertices, 4)
            eyes = eyes.reshape(len(sheets), n_vertices, 4)
            pieces += self._full_triangles(points, eyes, history, stitch_px)
            if self.mixed_subdivisions > 0:
                blocks = self._mixed_instances(points, sheets, len(history), _subdivision_caps(textures, sheets))
                pieces += [("mixed", len(mixed_blocks) + k) for k in range(len(blocks))]
                mixed_blocks += blocks
        mixed_pieces = self._mixed_triangles(textures, mixed_blocks, setup, camera)
        n_mixed = sum(len(b[2]) for b in mixed_blocks)
        stats = {"projected_vertices": projected, "unculled_vertices": len(histories) * n_vertices,
                 "mixed_sub_triangles": sum(len(p[1]["world_depth"]) for p in mixed_pieces) // 3}
        pieces = [mixed_pieces[p[1]] if p[0] == "mixed" else p for p in pieces]
        pieces = [p for p in pieces if len(p[1]["world_depth"])]
        if not pieces:
            stats["projection_seconds"] = time.perf_counter() - start
            return CachedProjection(textures, camera_view, None, (), 0, n_mixed, stats, per_frame=per_frame)
        runs, first = [], 0
        for image, arrays in pieces:
            count = len(arrays["world_depth"])
            if runs and runs[-1][0] == image:
                runs[-1] = (image, runs[-1][1], runs[-1][2] + count)
            else:
                runs.append((image, first, count))
            first += count
        names = ("world_depth", "pixel_reflector", "eye_distance", "color", "normal_lit", "uv")
        buffer = _vertex_buffer({name: (np.concatenate([p[1][name] for p in pieces]).astype(np.float32), 'F32',
                                        'FLOAT') for name in names})
        batch = gpu.types.GPUBatch(type='TRIS', buf=buffer)
        stats["projection_seconds"] = time.perf_counter() - start
        return CachedProjection(textures, camera_view, batch, tuple(runs), first // 3, n_mixed, stats,
                                per_frame=per_frame)

    def _project_pass(self, textures, batch, draws: list, n_texels: int, setup: dict):
        """Project the points of ``batch`` with ``textures``: per (group, order, texel
        offset, first, count) of ``draws`` the points first .. first + count - 1 into
        texels offset + index. Returns the two targets read back, (n_texels, 4) each:
        (pixel, depth, valid) and (eye vector, reflected distance)
        (``glsl/reflection_project_vert.glsl``); texels of points not drawn are 0 (invalid)."""
        import gpu

        columns = max(1, min(n_texels, projection.sbc_pack.TEXTURE_WIDTH))
        rows = max(1, -(-n_texels // columns))
        points = gpu.types.GPUTexture((columns, rows), format='RGBA32F')
        eyes = gpu.types.GPUTexture((columns, rows), format='RGBA32F')
        framebuffer = gpu.types.GPUFrameBuffer(color_slots=(points, eyes))
        with _saved_state(), framebuffer.bind():
            gpu.state.blend_set('NONE')
            gpu.state.viewport_set(0, 0, columns, rows)
            framebuffer.clear(color=(0.0, 0.0, 0.0, 0.0))
            gpu.state.depth_test_set('NONE')
            gpu.state.program_point_size_set(True)
            try:
                shader = _shader("project")
                shader.bind()
                shader.uniform_float("inverse_view_projection", setup["inverse_view_projection"])
                shader.uniform_float("view_size", setup["view_size"])
                shader.uniform_int("target_size", (columns, rows))
                shader.uniform_float("inverse_diameter", 1.0 / self.geometry.diameter)
                shader.uniform_float("order_range", setup["order_range"])
                textures.bind(shader)
                for group, order, offset, first, count in draws:
                    shader.uniform_int("group", int(group))
                    shader.uniform_int("order", int(order))
                    shader.uniform_int("layer_offset", int(offset))
                    batch.draw_range(shader, elem_start=int(first), elem_count=int(count))
            finally:
                gpu.state.program_point_size_set(False)
        return (_read_texture(points, columns, rows).reshape(-1, 4)[:n_texels],
                _read_texture(eyes, columns, rows).reshape(-1, 4)[:n_texels])

    def _project_points(self, source, positions, batch, draws: list, n_texels: int, setup: dict,
                        static: bool = False, camera=None):
        """The projection pass of ``draws`` (as :meth:`_project_pass`) with any source: a
        camera's textures on the GPU, else the source's own ``project`` (morphing grids,
        :class:`SheetSources`). ``positions`` are the points of ``batch`` (made from them
        when ``None``); ``static``: they are this renderer's own vertices, which a source
        may keep work for between views (morphing's node images, SBC paper VI). With the
        ``camera`` of the textures, risky answers are polished on the true rays as its
        numpy projection polishes them (:func:`_polish_readback`)."""
        if isinstance(source, projection.SBCTextures):
            if batch is None:
                batch = _points_batch(np.asarray(positions, np.float32))
            points, eyes = self._project_pass(source, batch, draws, n_texels, setup)
            if self.polish and getattr(camera, "true_rays", None) is not None:
                _polish_readback(camera, positions, draws, points, eyes, setup)
            return points, eyes
        return source.project(self, positions, batch, draws, n_texels, setup, static)

    def _vertex_arrays(self, positions, points, eyes, reflector: float, color, normal_lit, uv) -> dict:
        """Per-vertex arrays of drawn reflected triangles (``glsl/reflection_mesh_vert.glsl``)."""
        n = len(points)
        world = np.asarray(positions, np.float64) + eyes[:, :3] - self.geometry.shift
        return {"world_depth": np.c_[world, points[:, 2]],
                "pixel_reflector": np.c_[points[:, :2], np.full(n, reflector), np.zeros(n)],
                "eye_distance": eyes, "color": color, "normal_lit": normal_lit, "uv": uv}

    def _full_triangles(self, points, eyes, history, stitch_px: float) -> list:
        """(image, per-vertex arrays) pieces of the triangles drawn whole, per sheet (layer)
        of one history, in triangle order: those with a corner projected in the sheet and
        every other corner in it or, stitched, in another sheet of the history: the one
        nearest in the image to the triangle's first corner projected here, within
        ``stitch_px`` (a point can have two images in two sheets; a corner must not be
        joined to its other image across the mirror)."""
        g = self.geometry
        n_layers = len(points)
        valid = points[..., 3] > 0.5
        reflector = float(history[0]) + 1.0
        limit = np.float32(stitch_px) ** 2
        pieces = []
        for layer in range(n_layers):
            own = valid[layer][g.triangles]
            candidates = np.flatnonzero(own.any(axis=1))
            if len(candidates) == 0:
                continue
            corners, own = g.triangles[candidates], own[candidates]
            layer_of = np.full(corners.shape, layer)
            ok = own.copy()
            partial = ~own.all(axis=1)
            if partial.any() and n_layers > 1:
                anchor = points[layer, corners[np.arange(len(corners)), own.argmax(axis=1)], :2]
                for k in range(3):
                    need = partial & ~own[:, k]
                    if not need.any():
                        continue
                    index = corners[need, k]
                    offset = points[:, index, :2] - anchor[need][None]
                    distance2 = (offset * offset).sum(axis=2)
                    near = valid[:, index] & (distance2 <= limit)
                    near[layer] = False
                    distance2 = np.where(near, distance2, np.inf)[::-1]  # ties: the last layer, as the GPU did
                    layer_of[need, k] = n_layers - 1 - distance2.argmin(axis=0)
                    ok[need, k] = np.isfinite(distance2.min(axis=0))
            drawn = ok.all(axis=1)
            if not drawn.any():
                continue
            vertex, layers = corners[drawn].reshape(-1), layer_of[drawn].reshape(-1)
            arrays = self._vertex_arrays(g.vertices[vertex].astype(np.float32), points[layers, vertex],
                                         eyes[layers, vertex], reflector, g.colors[vertex],
                                         np.c_[g.normals[vertex], g.lit[vertex]], g.uvs[vertex])
            image = np.repeat(self._triangle_image[candidates[drawn]], 3)
            for value, first, count in _runs(image):
                pieces.append((value, {k: v[first:first + count] for k, v in arrays.items()}))
        return pieces

    def _mixed_instances(self, points, sheets: list, order: int, caps=None) -> list:
        """Mixed triangles of ``sheets`` (SBC V-B) as (image, n, corners, group, order)
        blocks, n the sub-grid (a power of two up to ``mixed_subdivisions``, so that
        sub-triangles span about :data:`MIXED_SUB_PX`): one or two corners project in the
        sheet and not every corner projects in some sheet of the history (those are
        stitched)."""
        g = self.geometry
        valid = points[..., 3] > 0.5
        somewhere = valid.any(axis=0)[g.triangles].all(axis=1)
        # A mixed triangle's size in pixels is estimated from its longest edge.
        longest = np.max([np.linalg.norm(g.vertices[g.triangles[:, k]] - g.vertices[g.triangles[:, (k + 1) % 3]],
                                         axis=1) for k in range(3)], axis=0)
        # Pixels per world unit at each vertex: the largest over the edges of the fully
        # projected triangles around it (local, so that a magnified part of a sheet, near a
        # silhouette, does not refine every mixed triangle of the sheet); a mixed triangle
        # without such a neighbour takes the sheet's largest.
        scales = []
        for layer in range(len(sheets)):
            own = valid[layer][g.triangles]
            full = np.flatnonzero(own.all(axis=1))
            vertex_scale = np.zeros(len(g.vertices))
            largest = 0.0
            for k in range(3):
                a, b = g.triangles[full, k], g.triangles[full, (k + 1) % 3]
                length = np.linalg.norm(g.vertices[b] - g.vertices[a], axis=1)
                ratio = np.linalg.norm(points[layer, b, :2] - points[layer, a, :2], axis=1) / np.where(
                    length > 0, length, np.inf)
                np.maximum.at(vertex_scale, a, ratio)
                np.maximum.at(vertex_scale, b, ratio)
                largest = max(largest, float(ratio.max(initial=0.0)))
            scales.append((vertex_scale, largest if len(full) else np.inf))
        blocks = []
        for image, first, count in g.ranges:
            triangles = g.triangles[first:first + count]
            by_level: dict = {}
            for layer, group in enumerate(sheets):
                own = valid[layer][triangles]
                chosen = np.flatnonzero(own.any(axis=1) & ~own.all(axis=1) & ~somewhere[first:first + count])
                if len(chosen) == 0:
                    continue
                vertex_scale, largest = scales[layer]
                scale = vertex_scale[triangles[chosen]].max(axis=1)
                scale = np.where(scale > 0, scale, largest)
                size_px = scale * longest[first:first + count][chosen]
                cap = self.mixed_subdivisions if caps is None else min(self.mixed_subdivisions, caps[layer])
                wanted = np.clip(np.nan_to_num(size_px / MIXED_SUB_PX, posinf=1e9), 1, cap)
                level = np.minimum(np.ceil(np.log2(wanted)).astype(np.int64), int(np.log2(max(1, cap))))
                for value in np.unique(level):
                    by_level.setdefault(int(value), []).append((triangles[chosen[level == value]],
                                                                np.full(int((level == value).sum()), group)))
            for value, parts in by_level.items():
                blocks.append((image, 1 << value, np.concatenate([p[0] for p in parts]),
                               np.concatenate([p[1] for p in parts]), order))
        return blocks

    def _mixed_triangles(self, textures, blocks: list, setup: dict, camera=None) -> list:
        """(image, per-vertex arrays) of each block of :meth:`_mixed_instances`: every
        sub-vertex (barycentric mix of the corners' data, :func:`subdivision.barycentric_grid`)
        projected with its sheet; sub-triangles with a sub-vertex that does not project
        are left out, so the reflection ends within about a sub-triangle of where
        projection ends instead of at the last whole triangle."""
        g = self.geometry
        if not blocks:
            return []
        vertices32 = g.vertices.astype(np.float32)
        grids, positions, groups, orders = [], [], [], []
        for image, n, corners, group, order in blocks:
            grid, sub_triangles = subdivision.barycentric_grid(n)
            w = grid.astype(np.float32)
            w = np.c_[w, np.float32(1.0) - w[:, 0] - w[:, 1]]  # (G, 3)
            grids.append((w, sub_triangles))
            positions.append(np.einsum("gk,mkc->mgc", w, vertices32[corners]).reshape(-1, 3))
            groups.append(np.repeat(group, len(w)))
            orders.append(np.full(len(w) * len(corners), order))
        positions, groups, orders = np.concatenate(positions), np.concatenate(groups), np.concatenate(orders)
        by_group = np.argsort(groups, kind="stable")
        points = np.zeros((len(positions), 4), np.float32)
        eyes = np.zeros((len(positions), 4), np.float32)
        for first in range(0, len(positions), MAX_PROJECTED_TEXELS):
            part = by_group[first:first + MAX_PROJECTED_TEXELS]
            draws = [(int(groups[part[a]]), int(orders[part[a]]), 0, int(a), int(c))
                     for _, a, c in _runs(groups[part])]
            projected, projected_eyes = self._project_points(textures, positions[part], None, draws, len(part),
                                                             setup, camera=camera)
            points[part], eyes[part] = projected, projected_eyes
        pieces, offset = [], 0
        for (image, n, corners, group, order), (w, sub_triangles) in zip(blocks, grids):
            m, size = len(corners), len(w)
            block = slice(offset, offset + m * size)
            offset += m * size
            valid = (points[block, 3] > 0.5).reshape(m, size)
            kept = valid[:, sub_triangles].all(axis=2)  # (m, sub-triangles)
            triangles_of = np.broadcast_to(sub_triangles, (m,) + sub_triangles.shape)
            if n >= MIXED_COARSE_FACTOR * 2:
                # Where a whole coarse sub-triangle (MIXED_COARSE_FACTOR^2 fine ones) projects,
                # it is drawn instead: the edge keeps the fine grid, the inside is interpolated
                # between projected points MIXED_COARSE_FACTOR sub-triangles apart.
                coarse_of_fine, coarse_in_fine = _coarse_cover(n, n // MIXED_COARSE_FACTOR)
                whole = np.ones((m, len(coarse_in_fine)), bool)
                np.logical_and.at(whole, (slice(None), coarse_of_fine), kept)
                kept = np.concatenate([kept & ~whole[:, coarse_of_fine], whole], axis=1)
                triangles_of = np.concatenate(
                    [triangles_of, np.broadcast_to(coarse_in_fine, (m,) + coarse_in_fine.shape)], axis=1)
            instance, sub = np.nonzero(kept)
            if len(instance) == 0:
                pieces.append((image, {"world_depth": np.zeros((0, 4))}))
                continue
            local = triangles_of[instance, sub].reshape(-1)  # sub-vertex in the grid
            owner = np.repeat(instance, 3)
            rows = owner * size + local
            c = corners[owner]
            weights = w[local]  # (k, 3)

            def mix(values):
                return np.einsum("kc,kcd->kd", weights, values[c].astype(np.float32))

            color = np.c_[mix(g.colors[:, :3]), np.ones(len(rows), np.float32)]
            lit = g.lit[c[:, 0]]
            normal_lit = np.c_[mix(g.normals), lit]
            reflector = np.asarray([float(h[0]) + 1.0 for h in textures.groups])[group[owner]]
            arrays = self._vertex_arrays(positions[block][rows], points[block][rows], eyes[block][rows], 0.0,
                                         color, normal_lit, mix(g.uvs))
            arrays["pixel_reflector"][:, 2] = reflector
            pieces.append((image, arrays))
        return pieces

    def render(self, view, sbc_or_textures, world_color=(0.0, 0.0, 0.0, 1.0), trace: bool = True,
               fill_radius: int | None = None, trace_edges: bool = False, trace_gaps: bool = False) -> np.ndarray:
        """Draw ``view`` offscreen and read it back: (H, W, 4) float32 linear RGBA, rows bottom to top.

        ``sbc_or_textures``: a ``SampleBasedCamera`` built for this view, its
        ``projection.SBCTextures``, another projection source of this view
        (:class:`SheetSources`, :class:`.morph_source.MorphSource`), or ``None`` when
        the per-frame passes (iterative search, morphing grids) draw every reflector.
        With ``trace`` the band along each footprint's edge that the camera cannot reach
        (d pixels wide) is ray traced (:meth:`trace_band`), and with ``trace_gaps`` every
        pixel of a mirror drawn from its grid that the blend left without a reflection
        (exact there, but tens of thousands of rays a frame: the sky's pixels too);
        without, it gets the composite's fill (``fill_radius``, ``None``: d). With
        ``trace_edges`` also the reflector pixels within d of a drawn reflection that got
        none: seams and creases; exact there, but no longer a purely feed-forward image
        (15-18 % of the mirror pixels of the demo scenes are traced). When
        ``sbc_or_textures`` is the camera itself, the pixels between ray-map cells of
        different histories are traced too (:func:`band_trace.history_boundary`).
        """
        start = time.perf_counter()
        textures, camera = sbc_or_textures, None
        if hasattr(sbc_or_textures, "ray_map"):  # the camera itself, not its textures or another source
            camera = sbc_or_textures
            cached = self._projection
            # The same camera again (a second render of it) keeps its projection.
            textures = cached.source if cached is not None and cached.camera is camera else (
                projection.SBCTextures(camera))
        uploaded = time.perf_counter()
        downsample = 0 if textures is None else textures.downsample
        targets = self.draw_passes(view, textures, camera)
        if camera is not None:
            self._projection.camera = camera
        drawn = time.perf_counter()
        traced = 0
        morphed = self.morph.drawn_reflectors if trace_gaps else []
        if trace and ((textures is not None and textures.groups) or morphed):
            max_order = max((len(h) for h in textures.groups), default=1) if textures is not None else 1
            traced = self.trace_band(view, targets, max_order, world_color, downsample, trace_edges,
                                     getattr(sbc_or_textures, "ray_map", None), camera, holes_of=morphed)
            fill_radius = 0 if targets.traced is not None else downsample
        elif fill_radius is None:
            fill_radius = downsample
        band = time.perf_counter()
        texture, framebuffer = targets.output
        with framebuffer.bind():
            self.composite(targets, world_color, False, fill_radius)
        image = _read_texture(texture, targets.width, targets.height)
        end = time.perf_counter()
        self.stats["iterative"] = self.iterative.status_counts()
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
