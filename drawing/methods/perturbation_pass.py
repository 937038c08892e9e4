# SPDX-License-Identifier: GPL-3.0-or-later
"""Perturbation (Chen & Arvo 2000) drawn like the other per-frame methods.

Per new view, ``engine.methods.perturbation`` traces the seed paths; every diffuse
vertex's Taylor step then runs on the GPU (``perturbation_gpu.py``; in numpy for an
orthographic view) into answer textures, one per image rank (a non-convex mirror shows
a point several times), which :class:`..reflected_meshes.ReflectedMeshes` draws with the
iterative search's and morphing's vertex stage. An unchanged view reuses the textures:
an orbit costs one projection per frame, a still viewport none.
"""

from __future__ import annotations

import numpy as np

from ...engine.methods.perturbation import PerturbationMethod, PerturbationSettings, PerturbationStats
from ...engine.methods.perturbation.projector import grazing
from ...engine.geometry.raytrace import ReflectorSet
from ..frame_pass import Frame, FramePass, PassInputs
from ..gpu_data import data_texture
from ..reflected_meshes import FOUND_CODE, ReflectedMeshes
from .perturbation_gpu import RANKS, PerturbationStep


class PerturbationPass(FramePass):
    """The perturbation reflectors of one renderer (``reflectors``: every reflector of
    the scene, which may block or carry the paths, ``reflector_set`` their BVH when the
    caller keeps one; ``methods``: the ``engine.methods.perturbation.PerturbationReflector``
    s drawn here)."""

    name = "perturbation"
    searches = True

    @classmethod
    def of_inputs(cls, methods: tuple, inputs: PassInputs) -> "PerturbationPass":
        return cls(inputs.geometry, inputs.reflectors, methods, inputs.meshes, inputs.settings.accuracy_px,
                   inputs.reflector_set)

    def __init__(self, geometry, reflectors, methods, meshes: ReflectedMeshes, accuracy_px: float = 0.5,
                 reflector_set: ReflectorSet | None = None):
        self.geometry = geometry
        self.methods = list(methods)
        self.meshes = meshes
        self._engine = None
        self._step = None
        self._reflectors = list(reflectors)
        self._reflector_set = reflector_set
        self._accuracy = float(accuracy_px)
        self._view_key = None
        self._answers: list = []
        self.counts = {"projections": 0}
        self.last_stats = None

    def update(self, frame: Frame) -> None:
        """:meth:`project` (``frame.claimed`` never holds one of its reflectors: it draws
        them in every view, :meth:`drawn_in`, so a camera leaves them out)."""
        self.project(frame.view)

    @property
    def engine(self) -> PerturbationMethod:
        if self._engine is None:
            analytic = {m.index: m.surface for m in self.methods if m.surface is not None}
            reflector_set = self._reflector_set if self._reflector_set is not None else ReflectorSet(self._reflectors)
            self._engine = PerturbationMethod(reflector_set, analytic,
                                              PerturbationSettings(accuracy_px=self._accuracy))
        return self._engine

    def project(self, view) -> None:
        """This view's answer textures (kept while the view does not change)."""
        if not self.methods or self.meshes.n_vertices == 0:
            return
        key = (np.asarray(view.view_matrix).tobytes(), np.asarray(view.projection_matrix).tobytes(),
               view.width, view.height)
        if key == self._view_key:
            return
        self._answers = self._on_gpu(view) if view.is_perspective else self._in_numpy(view)
        self.last_stats = self.engine.stats
        self._view_key = key
        self.counts["projections"] += 1

    def _on_gpu(self, view) -> list:
        """Seeds traced here, every vertex's step on the GPU (``perturbation_gpu.py``). An
        exact surface (convex) shows a point once: one image rank is drawn. The shader's
        adaptive seeds meet a sphere or ellipsoid (a quadric) in closed form and assume no
        other mirror blocks their rays; on a superquadric it traces none, as on a mesh, and
        the seeds are traced finer where their model errs (``PerturbationMethod.fine_enough``)."""
        if self._step is None:
            self._step = PerturbationStep(self.meshes)
        self.engine.stats = PerturbationStats()
        methods = {(m.index,): m for m in self.methods}
        answers = []
        for group in self.engine.grid_groups(view):
            method = methods.get(group.history)
            if method is None:
                continue
            exact = method.surface is not None and method.surface.is_quadric
            alone = method.surface if exact and len(self._reflectors) == 1 else None
            if alone is None:  # the shader traces no adaptive seeds: a grid fine enough instead
                group = self.engine.fine_enough(view, group)
            textures = self._step.answer(view, group, self._accuracy, alone)
            ranks = 1 if method.surface is not None else RANKS
            answers += [(method.index, texture) for texture in textures[:ranks]]
        return answers

    def _in_numpy(self, view) -> list:
        """Every vertex's step in numpy, uploaded (orthographic views; the reference);
        images grazing the mirror are not drawn (``projector.grazing``), as on the GPU."""
        projection = self.engine.project(view, self.geometry.vertices, [(m.index,) for m in self.methods])
        answers = []
        for g, history in enumerate(projection.groups):
            texels = np.zeros((self.meshes.n_vertices, 4), np.float32)
            valid = projection.valid[g].copy()
            valid[valid] = ~grazing(view, self.geometry.vertices[valid], projection.reflector_points[g, valid])
            texels[valid, :3] = projection.reflector_points[g, valid] - self.geometry.shift
            texels[valid, 3] = FOUND_CODE
            answers.append((history[0], data_texture(texels, self.meshes.width)))
        return answers

    @property
    def accuracy_px(self) -> float:
        """The Accuracy its steps are held to (their error estimate)."""
        return self._accuracy

    @property
    def mirrored_reflectors(self) -> list:
        """The reflectors declared exact surfaces: a sphere, an ellipsoid and a
        superquadric (exponent at least 2) bound convex bodies, and the pass draws first
        order only."""
        return [m.index for m in self.methods if m.surface is not None]

    @property
    def folded_reflectors(self) -> list:
        """The reflectors that showed a point twice in the last view (a non-convex
        mirror), or share the scene with other mirrors: the renderer traces the pixels
        next to their drawn reflections too."""
        indices = [k for k, _ in self._answers]
        return [m.index for m in self.methods if indices.count(m.index) > 1 or len(self._reflectors) > 1]

    def answers(self) -> list:
        """(reflector index, answer texture) of the last view, for ``ReflectedMeshes.draw``."""
        return list(self._answers)
