# SPDX-License-Identifier: GPL-3.0-or-later
"""Refraction through convex glass on the GPU: every frame, every diffuse vertex.

The glass's twin of ``iterative_draw.py``. Each frame, first each pixel's own path
through each glass (:class:`.glass_rays.GlassRays`), then a compute shader
(``glsl/refraction_search.glsl``, constants in ``engine/glass/refraction_search.py``)
that writes, for each diffuse vertex and glass solid, where the eye's ray enters the
glass on its way to the vertex (A) and where it leaves (B), in answer slots: every image
it finds, from the plane's guesses and from the pixels whose paths pass the vertex
nearest. The reflected meshes (``reflected_meshes.py``) are drawn as triangle corners at
A, lit with the true direction toward B, and each fragment is a ray cast: its pixel's
path must hit its triangle, at the distance along the ray, or pass near enough to stand
in for a neighbour (``glsl/reflection_mesh_frag.glsl``). The renderer this pass belongs
to holds the glass as its reflectors (``blender/glass_layer.py``), so its pre-pass ids
confine each refracted image to its glass's visible footprint, as a reflection to its
mirror's. What is uploaded once: the vertices (shared with the other passes) and every
glass's cube map (:class:`.iterative_draw.MapAtlas`); per frame, two dispatches and one
draw per glass. It draws where the scene has more image textures than the per-pixel trace
samples (``glass_trace.py``, which draws glass otherwise).
"""

from __future__ import annotations

import gpu
import numpy as np

from ...engine.glass import refraction_search as search_module
from ...engine.methods.iterative.search import FOUND, NOT_CONVERGED
from ..frame_pass import Frame, PassInputs
from ..screen_space import box_corners, box_on_screen, pixel_box
from ..reflected_meshes import FLIPPED_CODE, PLACED_CODE, AnswerSet
from ..shader_cache import cached_shader
from ..shader_sources import glsl_source
from .glass_rays import GlassRays
from .iterative_draw import MapSearchPass, map_search_info, map_search_prelude

#: The search's status codes that are not the mirror search's (the rest are shared).
TOTAL_REFLECTION = -5


@cached_shader
def refraction_shader():
    """The compute shader of the refraction search, built on first use."""
    # 84 bytes of push constants.
    info = map_search_info(extra_floats=("eta", "glass_id"), extra_ints=("reflects",), extra_ivec4s=("pixel_rect",),
                           extra_samplers=("pixel_entries", "pixel_exits", "pixel_leaving"))
    info.image(1, 'RGBA32F', 'FLOAT_2D', "exit_result", qualifiers={'WRITE'})
    defines = {**search_module.search_defines(), "FLIPPED_CODE": FLIPPED_CODE, "PLACED_CODE": PLACED_CODE}
    info.compute_source(glsl_source("refraction_search.glsl", defines, map_search_prelude("glass_path.glsl")))
    return gpu.shader.create_from_info(info)


class RefractionPass(MapSearchPass):
    """The refraction search's GPU side for one renderer's diffuse geometry and its
    convex glass solids (``engine.glass.refraction_search.RefractedGlass`` each, whose
    ``index`` is the renderer's reflector index of that glass): an entry and an exit
    texture per glass."""

    name = "refraction"
    #: No hidden-point test: an entry point facing the eye is never hidden by its own
    #: convex solid, and the pre-pass's ids drop what other surfaces hide. (Through a
    #: magnifying lens a triangle spans much of the glass, and its entry points,
    #: interpolated along chords, lie well behind the surface the test compares them with.)
    hidden_fraction = float("inf")

    @classmethod
    def of_inputs(cls, methods: tuple, inputs: PassInputs) -> "RefractionPass":
        return cls(inputs.geometry, methods, inputs.meshes)

    def __init__(self, geometry, methods, meshes=None):
        super().__init__(geometry, methods, meshes)
        self.rays = GlassRays()
        #: {glass index: (x0, y0, x1, y1)}: each glass's box on screen in pixels this frame,
        #: where the search reads the pixels' paths (none: a search without a frame).
        self._pixel_rects = {}
        self._no_paths = None

    def update(self, frame: Frame) -> None:
        """Each glass pixel's own path (:class:`.glass_rays.GlassRays`), then the search,
        which starts from them too."""
        if not (self.n_vertices and self.methods):
            return
        self._ensure()
        self.rays.trace(frame, self.methods, self._atlas, self.geometry.shift)
        view = frame.view
        for method in self.methods:
            rmap = method.reflector_map
            corners = box_corners(np.asarray(rmap.centre) + rmap.max_radius * np.array([[-1.0] * 3, [1.0] * 3]))
            x, y, width, height = pixel_box(box_on_screen(corners, view, 0.0, view.width, view.height),
                                            view.width, view.height, 0)
            self._pixel_rects[method.index] = (x, y, x + width, y + height)
        try:
            self.search(view, frame.warm)
        finally:
            self._pixel_rects = {}

    def draw(self, frame: Frame) -> None:
        """Black where a glass that does not reflect must reflect totally, then the
        refracted meshes, each fragment held to its pixel's path."""
        if self.rays.exits is None:
            return
        self.rays.draw_settled()
        setup = {**self.reflected_setup(frame), "glass_rays": self.rays.textures}
        self.meshes.draw(frame.world_to_clip, frame.targets, setup, frame.images, self.answers())

    @property
    def folded_reflectors(self) -> list:
        """Every glass: between two focal lines its images are mirrored (a caustic), and
        triangles across it are dropped."""
        return self.reflector_indices

    def frame_stats(self) -> dict:
        return {"refraction": self.status_counts()}

    def shader(self):
        return refraction_shader()

    def key(self, method) -> int:
        return method.index

    def new_results(self, method) -> tuple:
        images = search_module.IMAGES
        return self.meshes.answer_texture(images), self.meshes.answer_texture(images)

    def bind(self, shader, method, results) -> None:
        shader.uniform_float("eta", float(method.ior))
        shader.uniform_float("glass_id", float(method.index + 1))
        shader.uniform_int("reflects", int(bool(method.reflects)))
        rect = self._pixel_rects.get(method.index)
        if self._no_paths is None:
            self._no_paths = gpu.types.GPUTexture((1, 1), format='RGBA32F')
        paths = (self.rays.entries, self.rays.exits, self.rays.leaving) if rect else (self._no_paths,) * 3
        shader.uniform_int("pixel_rect", rect or (0, 0, 0, 0))
        for name, texture in zip(("pixel_entries", "pixel_exits", "pixel_leaving"), paths):
            shader.uniform_sampler(name, texture)
        entry, leave = results
        shader.image("result", entry)
        shader.image("exit_result", leave)

    def answers(self) -> list:
        """The AnswerSet (glass index, entry texture, exit texture, its slots) of the last
        search per glass."""
        return [AnswerSet(index, entry, leave, search_module.IMAGES) for index, (entry, leave) in self._results.items()]

    def read(self, glass_index: int, slot: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The last search of one glass, read back: (N, 3) entry and exit points (world
        space, NaN without an answer) and the (N,) status codes, of one answer slot, or
        of every slot (``slot`` None: (S, N, 3), (S, N, 3) and (S, N))."""
        entry, leave = self._results[glass_index]
        slots = self.meshes.read_slots(entry)
        exits = self.meshes.read_slot_points(leave)
        points = np.array([p for p, _ in slots])
        codes = np.array([c for _, c in slots])
        exit_points = np.where(np.isfinite(points[..., :1]), exits, np.nan)
        status = (codes % 16 - 8).astype(np.int8)
        if slot is None:
            return points, exit_points, status
        return points[slot], exit_points[slot], status[slot]

    def status_counts(self) -> dict:
        """{glass name: {"found", "images", "not_converged", "total_reflection",
        "unanswered"}}: vertices with an image, images in all, and the vertices without
        one by why."""
        counts = {}
        for method in self.methods:
            if method.index not in self._results:
                continue
            status = self.read(method.index)[2]
            found = (status == FOUND).any(axis=0)
            counts[method.name] = {"found": int(found.sum()), "images": int((status == FOUND).sum()),
                                   "not_converged": int((status[0] == NOT_CONVERGED).sum()),
                                   "total_reflection": int((status[0] == TOTAL_REFLECTION).sum()),
                                   "unanswered": int((~found).sum())}
        return counts
