# SPDX-License-Identifier: GPL-3.0-or-later
"""Perturbation's per-vertex work on the GPU: the compute stage
``glsl/perturbation_step.glsl``, the float32 twin of ``engine/methods/perturbation``'s
projector for first-order histories in perspective views.

Per view the seed paths are traced on the CPU (``PerturbationMethod.grid_groups``: a
few thousand rays) and uploaded, one texture of seeds and one of the grid per
reflector; one dispatch then answers every vertex: candidates, hops, the Taylor step
and its estimate, and on an exact sphere or ellipsoid the adaptive seeds (the eye ray
meets the quadric in the shader). Images grazing the mirror are left out
(``projector.grazing``). On a mesh or a superquadric the shader traces no rays: a
vertex whose step from the grid is not within the accuracy gets no answer there (the
numpy path traces more seeds for it), so the pass traces the grid finer first where the
seeds' quadrics miss the surface (``PerturbationMethod.fine_enough``); the renderer's
silhouette band is ray traced either way.
"""

from __future__ import annotations


import gpu
import numpy as np

from ...engine.methods.perturbation import answers, candidates, projector, taylor_step
from ..gpu_data import data_texture
from ..reflected_meshes import FOUND_CODE
from ..shader_sources import glsl_source
from ..shader_cache import cached_shader

#: Invocations per work group (along x).
LOCAL_SIZE = 64
#: Texels per seed in the seed texture.
SEED_TEXELS = 6
#: Image ranks answered per vertex (result textures).
RANKS = 3
#: Coarse grid columns the candidate search keeps in its three-row ring.
MAX_COLUMNS = 256
#: Candidate images followed per vertex.
MAX_CANDIDATES = 6


def step_defines() -> dict:
    """The engine's constants, as the shader's ``#define`` s."""
    p, step = projector, taylor_step
    return {"SEED_TEXELS": SEED_TEXELS, "MAX_COLUMNS": MAX_COLUMNS,
            "MAX_CANDIDATES": MAX_CANDIDATES, "CANDIDATE_SPREAD": f"{candidates.CANDIDATE_SPREAD:.9e}", "HOPS": p.HOPS,
            "HOP_SAMPLES": p.HOP_SAMPLES,
            "REACH": f"{p.REACH:.9e}", "MAX_RELATIVE_STEP": f"{step.MAX_RELATIVE_STEP:.9e}",
            "BEHIND_START": f"{step.BEHIND_START:.9e}", "GRAZING_COSINE": f"{p.GRAZING_COSINE:.9e}",
            "MODEL_SAFETY": f"{step.MODEL_SAFETY:.9e}",
            "REFINE_ROUNDS": p.REFINE_ROUNDS, "MAX_MISSES": p.MAX_MISSES,
            "SAME_IMAGE_PX": f"{answers.SAME_IMAGE_PX:.9e}", "FOUND_CODE": f"{float(FOUND_CODE):.1f}"}


@cached_shader
def step_shader():
    """The compute shader of the step, built on first use."""
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('INT', "n_vertices")
    info.push_constant('INT', "positions_width")
    info.push_constant('INT', "seeds_width")
    info.push_constant('INT', "grid_width")
    info.push_constant('INT', "analytic")
    info.sampler(0, 'FLOAT_2D', "vertex_positions")
    info.sampler(1, 'FLOAT_2D', "seeds")
    info.sampler(2, 'FLOAT_2D', "grid")
    info.sampler(3, 'FLOAT_2D', "params")
    for k in range(RANKS):
        info.image(k, 'RGBA32F', 'FLOAT_2D', f"result{k}", qualifiers={'WRITE'})
    info.local_group_size(LOCAL_SIZE, 1)
    info.compute_source(glsl_source("perturbation_step.glsl", step_defines()))
    return gpu.shader.create_from_info(info)


def shifted(hessian: np.ndarray, linear: np.ndarray, constant: np.ndarray, shift: np.ndarray):
    """(b', c') of quadrics g(y + shift) = y^T Q y / 2 + b' . y + c' (Q unchanged)."""
    moved = hessian @ shift
    return linear + moved, constant + 0.5 * moved @ shift + linear @ shift


def seed_texels(group, shift: np.ndarray) -> np.ndarray:
    """(S * SEED_TEXELS, 4) float32: the group's seeds, relative to ``shift``."""
    seeds, quadric = group.seeds, group.quadrics[-1]
    q = np.asarray(quadric.hessian)
    linear, constant = shifted(q, np.asarray(quadric.linear), np.asarray(quadric.constant), shift)
    count = len(seeds.pixels)
    texels = np.zeros((count, SEED_TEXELS, 4))
    texels[:, 0, :3] = seeds.points[:, -1] - shift
    texels[:, 0, 3] = np.minimum(seeds.head, 1e30)
    texels[:, 1, :3] = seeds.outgoing
    texels[:, 2] = np.stack([q[:, 0, 0], q[:, 0, 1], q[:, 0, 2], q[:, 1, 1]], axis=1)
    texels[:, 3, :3] = np.stack([q[:, 1, 2], q[:, 2, 2], group.model_error], axis=1)
    texels[:, 4, :3], texels[:, 4, 3] = linear, constant
    texels[:, 5, :2] = seeds.pixels
    return texels.reshape(-1, 4).astype(np.float32)


def params_texels(view, group, accuracy_px: float, surface, shift: np.ndarray) -> np.ndarray:
    """The shader's ``params`` row (see the shader's header)."""
    translate = np.eye(4)
    translate[:3, 3] = shift
    vp = np.asarray(view.projection_matrix) @ np.asarray(view.view_matrix) @ translate
    rows = np.zeros((15, 4))
    rows[0:4] = vp.T  # GLSL matrices are set column by column
    rows[4:8] = np.linalg.inv(vp).T
    rows[8, :3] = view.eye - shift
    rows[9] = (*group.origin, group.grid.shape[1], group.grid.shape[0])
    rows[10] = (group.stride, accuracy_px, view.width, view.height)
    if surface is not None:
        q, b, c = surface.quadric()
        b, c = shifted(q[None], b[None], np.array([c]), shift)
        rows[11] = (q[0, 0], q[0, 1], q[0, 2], q[1, 1])
        rows[12, :2] = (q[1, 2], q[2, 2])
        rows[13] = (*b[0], c[0])
    rows[14, 0] = group.coarse
    return rows.astype(np.float32)


class PerturbationStep:
    """The step on the GPU for one renderer's vertices (``meshes``: its
    ``ReflectedMeshes``): :meth:`answer` writes a group's RANKS answer textures."""

    def __init__(self, meshes):
        self.meshes = meshes
        self._results: dict = {}

    def answer(self, view, group, accuracy_px: float, surface=None) -> list:
        """The answer textures of ``group`` (a first-order ``SeedGroup``) in ``view``, one
        per image rank (kept per history and written again by the next view's call);
        ``surface``: the reflector's exact surface (adaptive seeds in the shader)."""
        shift = self.meshes.geometry.shift
        seeds = data_texture(seed_texels(group, shift))
        grid = data_texture(group.grid.reshape(-1, 1).astype(np.float32))
        params = data_texture(params_texels(view, group, accuracy_px, surface, shift))
        if group.history not in self._results:
            self._results[group.history] = [self.meshes.answer_texture() for _ in range(RANKS)]
        results = self._results[group.history]
        shader = step_shader()
        shader.bind()
        shader.uniform_int("n_vertices", self.meshes.n_vertices)
        shader.uniform_int("positions_width", self.meshes.width)
        shader.uniform_int("seeds_width", seeds.width)
        shader.uniform_int("grid_width", grid.width)
        shader.uniform_int("analytic", int(surface is not None))
        shader.uniform_sampler("vertex_positions", self.meshes.positions)
        shader.uniform_sampler("seeds", seeds)
        shader.uniform_sampler("grid", grid)
        shader.uniform_sampler("params", params)
        for k, texture in enumerate(results):
            shader.image(f"result{k}", texture)
        gpu.compute.dispatch(shader, *self.meshes.work_groups(LOCAL_SIZE))
        return results
