# SPDX-License-Identifier: GPL-3.0-or-later
"""The iterative search on the GPU: every frame, every diffuse vertex, no CPU work.

Roger & Holzschuch (2006), section 3.3.7: the search runs on the GPU, and its second
strategy (compute the reflected positions in one pass, draw them in another), which
the paper could not use for want of render-to-vertex-buffer, is the one here: a compute
shader (``glsl/iterative_search.glsl``, the twin of ``engine/methods/iterative/search.py``)
writes each vertex's reflection point into a float texture, one texel per vertex (per
image slot on a folded mirror: every image, ``engine/methods/iterative/fold_patches.py``), and
the reflected meshes' vertex stage (``glsl/iterative_mesh_vert.glsl``) reads its
vertex's texel (``reflected_meshes.py``, shared with morphing). What is uploaded once:
the diffuse vertices (a texture) with their shading data (a vertex buffer), and every star-shaped
reflector's cube map (:class:`MapAtlas`: a search reads its own map and the others',
which may block its reflected segments). What runs per frame: one dispatch and one
draw per reflector, with the view in push constants.
"""

from __future__ import annotations


import gpu
import numpy as np

from ...engine.methods.iterative import fold_patches, search as search_module
from ..frame_pass import Frame, FramePass, PassInputs
from ..gpu_data import data_texture
from ..reflected_meshes import FLIPPED_CODE, AnswerSet, ReflectedMeshes
from ..shader_sources import glsl_source
from ..shader_cache import cached_shader

#: Invocations per work group of the search (along x).
LOCAL_SIZE = 64


def search_defines() -> dict:
    """The engine's constants, as the search shader's ``#define`` s."""
    s = search_module
    return {"MAX_ITERATIONS": s.MAX_ITERATIONS, "GUESS_BISECTIONS": s.GUESS_BISECTIONS,
            "DERIVATIVE_STEP": f"{s.DERIVATIVE_STEP:.9e}", "TRUST_RADIUS": f"{s.TRUST_RADIUS:.9e}",
            "HALVINGS": s.HALVINGS, "MAX_CHART": f"{s.MAX_CHART:.9e}",
            "RESIDUAL_TOLERANCE": f"{s.RESIDUAL_TOLERANCE:.9e}", "OCCLUSION_SAMPLES": s.OCCLUSION_SAMPLES,
            "RESTART_OFFSET": f"{s.RESTARTS[1][0]:.9e}", "FLIPPED_CODE": FLIPPED_CODE,
            "PATCH_MARGIN": f"{s.PATCH_MARGIN:.9e}", "NEAR_PATCH": f"{s.NEAR_PATCH:.9e}",
            "MAX_IMAGES": fold_patches.MAX_IMAGES, "SAME_IMAGE_PER_STOP": f"{s.SAME_IMAGE / s.STOP_FRACTION:.9e}"}


def map_search_prelude(*then: str) -> str:
    """The GLSL a per-vertex search on the cube maps begins with: the maps' reading
    (``glsl/cube_map.glsl``), what the searches share (``glsl/map_search.glsl``), then the
    files ``then``."""
    return "".join(glsl_source(name) for name in ("cube_map.glsl", "map_search.glsl") + then)


def map_search_info(extra_floats=(), extra_samplers=(), extra_ints=(), extra_ivec4s=()) -> "gpu.types.GPUShaderCreateInfo":
    """What a per-vertex search on the cube maps (``glsl/map_search.glsl``) declares:
    the view's push constants (:func:`bind_map_search`), the vertices, the maps and their
    parameters, a read-write ``result`` image, one invocation per vertex texel; then the
    float, int and ivec4 push constants ``extra_floats``, ``extra_ints`` and
    ``extra_ivec4s`` and the samplers ``extra_samplers`` of the search."""
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('VEC4', "camera")
    info.push_constant('VEC4', "w_row")
    for name in extra_ivec4s:
        info.push_constant('IVEC4', name)
    for name in ("stop_per_w",) + tuple(extra_floats):
        info.push_constant('FLOAT', name)
    for name in ("n_vertices", "positions_width", "warm", "self_map", "n_maps") + tuple(extra_ints):
        info.push_constant('INT', name)
    for slot, name in enumerate(("vertex_positions", "reflector_maps", "map_params") + tuple(extra_samplers)):
        info.sampler(slot, 'FLOAT_2D', name)
    info.image(0, 'RGBA32F', 'FLOAT_2D', "result", qualifiers={'READ', 'WRITE'})
    info.local_group_size(LOCAL_SIZE, 1)
    return info


@cached_shader
def search_shader():
    """The compute shader of the search, built on first use."""
    info = map_search_info(extra_samplers=("map_patches",))
    info.compute_source(glsl_source("iterative_search.glsl", search_defines(), map_search_prelude()))
    return gpu.shader.create_from_info(info)


def bind_map_search(shader, view, meshes: ReflectedMeshes, atlas: "MapAtlas", warm: bool) -> float:
    """Bind a search shader (:func:`map_search_info`) and set what every dispatch of a
    frame shares: ``camera`` (the eye relative to the meshes' shift, w 1; or the direction
    toward the viewer, w 0), ``w_row`` (the view-projection's last row, for clip w), the
    vertices, the maps of ``atlas``, and ``warm``. Returns the size of a pixel at clip w 1
    (the ``stop_per_w`` of one pixel)."""
    shift = meshes.geometry.shift
    world_to_clip = np.asarray(view.projection_matrix) @ np.asarray(view.view_matrix)
    translate = np.eye(4)
    translate[:3, 3] = shift
    w_row = (world_to_clip @ translate)[3]
    camera = (*(view.eye - shift), 1.0) if view.is_perspective else (*view.backward, 0.0)
    shader.bind()
    shader.uniform_float("camera", tuple(float(c) for c in camera))
    shader.uniform_float("w_row", tuple(float(c) for c in w_row))
    shader.uniform_int("n_vertices", meshes.n_vertices)
    shader.uniform_int("positions_width", meshes.width)
    shader.uniform_int("warm", int(bool(warm)))
    shader.uniform_int("n_maps", atlas.count)
    shader.uniform_sampler("vertex_positions", meshes.positions)
    shader.uniform_sampler("reflector_maps", atlas.texture)
    shader.uniform_sampler("map_params", atlas.params)
    return 2.0 / (float(view.projection_matrix[0][0]) * view.width)


class MapAtlas:
    """Every star-shaped reflector's (and piece's) cube map in one texture, one below
    another, three texels of parameters per map (``glsl/iterative_search.glsl``'s
    ``use_map``) and the pieces' patches, three texels a row: each search reads its own
    map and the others', which may block its reflected segments."""

    def __init__(self, methods, shift):
        maps = [m.reflector_map for m in methods]
        width = max(rmap.texels.shape[1] for rmap in maps)
        rows = np.cumsum([0] + [rmap.texels.shape[0] for rmap in maps])
        patches = [np.zeros((0, 3, 4), np.float32) if rmap.patches is None else rmap.patches for rmap in maps]
        patch_rows = np.cumsum([0] + [len(p) for p in patches])
        texels = np.zeros((rows[-1], width, 4), np.float32)
        params = np.zeros((3 * len(maps), 4), np.float32)
        for k, rmap in enumerate(maps):
            texels[rows[k]:rows[k + 1], :rmap.texels.shape[1]] = rmap.texels
            params[3 * k] = (*(np.asarray(rmap.centre) - shift), rmap.max_radius)
            params[3 * k + 1] = (rows[k], rmap.face_size, float(bool(rmap.convex)), rmap.mean_radius)
            params[3 * k + 2] = (patch_rows[k], len(patches[k]), rmap.min_radius, rmap.images)
        self.count = len(maps)
        self.texture = data_texture(texels)
        self.params = data_texture(params, len(params))
        # One row at least: a texture may not be empty.
        self.patches = data_texture(np.concatenate(patches + [np.zeros((1, 3, 4), np.float32)]))


class MapSearchPass(FramePass):
    """A per-vertex search on the cube maps (``glsl/map_search.glsl``) for one renderer's
    geometry (on the GPU as ``meshes``, a :class:`..reflected_meshes.ReflectedMeshes`, made
    here when not given) and its searched maps (``methods``, each with a
    ``reflector_map`` and an ``accuracy_px``): the maps in one :class:`MapAtlas`, one
    dispatch per map a frame into its own result textures. A search says how its shader
    is made (:meth:`shader`), what each map's results are (:meth:`new_results`, keyed by
    :meth:`key`) and what a dispatch binds besides the shared inputs (:meth:`bind`)."""

    searches = True

    def __init__(self, geometry, methods, meshes: ReflectedMeshes | None = None):
        self.geometry = geometry
        self.methods = list(methods)
        self.meshes = meshes if meshes is not None else ReflectedMeshes(geometry)
        self.n_vertices = self.meshes.n_vertices
        self._atlas = None
        self._results: dict = {}
        self.counts = {"searches": 0}

    @property
    def accuracy_px(self) -> float | None:
        """The finest Accuracy of the searched maps (their searches stop at a tenth of it)."""
        return min((m.accuracy_px for m in self.methods), default=None)

    def update(self, frame: Frame) -> None:
        """:meth:`search` (``frame.claimed`` never holds a searched reflector: the
        search draws it in every view, :meth:`drawn_in`, so a camera leaves it out)."""
        self.search(frame.view, frame.warm)

    def shader(self):
        """The search's compute shader (:func:`map_search_info`, built once)."""
        raise NotImplementedError

    def key(self, method):
        """The key of a searched map's results."""
        raise NotImplementedError

    def new_results(self, method):
        """A searched map's result textures, made on first use."""
        raise NotImplementedError

    def bind(self, shader, method, results) -> None:
        """What one map's dispatch binds besides the view, the maps and ``self_map``."""
        raise NotImplementedError

    def _ensure(self) -> None:
        if self._atlas is None:
            self._atlas = MapAtlas(self.methods, self.geometry.shift)
        for method in self.methods:
            if self.key(method) not in self._results:
                self._results[self.key(method)] = self.new_results(method)

    def search(self, view, warm: bool = False) -> None:
        """This frame's search: one dispatch per map, into its result textures.
        ``warm``: each vertex starts from its last answer (a viewport whose view moves
        a little each frame); cold, the answer depends on this view alone."""
        if self.n_vertices == 0 or not self.methods:
            return
        self._ensure()
        shader = self.shader()
        pixel_scale = bind_map_search(shader, view, self.meshes, self._atlas, warm)
        for k, method in enumerate(self.methods):
            shader.uniform_float("stop_per_w", search_module.STOP_FRACTION * method.accuracy_px * pixel_scale)
            shader.uniform_int("self_map", k)
            self.bind(shader, method, self._results[self.key(method)])
            gpu.compute.dispatch(shader, *self.meshes.work_groups(LOCAL_SIZE))
        self.counts["searches"] += 1


class IterativePass(MapSearchPass):
    """The iterative method's GPU side for one renderer's reflected geometry (a
    ``draw_geometry.DrawGeometry``) and its star-shaped reflectors
    (``engine.methods.iterative.IterativeReflector`` each, a piece's or a folded mirror's
    too), among ``n_reflectors`` of the scene."""

    name = "iterative"

    @classmethod
    def of_inputs(cls, methods: tuple, inputs: PassInputs) -> "IterativePass":
        return cls(inputs.geometry, methods, inputs.meshes, len(inputs.reflectors))

    def __init__(self, geometry, methods, meshes: ReflectedMeshes | None = None, n_reflectors: int = 1):
        super().__init__(geometry, methods, meshes)
        self.n_reflectors = n_reflectors

    @property
    def folded_reflectors(self) -> list:
        """The searched mirrors that are not convex (a fold crowds several images, and
        triangles across it are dropped) or not alone (another mirror's reflection, a
        higher order, begins next to a drawn one)."""
        return _unique(m.index for m in self.methods if not m.reflector_map.convex or self.n_reflectors > 1)

    @property
    def mirrored_reflectors(self) -> list:
        """The searched mirrors that are convex (``reflector_map.is_convex``)."""
        return _unique(m.index for m in self.methods if m.reflector_map.convex)

    def frame_stats(self) -> dict:
        return {"iterative": self.status_counts()}

    def shader(self):
        return search_shader()

    def key(self, method) -> tuple:
        """A searched map's answer texture: its reflector and piece."""
        return method.index, method.piece

    def new_results(self, method):
        return self.meshes.answer_texture(method.reflector_map.images)

    def bind(self, shader, method, results) -> None:
        shader.uniform_sampler("map_patches", self._atlas.patches)
        shader.image("result", results)

    def answers(self) -> list:
        """The AnswerSet of the last search per map (a mirror searched as pieces has one
        per piece; a folded one, its slots in one texture), for ``ReflectedMeshes.draw``."""
        return [AnswerSet(m.index, self._results[self.key(m)], images=m.reflector_map.images)
                for m in self.methods if self.key(m) in self._results]

    def read(self, reflector_index: int, piece: int = 0, slot: int = 0) -> search_module.SearchResult:
        """The last search of one reflector (or of one of its pieces; of a folded one, one
        answer slot), read back (tests, the status counts)."""
        positions, code = self.meshes.read(self._results[(reflector_index, piece)], slot)
        status = (code % 16 - 8).astype(np.int8)
        return search_module.SearchResult(positions, status, (code % FLIPPED_CODE // 16).astype(np.int16),
                                          code >= FLIPPED_CODE)

    def status_counts(self) -> dict:
        """{reflector name: {"found", "not_converged", "unanswered"}} of the last search,
        read back: the vertices the search could not settle are counted, not drawn.
        A mirror searched as pieces counts a vertex found where any piece found it, not
        converged where one did not converge and none found it."""
        found, stuck = {}, {}
        for method in self.methods:
            if self.key(method) not in self._results:
                continue
            status = self.read(method.index, method.piece).status
            found[method.name] = found.get(method.name, False) | (status == search_module.FOUND)
            stuck[method.name] = stuck.get(method.name, False) | (status == search_module.NOT_CONVERGED)
        return {name: {"found": int(found[name].sum()), "not_converged": int((stuck[name] & ~found[name]).sum()),
                       "unanswered": int((~found[name]).sum())} for name in found}


def _unique(indices) -> list:
    """Reflector indices, each once, in order."""
    return list(dict.fromkeys(indices))
