# SPDX-License-Identifier: GPL-3.0-or-later
"""Reflected meshes placed from per-vertex answers computed on the GPU every frame.

The methods that answer on the GPU each frame (the iterative search,
``iterative_draw.py``; reflection morphing, ``morph_pass.py``) write one *answer texel*
per diffuse vertex and reflector: (the vertex's first reflector point relative to the
renderer's shift, a code whose value modulo 16 is :data:`FOUND_CODE` where there is an
answer). :class:`ReflectedMeshes` holds what they share, uploaded once per geometry: the
vertices as a float texture (what the compute stages read) and the indexed reflected
meshes with their shading data; :meth:`ReflectedMeshes.draw` draws the meshes of each
answer texture with ``glsl/iterative_mesh_vert.glsl`` (a vertex at its answer, a triangle
with an unanswered corner discarded) and the sample-based camera's fragment stage; a
folded mirror's answers, several images per vertex in slots, as triangle corners matched
across the slots (:class:`AnswerSet`, :meth:`ReflectedMeshes.corner_batch`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import gpu
import numpy as np

from ..engine.geometry.subdivision import EDGE_FRACTION
from ..engine.glass import refraction_search
from ..engine.methods.iterative import search as search_module
from .draw_shaders import reflected_fragment_source, reflected_interface, shading_source
from .gpu_data import data_texture, read_texture, vertex_buffer
from .shader_sources import glsl_source
from .shader_cache import cached_shader

#: Texels per row of the vertex and answer textures.
TEXTURE_WIDTH = 4096
#: 20 degrees: an answer from another sheet of a curved mirror (across a fold, a crease,
#: another image in the same slot) misses by far more; an interpolated point of a small
#: reflected triangle by far less.
REFLECTION_COSINE = math.cos(math.radians(20.0))
#: 5 degrees: the law of reflection's tolerance where a folded mirror's answer slots are
#: drawn. Its triangles are matched across slots by their corners' nearest images, and
#: where a corner's own image is missing the nearest is another image of a neighbouring
#: point: a triangle across a fold or a caustic loop, whose pixels reflect toward points
#: close to its own (within 20 degrees on the tuning star ball's columns).
FOLDED_REFLECTION_COSINE = math.cos(math.radians(5.0))
#: A reflected fragment is kept only where the interpolated validity of its triangle's
#: corners reaches this: 1 inside triangles whose corners all have an answer, below it
#: everywhere else but within 1e-4 of an edge's length from a valid corner.
VALID_THRESHOLD = 0.9999
#: An answer texel's code for a found answer: (FOUND + 8) + 16 steps, modulo 16 (the
#: iterative search's status and step count; morphing writes FOUND_CODE itself).
FOUND_CODE = search_module.FOUND + 8
#: Added to the code of a flipped image (``search.flipped_images``): a triangle whose
#: corners disagree spans a fold and is not drawn. Above 16 times any step count.
FLIPPED_CODE = 2048
#: Added to the code of a vertex without an answer that is placed all the same, for the
#: fragment stage's ray cast through glass (``glsl/refraction_search.glsl``).
PLACED_CODE = 4096
#: The live view snaps reflected vertices to a grid of this share of its Accuracy (px):
#: at most half a cell off on each axis (0.71 of a cell in all), the answer itself a
#: tenth of the Accuracy off (``search.STOP_FRACTION``): within the Accuracy together.
#: A reflection packs the scene's triangles into a mirror's few pixels (sbc_fig3: 46 %
#: of them under a pixel across), and each costs its set-up and rasterisation; one
#: whose corners snap to one point, or to two, has no area and is dropped first.
SNAP_SHARE = 1.0
#: A vertex without an answer is never drawn (its triangles' fragments are discarded),
#: so it is placed wherever its triangles cost least: at the centre of its cell of a grid
#: this many cells across the view. Its triangles with no answered corner (a third of
#: each mirror's on the two-spheres demo) collapse to points and are dropped before
#: set-up; one with an answered corner (1-2 %) reaches at most a cell away.
UNANSWERED_CELLS = 64



class AnswerSet(NamedTuple):
    """One reflector's answers of a per-frame pass, for :meth:`ReflectedMeshes.draw`:
    ``texture`` holds an answer texel per vertex (:meth:`ReflectedMeshes.answer_texture`);
    ``exit_points``, for glass, the point each vertex's path leaves it
    (``methods/refraction_draw.py``); ``images``: 1, or the answer slots one below
    another, every image of a vertex in a folded mirror
    (``engine/methods/iterative/fold_patches.MAX_IMAGES``) or through glass (the triangles are then matched across slots, ``glsl/iterative_mesh_vert.glsl``)."""

    reflector_index: int
    texture: object
    exit_points: object = None
    images: int = 1


@cached_shader
def reflected_shader(law_test: bool = True, hidden_test: bool = True, refracted: bool = False, images: int = 1):
    """The reflected meshes' shader, built on first use (fragment stage shared with the
    sample-based camera's reflected meshes), with or without the fragment stage's
    law-of-reflection and hidden-point tests (:func:`fragment_tests`); ``refracted``:
    the vertices are seen through glass, along the ray leaving it at the point the
    ``exit_points`` texture holds per vertex (``methods/refraction_draw.py``), each
    fragment held to the path its pixel takes through the glass (``methods/glass_rays.py``);
    ``images``: the answers hold that many slots, drawn a slot of each triangle's first
    corner at a time (the triangle-corner batch, push constant ``slot``); glass is
    drawn as triangle corners even from one slot (its fragments' ray cast needs each
    corner's place in its triangle)."""
    interface = reflected_interface(f"curved_reflections_iterative_interface{'_refracted' * refracted}",
                                    searched=True, refracted=refracted)
    info = gpu.types.GPUShaderCreateInfo()
    # In this order 116 bytes (120 with `slot`), within the 128 Vulkan guarantees
    # (Blender counts 128 with `slot`); the vertices' texture width is read from it.
    info.push_constant('MAT4', "view_projection")
    info.push_constant('VEC4', "camera")
    corners = drawn_as_corners(images, refracted)
    if corners:
        info.push_constant('INT', "slot")
    info.push_constant('FLOAT', "inverse_diameter")
    info.push_constant('FLOAT', "order_range")
    info.push_constant('FLOAT', "reflector_id")
    info.push_constant('INT', "use_image")
    info.push_constant('FLOAT', "hidden_tolerance")
    info.push_constant('FLOAT', "reflection_cosine")
    info.push_constant('VEC2', "snap_grid")
    info.sampler(0, 'FLOAT_2D', "search_result")
    info.sampler(1, 'FLOAT_2D', "vertex_positions")
    info.sampler(2, 'FLOAT_2D', "prepass_labels")
    info.sampler(3, 'FLOAT_2D', "image")
    info.sampler(4, 'FLOAT_2D', "prepass_normals")
    if refracted:
        info.sampler(5, 'FLOAT_2D', "exit_points")
        info.sampler(6, 'FLOAT_2D', "glass_exits")
        info.sampler(7, 'FLOAT_2D', "glass_leaving")
        info.sampler(8, 'FLOAT_2D', "mesh_boxes")
    info.vertex_in(0, 'INT', "vertex_index")
    info.vertex_in(1, 'VEC4', "color")
    info.vertex_in(2, 'VEC4', "normal_lit")
    info.vertex_in(3, 'VEC2', "uv")
    if corners:
        info.vertex_in(4, 'INT', "anchor_index")
        info.vertex_in(5, 'INT', "corner")
    info.vertex_out(interface)
    info.fragment_out(0, 'VEC4', "color_out")
    defines_in = "#define EXIT_POINTS\n" * refracted + f"#define IMAGES {images}\n" * corners
    info.vertex_source(defines_in + shading_source() + glsl_source(
        "iterative_mesh_vert.glsl", {"FOUND_CODE": FOUND_CODE, "FLIPPED_CODE": FLIPPED_CODE, "PLACED_CODE": PLACED_CODE,
                                     "UNANSWERED_CELLS": f"{UNANSWERED_CELLS:.1f}"}))
    defines = f"#define SEARCHED\n#define VALID_THRESHOLD {VALID_THRESHOLD}\n"
    defines += "#define LAW_TEST\n" * law_test + "#define HIDDEN_TEST\n" * hidden_test
    defines += (f"#define REFRACTION_TEST\n#define PATH_FOUND {search_module.FOUND}\n"
                f"#define OUTSIDE_PX {refraction_search.OUTSIDE_PX:.9e}\n"
                f"#define REFRACTION_REACH {refraction_search.REFRACTION_REACH * EDGE_FRACTION:.9e}\n") * refracted
    info.fragment_source(reflected_fragment_source(defines))
    return gpu.shader.create_from_info(info)


def drawn_as_corners(images: int, refracted: bool) -> bool:
    """Whether answers in ``images`` slots are drawn from the triangle-corner batch
    (:meth:`ReflectedMeshes.corner_batch`): several slots are matched per triangle, and a
    fragment seen through glass is cast against its own triangle."""
    return images > 1 or refracted


def fragment_tests(reflector_index: int, setup: dict) -> tuple[bool, bool]:
    """(law of reflection, hidden point): which of the fragment stage's tests can drop a
    fragment of a reflector's answers (``glsl/reflection_mesh_frag.glsl``). The law of
    reflection at its usual tolerance (:data:`REFLECTION_COSINE`) guards against a
    triangle whose corners lie in different sheets of the reflection, and a mirror whose
    images are all mirrored (``setup["mirrored"]``, a convex one) has one sheet; a
    tighter tolerance (a render's test of blended answers) can fail on any mirror. The
    hidden-point test drops nothing with an infinite ``hidden_fraction`` (morphing's). A
    test that cannot fail is compiled out rather than skipped by a uniform: llvmpipe runs
    a branch on a uniform for every fragment anyway, and the two tests cost the morphing
    pass's reflected meshes a fifth of their time (their texture reads and arithmetic on
    every fragment, overdraw included)."""
    law_test = (reflector_index not in setup.get("mirrored", frozenset())
                or setup["reflection_cosine"] > REFLECTION_COSINE)
    return law_test, math.isfinite(setup["hidden_fraction"])


def snap_grid(view_size, snap_px: float) -> tuple:
    """The ``snap_grid`` uniform of the reflected-mesh shaders: the view's cells across
    and up for a grid ``snap_px`` pixels apart; (0, 0), no snapping, for 0."""
    if not snap_px > 0:
        return (0.0, 0.0)
    return tuple(float(size) / snap_px for size in view_size)


def _culled_faces(winding: int) -> str:
    """The faces to cull of a closed solid of ``winding`` (``closed_surfaces.winding``) in
    a mirrored image: seen from the mirror its far side winds as its near side does in a
    direct view (counter-clockwise for outward normals, OpenGL's front), the mirror
    reversing it; 'NONE' for a mesh that is not a closed solid."""
    return {1: 'FRONT', -1: 'BACK'}.get(winding, 'NONE')


class ReflectedMeshes:
    """One renderer's diffuse vertices (a texture) and reflected meshes (an indexed batch)
    on the GPU, uploaded on first use, and the draw of answer textures."""

    def __init__(self, geometry):
        self.geometry = geometry
        self.n_vertices = len(geometry.vertices)
        self.width = max(1, min(self.n_vertices, TEXTURE_WIDTH))
        self.height = max(1, -(-self.n_vertices // self.width))
        self._positions = None
        self._batch = None
        self._corner_batch = None
        self._mesh_boxes = None

    @property
    def positions(self):
        """The vertices relative to the shift, one RGBA32F texel each (rows of ``width``),
        the index of each one's mesh as w."""
        self._ensure()
        return self._positions

    @property
    def mesh_boxes(self):
        """Each diffuse mesh's bounding box relative to the shift: two RGBA32F texels per
        mesh (its lowest and highest corner), made on first use."""
        if self._mesh_boxes is None:
            g = self.geometry
            count = max(1, len(g.mesh_names))
            low, high = np.full((count, 3), np.inf), np.full((count, 3), -np.inf)
            mesh = np.zeros(self.n_vertices, int) if g.vertex_mesh is None else g.vertex_mesh
            np.minimum.at(low, mesh, g.vertices - g.shift)
            np.maximum.at(high, mesh, g.vertices - g.shift)
            self._mesh_boxes = data_texture(np.stack([low, high], axis=1).reshape(-1, 3), 2 * count)
        return self._mesh_boxes

    def _ensure(self) -> None:
        if self._positions is not None:
            return
        g = self.geometry
        mesh = np.zeros(self.n_vertices) if g.vertex_mesh is None else g.vertex_mesh
        self._positions = data_texture(np.c_[g.vertices - g.shift, mesh].astype(np.float32), self.width)
        attributes = {"vertex_index": (np.arange(self.n_vertices, dtype=np.int32), 'I32', 'INT'),
                      "color": (g.colors, 'F32', 'FLOAT'),
                      "normal_lit": (np.c_[g.normals, g.lit].astype(np.float32), 'F32', 'FLOAT'),
                      "uv": (g.uvs, 'F32', 'FLOAT')}
        if len(g.triangles):
            self._batch = gpu.types.GPUBatch(type='TRIS', buf=vertex_buffer(attributes), elem=gpu.types.GPUIndexBuf(
                type='TRIS', seq=np.asarray(g.triangles, dtype=np.int32)))

    def corner_batch(self):
        """The reflected meshes as a batch of triangle corners (no index buffer), each
        with its vertex's data, its triangle's first corner (``anchor_index``) and which
        corner it is (``corner``, 0-2): a folded mirror's answer slots are matched per
        triangle (``glsl/iterative_mesh_vert.glsl``), and a fragment seen through glass is
        tested against its own triangle (``glsl/reflection_mesh_frag.glsl``).
        Made on first use."""
        self._ensure()
        if self._corner_batch is None and self._batch is not None:
            g = self.geometry
            corners = np.asarray(g.triangles, dtype=np.int32)
            flat = corners.reshape(-1)
            attributes = {"vertex_index": (flat, 'I32', 'INT'),
                          "color": (np.asarray(g.colors)[flat], 'F32', 'FLOAT'),
                          "normal_lit": (np.c_[g.normals, g.lit].astype(np.float32)[flat], 'F32', 'FLOAT'),
                          "uv": (np.asarray(g.uvs)[flat], 'F32', 'FLOAT'),
                          "anchor_index": (np.repeat(corners[:, 0], 3), 'I32', 'INT'),
                          "corner": (np.tile(np.arange(3, dtype=np.int32), len(corners)), 'I32', 'INT')}
            self._corner_batch = gpu.types.GPUBatch(type='TRIS', buf=vertex_buffer(attributes))
        return self._corner_batch

    def answer_texture(self, images: int = 1):
        """A new answer texture, one RGBA32F texel per vertex in each of ``images`` slots
        (one below another)."""
        return gpu.types.GPUTexture((self.width, self.height * images), format='RGBA32F')

    def work_groups(self, local_size: int) -> tuple:
        """The work groups of a compute stage with one invocation per vertex texel."""
        return -(-self.width // local_size), self.height, 1

    def draw(self, view_projection, targets, setup: dict, image_of, answers) -> None:
        """The reflected meshes of each (reflector index, answer texture) of ``answers``
        (or (glass index, entry texture, exit texture) of a refracting pass)
        into the bound framebuffer (depth test on), placed by ``view_projection`` (a
        ``mathutils.Matrix`` relative to the shift), against the pre-pass of ``targets``
        (``frame_targets.FrameTargets``); ``image_of(k)`` is the texture of
        image ``k`` (-1: none); ``setup`` as ``FramePass.reflected_setup``, with
        ``hidden_fraction``: a fragment whose reflector point lies farther from the eye
        than the mirror surface the pre-pass saw there, by more than this fraction of the
        reflector's bounding-box diagonal, is hidden by the mirror and dropped
        (``FramePass.hidden_fraction``); and ``reflection_cosine``: one whose eye ray,
        reflected about the mirror's normal there, leaves further than this cosine from
        the fragment's point of the mesh is dropped (``FramePass.reflection_cosine``);
        and optionally ``mirrored``: reflectors whose images are all mirrored
        (``FramePass.mirrored_reflectors``), in which the triangles of closed solids that
        face away from the mirror are culled by their winding (``range_windings``); and
        ``snap_px`` (0: off), with ``view_size``: each vertex is placed at the centre of
        its cell of a grid that many pixels apart, pixel centres for 1 (the live view,
        within its Accuracy), and a reflected triangle within one cell, collapsed to a
        point, is dropped before it is rasterised (:data:`SNAP_SHARE`). A vertex without
        an answer goes to the centre of its cell of a coarser grid, always
        (:data:`UNANSWERED_CELLS`)."""
        answers = list(answers)
        self._ensure()
        if self._batch is None or not answers:
            return
        mirrored = setup.get("mirrored", frozenset())
        windings = self.geometry.range_windings or (0,) * len(self.geometry.ranges)
        for answer in answers:
            reflector_index, texture, exit_points, images = AnswerSet(*answer)
            law_test, hidden_test = fragment_tests(reflector_index, setup)
            law_test &= exit_points is None  # refracted: the law of reflection does not hold
            shader = reflected_shader(law_test, hidden_test, exit_points is not None, images)
            shader.bind()
            shader.uniform_float("view_projection", view_projection)
            shader.uniform_float("inverse_diameter", setup["inverse_diameter"])
            shader.uniform_float("order_range", setup["order_range"])
            shader.uniform_sampler("vertex_positions", self._positions)
            shader.uniform_sampler("prepass_labels", targets.prepass_labels)
            shader.uniform_float("snap_grid", snap_grid(setup["view_size"], setup.get("snap_px", 0.0)))
            shader.uniform_sampler("search_result", texture)
            if exit_points is not None:
                shader.uniform_sampler("exit_points", exit_points)
                for name, texture in zip(("glass_exits", "glass_leaving"), setup["glass_rays"]):
                    shader.uniform_sampler(name, texture)
                shader.uniform_sampler("mesh_boxes", self.mesh_boxes)
            shader.uniform_float("reflector_id", float(reflector_index + 1))
            if law_test or hidden_test:
                shader.uniform_float("camera", setup["camera"])
            if law_test:
                shader.uniform_sampler("prepass_normals", targets.prepass_normals)
                cosine = setup["reflection_cosine"]
                shader.uniform_float("reflection_cosine", max(cosine, FOLDED_REFLECTION_COSINE) if images > 1 else cosine)
            if hidden_test:
                shader.uniform_float("hidden_tolerance",
                                     setup["hidden_fraction"] * float(self.geometry.reflector_sizes[reflector_index]))
            corners = drawn_as_corners(images, exit_points is not None)
            batch = self.corner_batch() if corners else self._batch
            for slot in range(images):
                if corners:
                    shader.uniform_int("slot", slot)
                for (image, first, count), winding in zip(self.geometry.ranges, windings):
                    gpu.state.face_culling_set(_culled_faces(winding) if reflector_index in mirrored else 'NONE')
                    shader.uniform_int("use_image", int(image >= 0))
                    shader.uniform_sampler("image", image_of(image))
                    batch.draw_range(shader, elem_start=3 * first, elem_count=3 * count)
        gpu.state.face_culling_set('NONE')

    def read(self, texture, slot: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """An answer texture read back (its slot ``slot``): (N, 3) world points (NaN where
        no answer) and the (N,) int64 codes."""
        return self.read_slots(texture)[slot]

    def read_slots(self, texture) -> list:
        """Every answer slot of an answer texture, read back at once: (points, codes) per
        slot, as :meth:`read`."""
        slots = []
        for texels in self._texels(texture):
            code = texels[:, 3].astype(np.int64)
            found = code % 16 == FOUND_CODE
            slots.append((np.where(found[:, None], texels[:, :3] + self.geometry.shift, np.nan), code))
        return slots

    def read_points(self, texture) -> np.ndarray:
        """(N, 3) world points of a texture of one point per vertex, read back."""
        return self.read_slot_points(texture)[0]

    def read_slot_points(self, texture) -> np.ndarray:
        """(slots, N, 3) world points of a texture of one point per vertex in each slot."""
        return self._texels(texture)[..., :3] + self.geometry.shift

    def _texels(self, texture) -> np.ndarray:
        """(slots, N, 4) float64 texels of a texture of one texel per vertex in each slot."""
        texels = read_texture(texture, self.width, texture.height).reshape(-1, self.height * self.width, 4)
        return texels[:, :self.n_vertices].astype(np.float64)
