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
from ..frame_pass import PassInputs
from ..reflected_meshes import FLIPPED_CODE, AnswerSet
from ..shader_cache import cached_shader
from ..shader_sources import glsl_source
from .iterative_draw import MapSearchPass, map_search_info

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
        return self.meshes.answer_texture(), self.meshes.answer_texture()

    def bind(self, shader, method, results) -> None:
        shader.uniform_float("eta", float(method.ior))
        entry, leave = results
        shader.image("result", entry)
        shader.image("exit_result", leave)

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
