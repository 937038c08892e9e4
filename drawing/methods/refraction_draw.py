# SPDX-License-Identifier: GPL-3.0-or-later
"""Refraction through convex glass on the GPU: every frame, every diffuse vertex.

The glass's twin of ``iterative_draw.py``: a compute shader
(``glsl/refraction_search.glsl``, constants in ``engine/glass/refraction_search.py``)
writes, for each diffuse vertex and glass solid, where the eye's ray enters the glass on
its way to the vertex (A) and where it leaves (B), one texel each; the reflected meshes
(``reflected_meshes.py``) are drawn at A, lit with the true direction toward B, their
depth the distance from B (two vertices on one pixel share the path inside: the nearer
one outside wins). The renderer this pass belongs to holds the glass as its reflectors
(``blender/glass_layer.py``), so its pre-pass ids confine each refracted image to its
glass's visible footprint, as a reflection to its mirror's. What is uploaded once: the
vertices (shared with the other passes) and every glass's cube map
(:class:`.iterative_draw.MapAtlas`); per frame, one dispatch and one draw per glass.
"""

from __future__ import annotations

import gpu
import numpy as np

from ...engine.glass import refraction_search as search_module
from ...engine.methods.iterative.search import FOUND, NOT_CONVERGED
from ..frame_pass import Frame, FramePass, PassInputs
from ..reflected_meshes import FLIPPED_CODE, AnswerSet, ReflectedMeshes
from ..shader_cache import cached_shader
from ..shader_sources import glsl_source
from .iterative_draw import LOCAL_SIZE, MapAtlas, bind_map_search, map_search_info

#: The search's status codes that are not the mirror search's (the rest are shared).
TOTAL_REFLECTION = -5


@cached_shader
def refraction_shader():
    """The compute shader of the refraction search, built on first use."""
    info = map_search_info(extra_floats=("eta",))
    info.image(1, 'RGBA32F', 'FLOAT_2D', "exit_result", qualifiers={'WRITE'})
    defines = {**search_module.search_defines(), "FLIPPED_CODE": FLIPPED_CODE}
    info.compute_source(glsl_source("refraction_search.glsl", defines, glsl_source("map_search.glsl")))
    return gpu.shader.create_from_info(info)


class RefractionPass(FramePass):
    """The refraction search's GPU side for one renderer's diffuse geometry and its
    convex glass solids (``engine.glass.refraction_search.RefractedGlass`` each, whose
    ``index`` is the renderer's reflector index of that glass)."""

    name = "refraction"
    searches = True
    #: No hidden-point test: an entry point facing the eye is never hidden by its own
    #: convex solid, and the pre-pass's ids drop what other surfaces hide. (Through a
    #: magnifying lens a triangle spans much of the glass, and its entry points,
    #: interpolated along chords, lie well behind the surface the test compares them with.)
    hidden_fraction = float("inf")

    @classmethod
    def of_inputs(cls, methods: tuple, inputs: PassInputs) -> "RefractionPass":
        return cls(inputs.geometry, methods, inputs.meshes)

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
        """The finest Accuracy of the searched glass."""
        return min((m.accuracy_px for m in self.methods), default=None)

    @property
    def folded_reflectors(self) -> list:
        """Every glass: between two focal lines its images are mirrored (a caustic), and
        triangles across it are dropped."""
        return self.reflector_indices

    def update(self, frame: Frame) -> None:
        self.search(frame.view, frame.warm)

    def frame_stats(self) -> dict:
        return {"refraction": self.status_counts()}

    def _ensure(self) -> None:
        if self._atlas is None:
            self._atlas = MapAtlas(self.methods, self.geometry.shift)
        for method in self.methods:
            if method.index not in self._results:
                self._results[method.index] = (self.meshes.answer_texture(), self.meshes.answer_texture())

    def search(self, view, warm: bool = False) -> None:
        """This frame's search: one dispatch per glass, into its two result textures.
        ``warm``: each vertex starts from its last answer."""
        if self.n_vertices == 0 or not self.methods:
            return
        self._ensure()
        shader = refraction_shader()
        pixel_scale = bind_map_search(shader, view, self.meshes, self._atlas, warm)
        for k, method in enumerate(self.methods):
            shader.uniform_float("stop_per_w", search_module.STOP_FRACTION * method.accuracy_px * pixel_scale)
            shader.uniform_float("eta", float(method.ior))
            shader.uniform_int("self_map", k)
            entry, leave = self._results[method.index]
            shader.image("result", entry)
            shader.image("exit_result", leave)
            gpu.compute.dispatch(shader, *self.meshes.work_groups(LOCAL_SIZE))
        self.counts["searches"] += 1

    def answers(self) -> list:
        """The AnswerSet (glass index, entry texture, exit texture) of the last search per glass."""
        return [AnswerSet(index, entry, leave) for index, (entry, leave) in self._results.items()]

    def read(self, glass_index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The last search of one glass, read back: (N, 3) entry and exit points (world
        space, NaN without an answer) and the (N,) status codes."""
        entry, leave = self._results[glass_index]
        points, code = self.meshes.read(entry)
        exit_points = np.where(np.isfinite(points[:, :1]), self.meshes.read_points(leave), np.nan)
        return points, exit_points, (code % 16 - 8).astype(np.int8)

    def status_counts(self) -> dict:
        """{glass name: {"found", "not_converged", "total_reflection", "unanswered"}}."""
        counts = {}
        for method in self.methods:
            if method.index not in self._results:
                continue
            status = self.read(method.index)[2]
            counts[method.name] = {"found": int((status == FOUND).sum()),
                                   "not_converged": int((status == NOT_CONVERGED).sum()),
                                   "total_reflection": int((status == TOTAL_REFLECTION).sum()),
                                   "unanswered": int((status != FOUND).sum())}
        return counts
