# SPDX-License-Identifier: GPL-3.0-or-later
"""A sample-based camera's reflected triangles over the renderer's meshes: made once per
camera, drawn every frame (SBC paper, Popescu, Sacks, Mei 2006, sections V-A and V-B).

a. *Vertex projection* (GPU): every vertex of the (pre-subdivided, SBC V-B,
   :mod:`...engine.geometry.subdivision`) diffuse meshes is projected per sheet with ``sbc_project``
   (``glsl/sbc_projection.glsl``, ``glsl/reflection_project_vert.glsl``): pixel, depth
   and validity, eye vector and reflected distance land in texel ``gl_VertexID`` of the
   sheet's layer of two float targets, read back. Only the vertex chunks (runs of
   :data:`CHUNK_VERTICES` Morton-sorted vertices) that meet the sheet's bounds are
   projected (:mod:`...engine.methods.sbc.sheet_bounds`); the others could not project there.
b. *Triangles* (CPU, from the read-back), per sheet: those with a corner projected in
   the sheet and every corner projected, in it or, across the seam between two sheets
   of one history, in another sheet within a few ray-map cells of the triangle's own
   corner (:data:`STITCH_CELLS`; so seams do not open cracks, and a corner is not
   joined to its second image across the mirror). The depth is SBC V-A's offset
   (k - 1 + z / D) g: within a sheet the point nearer the mirror along the reflected
   ray wins (case 2), lower orders before higher ones (case 3), one depth buffer.
c. *Mixed triangles* (SBC V-B: one or two corners project, none stitched): each is cut
   into a barycentric sub-grid whose sub-vertices are projected on their own (a second
   GPU projection pass); sub-triangles with a sub-vertex that does not project are
   dropped, so the reflection ends within about a sub-triangle (about 1 px,
   :data:`MIXED_SUB_PX`) of where projection ends instead of at the last whole
   triangle. Inside, a block of :data:`MIXED_COARSE_FACTOR` ^ 2 sub-triangles that all
   project is kept as one triangle over its projected corners.

The result, a :class:`CameraTriangles`, is one vertex buffer whose vertices hold their
first reflector point in world space, depth, eye vector, distance and mesh data; the
camera's pass (``camera_pass.CameraPass``) keeps it and draws it every frame with
``glsl/reflection_mesh_vert.glsl``.

What is projected comes from a *projection source*, one protocol for every kind: its
``groups`` (a reflection history per sheet), ``downsample`` (ray-map pixels per cell),
``view`` (the view it was made for), ``on_gpu`` (it projects a batch of points on the
GPU, else their positions in numpy), ``sheet_subdivisions`` (a cap per sheet on the
mixed-triangle sub-grid, or None) and ``project(maker, positions, batch, draws,
n_texels, setup, static, camera)`` -> the (pixel, depth, kind) and (eye vector,
distance) texels of :meth:`CameraTriangleMaker.project_pass`. A camera's GPU textures
(``sbc_gpu.SBCTextures``) and the camera in numpy (``camera_source.CameraSource``)
are sources; so is the numpy morphing blend the benchmarks compare with
(``tools/numpy_morph_source.py``).
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field

import gpu
import numpy as np
from mathutils import Matrix

from ...engine.geometry.closed_surfaces import ConvexMirrors, turned_away
from ...engine.methods.sbc import sheet_bounds
from ...engine.geometry import subdivision
from .. import draw_shaders
from . import sbc_gpu
from ..gpu_data import points_batch, read_texture, saved_state

#: A mixed triangle (SBC V-B) is drawn as a triangular grid of n sub-triangles along each
#: edge (n^2 in all), each sub-vertex projected on its own; n is a power of two up to this,
#: chosen so that sub-triangles span about MIXED_SUB_PX pixels. 0 drops mixed triangles
#: (the paper's baseline).
MIXED_SUBDIVISIONS = 32
MIXED_SUB_PX = 1.0
#: Inside a mixed triangle, a block of MIXED_COARSE_FACTOR^2 sub-triangles that all
#: project is drawn as one (sub-grids of at least twice this many steps).
MIXED_COARSE_FACTOR = 4
#: Texels of the vertex projection target (16 bytes each): the sheets of one history
#: are projected side by side (for stitching) as far as this allows.
MAX_PROJECTED_TEXELS = 1 << 22
#: A triangle across a seam between sheets joins a corner from another sheet only
#: within this many ray-map cells (times the down-sampling, in pixels) of its own corner.
STITCH_CELLS = 8


def _sheet_chunks(histories: list, capacity: int) -> list:
    """Sheet indices grouped by history (first appearance order), in chunks of at most
    ``capacity`` sheets: the sheets projected side by side and stitched together."""
    by_history: dict = {}
    for sheet, history in enumerate(histories):
        by_history.setdefault(tuple(history), []).append(sheet)
    return [sheets[k:k + capacity] for sheets in by_history.values() for k in range(0, len(sheets), capacity)]


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


def _subdivision_caps(source, sheets: list):
    """The largest mixed-triangle sub-grid each of ``sheets`` allows (``None``: the
    renderer's): a source whose points cost much more to project than the GPU pass
    (``MorphSource``) caps it."""
    caps = source.sheet_subdivisions
    return None if caps is None else [caps[sheet] for sheet in sheets]


def _culling(camera, diameter: float):
    """Per-sheet k-DOPs and bounding cones of a sample-based ``camera`` that cull vertex
    chunks (:mod:`...engine.methods.sbc.sheet_bounds`), or ``None`` (no camera: no culling)."""
    if camera is None:
        return None
    return sheet_bounds.sheet_kdops(camera, diameter), camera.cones


@dataclass
class CameraTriangles:
    """The reflected triangles of one sample-based camera over the renderer's meshes.

    Made once per camera (or per mesh change: a new renderer) by
    :meth:`CameraTriangleMaker.triangles`, kept and drawn every frame by
    ``camera_pass.CameraPass``. Every vertex of a drawn
    reflected triangle holds its first reflector point in world space, its depth (order
    and distance along the reflected ray, SBC V-A), its camera-view pixel, its eye vector
    and reflected distance (SBC V-C, V-D) and its mesh's colour, normal and UVs.
    """

    source: object  # the sbc_gpu.SBCTextures or other source it was made from (identity = the key it is kept by)
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
    #: The depth range per order of its vertices (``reflected_depth.reflected_depth``): 1 / (max order + 1).
    order_range: float = 1.0
    #: The vertex arrays by attribute, until they are put on the GPU as ``batch``.
    arrays: dict | None = None


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


class CameraTriangleMaker:
    """Makes the reflected triangles of a sample-based camera over one renderer's
    geometry (a ``draw_geometry.DrawGeometry``): :meth:`triangles`.

    ``per_frame_reflectors(view)``: the reflectors whose first-order sheets the
    per-frame passes draw instead (left out of a projection); ``counts``: the renderer's
    counters (``"projections"``, counted by ``camera_pass.CameraPass`` as it uploads them). ``cull``: project in each sheet only
    the vertex chunks that meet the sheet's k-DOP (:mod:`...engine.methods.sbc.sheet_bounds`; needs the
    camera itself, not only its textures). ``polish``: the GPU's ray-list and fold-cell
    answers are polished on the true rays on the CPU (needs the camera too; exact, but
    the numpy BVH makes it seconds per camera: the live viewport turns it off).
    ``convex_mirrors``: which mirrors are convex (``closed_surfaces.ConvexMirrors``),
    allowing the far sides of closed solids to be culled (:attr:`convex_reflectors`).
    """

    def __init__(self, geometry, per_frame_reflectors, counts: dict, mixed_subdivisions: int = MIXED_SUBDIVISIONS,
                 cull: bool = True, polish: bool = True, convex_mirrors: ConvexMirrors | None = None):
        self.geometry = geometry
        self.per_frame_reflectors = per_frame_reflectors
        self.counts = counts
        self.counts.setdefault("projections", 0)
        self.mixed_subdivisions = int(mixed_subdivisions)
        self.cull = bool(cull)
        self.polish = bool(polish)
        self._convex = ConvexMirrors() if convex_mirrors is None else convex_mirrors
        #: Names these vertices for sources that keep work for them (MorphSource).
        self.vertices_token = object()
        self._points = None
        g = geometry
        self._triangle_image = np.full(len(g.triangles), -1, np.int64)
        #: Per triangle, its closed solid's winding (+1 counter-clockwise seen from
        #: outside, -1 the other way; 0: not a closed solid, or one a mirror lies in).
        self._triangle_winding = np.zeros(len(g.triangles), np.int8)
        windings = g.range_windings or (0,) * len(g.ranges)
        for (image, first, count), winding in zip(g.ranges, windings):
            self._triangle_image[first:first + count] = image
            self._triangle_winding[first:first + count] = winding
        self._chunk_boxes = sheet_bounds.chunk_boxes(g.vertices, CHUNK_VERTICES) if len(g.vertices) else None

    @property
    def convex_reflectors(self) -> frozenset:
        """Indices of the mirrors that bound a convex body (``convex_mirrors``), whose
        first-order sheets leave out the far sides of closed solids (:meth:`_facing_away`)."""
        return self._convex.indices

    def vertex_points(self):
        """The renderer's vertices as a POINTS batch (the projection pass's input)."""
        if self._points is None:
            self._points = points_batch(self.geometry.vertices.astype(np.float32))
        return self._points

    def _vertex_runs(self, kdops, sheet: int) -> list:
        """(first, count) runs of vertices to project in ``sheet``: all of them without
        culling, else the chunks meeting the sheet's k-DOP, neighbouring chunks merged."""
        n = len(self.geometry.vertices)
        if kdops is None or kdops[0][sheet] is None:  # no culling, or a sheet without bounds
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

    def triangles(self, textures, camera_view, camera=None, per_frame=None, vertex_batch=None) -> CameraTriangles:
        """Project the meshes with the camera of ``textures`` (SBC V-A) and decide, from
        the read-back, which reflected triangles are drawn (V-B): per sheet, those with
        every corner projected in it or, across a seam, in another sheet of its history
        within :data:`STITCH_CELLS` cells; mixed triangles (one or two corners projected,
        none stitched) as sub-grids of about :data:`MIXED_SUB_PX` whose sub-vertices are
        projected on their own, keeping the sub-triangles whose three sub-vertices project.

        Returns them as vertex arrays, not yet on the GPU (:meth:`_uploaded`). With a
        source that projects on the CPU (``camera_source.CameraSource``) and the
        reflectors the per-frame passes draw in ``camera_view`` (``per_frame``), it runs
        no GPU call and changes nothing here: a worker thread may run it. ``vertex_batch``:
        the vertices as a GPU batch, for the GPU pass of ``sbc_gpu.SBCTextures``.
        """
        start = time.perf_counter()
        g = self.geometry
        histories = list(textures.groups)
        n_vertices = len(g.vertices)
        if per_frame is None:
            per_frame = self.per_frame_reflectors(camera_view)
        if n_vertices == 0 or not histories or not len(g.triangles):
            return CameraTriangles(textures, camera_view, None, (), 0, 0, {
                "projection_seconds": 0.0, "projected_vertices": 0, "unculled_vertices": 0, "mixed_sub_triangles": 0},
                per_frame=per_frame)
        world_to_clip = np.asarray(camera_view.projection_matrix) @ np.asarray(camera_view.view_matrix)
        setup = {"inverse_view_projection": Matrix(np.linalg.inv(world_to_clip).tolist()),
                 "view_size": (float(camera_view.width), float(camera_view.height)),
                 "order_range": 1.0 / (max(len(h) for h in histories) + 1)}
        setup["inverse_diameter"] = 1.0 / g.diameter
        stitch_px = STITCH_CELLS * textures.downsample
        kdops = _culling(camera, g.diameter) if self.cull else None
        pieces, mixed_blocks, projected = [], [], 0
        for sheets in _sheet_chunks(histories, max(1, MAX_PROJECTED_TEXELS // n_vertices)):
            history = histories[sheets[0]]
            if len(history) == 1 and history[0] in per_frame:
                continue  # the iterative search or a grid draws these first-order reflections every frame
            draws = []
            for layer, sheet in enumerate(sheets):
                for first, count in self._vertex_runs(kdops, sheet):
                    draws.append((sheet, len(history), layer * n_vertices, first, count))
                    projected += count
            points, eyes = self.project_points(textures, g.vertices, vertex_batch, draws,
                                                len(sheets) * n_vertices, setup, static=True, camera=camera)
            points = points.reshape(len(sheets), n_vertices, 4)
            eyes = eyes.reshape(len(sheets), n_vertices, 4)
            cull_back = len(history) == 1 and history[0] in self.convex_reflectors
            pieces += self._full_triangles(points, eyes, history, stitch_px, cull_back)
            if self.mixed_subdivisions > 0:
                blocks = self._mixed_instances(points, sheets, len(history), _subdivision_caps(textures, sheets),
                                               eyes=eyes if cull_back else None)
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
            return CameraTriangles(textures, camera_view, None, (), 0, n_mixed, stats, per_frame=per_frame)
        runs, first = [], 0
        for image, arrays in pieces:
            count = len(arrays["world_depth"])
            if runs and runs[-1][0] == image:
                runs[-1] = (image, runs[-1][1], runs[-1][2] + count)
            else:
                runs.append((image, first, count))
            first += count
        names = ("world_depth", "pixel_reflector", "eye_distance", "color", "normal_lit", "uv")
        arrays = {name: np.concatenate([p[1][name] for p in pieces]).astype(np.float32) for name in names}
        stats["projection_seconds"] = time.perf_counter() - start
        return CameraTriangles(textures, camera_view, None, tuple(runs), first // 3, n_mixed, stats,
                                per_frame=per_frame, order_range=setup["order_range"], arrays=arrays)

    def project_pass(self, textures, batch, draws: list, n_texels: int, setup: dict):
        """Project the points of ``batch`` with ``textures``: per (group, order, texel
        offset, first, count) of ``draws`` the points first .. first + count - 1 into
        texels offset + index. Returns the two targets read back, (n_texels, 4) each:
        (pixel, depth, valid) and (eye vector, reflected distance)
        (``glsl/reflection_project_vert.glsl``); texels of points not drawn are 0 (invalid)."""
        columns = max(1, min(n_texels, sbc_gpu.sbc_pack.TEXTURE_WIDTH))
        rows = max(1, -(-n_texels // columns))
        points = gpu.types.GPUTexture((columns, rows), format='RGBA32F')
        eyes = gpu.types.GPUTexture((columns, rows), format='RGBA32F')
        framebuffer = gpu.types.GPUFrameBuffer(color_slots=(points, eyes))
        with saved_state(), framebuffer.bind():
            gpu.state.blend_set('NONE')
            gpu.state.viewport_set(0, 0, columns, rows)
            framebuffer.clear(color=(0.0, 0.0, 0.0, 0.0))
            gpu.state.depth_test_set('NONE')
            gpu.state.program_point_size_set(True)
            try:
                shader = draw_shaders.shader("project")
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
        return (read_texture(points, columns, rows).reshape(-1, 4)[:n_texels],
                read_texture(eyes, columns, rows).reshape(-1, 4)[:n_texels])

    def project_points(self, source, positions, batch, draws: list, n_texels: int, setup: dict,
                       static: bool = False, camera=None):
        """The projection pass of ``draws`` (as :meth:`project_pass`) with any projection
        source: its own ``project`` (a camera's textures on the GPU, a camera or a grid in
        numpy). ``positions`` are the points of ``batch`` (made from them by a source that
        projects on the GPU when ``None``); ``static``: they are this renderer's own
        vertices, which a source may keep work for between views (morphing's node
        images, SBC paper VI). With the ``camera`` of the textures, risky answers are
        polished on the true rays as its numpy projection polishes them
        (:func:`.sbc_gpu.polish_readback`)."""
        return source.project(self, positions, batch, draws, n_texels, setup, static, camera)

    def _vertex_arrays(self, positions, points, eyes, reflector: float, color, normal_lit, uv) -> dict:
        """Per-vertex arrays of drawn reflected triangles (``glsl/reflection_mesh_vert.glsl``)."""
        n = len(points)
        world = np.asarray(positions, np.float64) + eyes[:, :3] - self.geometry.shift
        return {"world_depth": np.c_[world, points[:, 2]],
                "pixel_reflector": np.c_[points[:, :2], np.full(n, reflector), np.zeros(n)],
                "eye_distance": eyes, "color": color, "normal_lit": normal_lit, "uv": uv}

    def _full_triangles(self, points, eyes, history, stitch_px: float, cull_back: bool = False) -> list:
        """(image, per-vertex arrays) pieces of the triangles drawn whole, per sheet (layer)
        of one history, in triangle order: those with a corner projected in the sheet and
        every other corner in it or, stitched, in another sheet of the history: the one
        nearest in the image to the triangle's first corner projected here, within
        ``stitch_px`` (a point can have two images in two sheets; a corner must not be
        joined to its other image across the mirror). ``cull_back``: a first-order history
        of a convex mirror, whose triangles turned away from it are left out
        (:meth:`_facing_away`)."""
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
            if cull_back:
                drawn &= ~self._facing_away(candidates, corners, eyes[layer_of, corners, :3], ok)
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

    def _facing_away(self, triangles, corners, eyes, known) -> np.ndarray:
        """:func:`...engine.geometry.closed_surfaces.turned_away` of mesh ``triangles`` (their ``corners``)
        seen from their first-order reflector points (``eyes``; a mixed triangle
        ``known`` only at its projected corners). The mirror lies outside the solid
        (``closed_surfaces.cullable_winding``), so the reflected ray meets its near side
        first and such a triangle's image is hidden in its sheet (SBC V-A, case 2): left
        out rather than drawn and hidden, about half the closed meshes' triangles. Only
        for convex mirrors: on a non-convex one (the vase demo) a sheet can hold the far
        side of a solid without its near side, and the floor would show through."""
        return turned_away(self.geometry.vertices, corners, self._triangle_winding[triangles], eyes, known)

    def _mixed_instances(self, points, sheets: list, order: int, caps=None, eyes=None) -> list:
        """Mixed triangles of ``sheets`` (SBC V-B) as (image, n, corners, group, order)
        blocks, n the sub-grid (a power of two up to ``mixed_subdivisions``, so that
        sub-triangles span about :data:`MIXED_SUB_PX`): one or two corners project in the
        sheet and not every corner projects in some sheet of the history (those are
        stitched). With the projection's ``eyes`` (a first-order history of a convex
        mirror), triangles of closed solids that turn their back to the mirror at their
        projected corners are left out (:meth:`_facing_away`)."""
        g = self.geometry
        valid = points[..., 3] > 0.5
        somewhere = valid.any(axis=0)[g.triangles].all(axis=1)
        # A mixed triangle's size in pixels is estimated from its longest edge.
        longest = np.max([np.linalg.norm(g.vertices[g.triangles[:, k]] - g.vertices[g.triangles[:, (k + 1) % 3]],
                                         axis=1) for k in range(3)], axis=0)
        # Pixels per world unit at each vertex: the largest over the edges of the fully
        # projected triangles around it (local, so that a magnified part of a sheet, near a
        # silhouette, does not refine every mixed triangle of the sheet); a mixed triangle
        # without such a neighbour takes its sheet's 90th percentile. (The sheet's largest,
        # thousands of pixels per unit next to a fold, would subdivide many mixed triangles
        # of a crumpled mirror 32 times, each sub-vertex polished on the true rays; the
        # median leaves some mirror pixels without their reflection.)
        scales = []
        for layer in range(len(sheets)):
            own = valid[layer][g.triangles]
            full = np.flatnonzero(own.all(axis=1))
            vertex_scale = np.zeros(len(g.vertices))
            for k in range(3):
                a, b = g.triangles[full, k], g.triangles[full, (k + 1) % 3]
                length = np.linalg.norm(g.vertices[b] - g.vertices[a], axis=1)
                ratio = np.linalg.norm(points[layer, b, :2] - points[layer, a, :2], axis=1) / np.where(
                    length > 0, length, np.inf)
                np.maximum.at(vertex_scale, a, ratio)
                np.maximum.at(vertex_scale, b, ratio)
            scaled = vertex_scale[vertex_scale > 0]
            scales.append((vertex_scale, float(np.percentile(scaled, 90)) if len(scaled) else np.inf))
        blocks = []
        for image, first, count in g.ranges:
            triangles = g.triangles[first:first + count]
            by_level: dict = {}
            for layer, group in enumerate(sheets):
                own = valid[layer][triangles]
                chosen = np.flatnonzero(own.any(axis=1) & ~own.all(axis=1) & ~somewhere[first:first + count])
                if len(chosen) and eyes is not None:
                    corners = triangles[chosen]
                    chosen = chosen[~self._facing_away(first + chosen, corners, eyes[layer][corners, :3], own[chosen])]
                if len(chosen) == 0:
                    continue
                vertex_scale, typical = scales[layer]
                scale = vertex_scale[triangles[chosen]].max(axis=1)
                scale = np.where(scale > 0, scale, typical)
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
            projected, projected_eyes = self.project_points(textures, positions[part], None, draws, len(part),
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

