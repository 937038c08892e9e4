# SPDX-License-Identifier: GPL-3.0-or-later
"""What the renderer asks of a method that answers every vertex on the GPU each frame.

The iterative search (``methods/iterative_draw.py``), the morphing grids, tetrahedral and
octree (``methods/morph_pass.py``), and perturbation (``methods/perturbation_pass.py``)
each write one answer texture per reflector (and image slot) that
:class:`.reflected_meshes.ReflectedMeshes` draws. The renderer (``reflection_draw.py``)
holds them as a tuple of :class:`FramePass` and never asks which method one is: it
updates them for the view, draws their answers, and traces the pixels each says its
method cannot be trusted on.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

from ..engine.frame_settings import FrameSettings

#: 20 degrees: an answer from another sheet of a curved mirror (across a fold, a crease,
#: another image in the same slot) misses by far more; an interpolated point of a small
#: reflected triangle by far less.
REFLECTION_COSINE = math.cos(math.radians(20.0))


@dataclass(frozen=True)
class PassInputs:
    """What a renderer hands each pass it makes (:meth:`FramePass.factory`): its reflected
    geometry (``draw_geometry.DrawGeometry``) and that geometry on the GPU
    (``reflected_meshes.ReflectedMeshes``), every reflector of the scene and their
    ray-tracing set when the caller keeps one, the convexity of each mirror
    (``closed_surfaces.ConvexMirrors``, tested once for every pass), and the frame's
    settings."""

    geometry: object
    meshes: object
    reflectors: tuple
    reflector_set: object
    convex_mirrors: object
    settings: FrameSettings


class FramePass:
    """One method's per-frame GPU work for one renderer. Subclasses implement
    :meth:`of_inputs`, :meth:`update` and :meth:`answers`, and hold ``methods`` (one per
    reflector, each with its ``index``) or override :attr:`reflector_indices`; the rest
    says how the renderer's band trace treats the pass's reflectors and what work it does
    off the drawing thread, and defaults to *not at all*."""

    #: The pass's name in statistics and in ``ReflectionRenderer.pass_named``.
    name = "pass"

    #: Whether the method answers by a search per vertex (see :attr:`searched_reflectors`).
    searches = False

    #: A reflected fragment whose reflector point lies farther from the eye than the mirror
    #: surface the pre-pass saw at its pixel, by more than this fraction of the reflector's
    #: bounding-box diagonal, is hidden by the mirror itself and dropped
    #: (``glsl/reflection_mesh_frag.glsl``): a per-vertex method answers without tracing
    #: the eye's ray. On a bumpy sphere, perturbation's answers hidden behind a bump lie
    #: 0.1-2.5 % of it behind the surface seen (median 1 %; this catches 63-70 % of them),
    #: its visible answers at most 0.13 % (``tests/drawing/test_reflected_meshes.py``).
    hidden_fraction = 0.003
    #: A reflected fragment is kept only where the eye's ray, reflected about the normal of
    #: the mirror the pre-pass saw at its pixel, leaves within this cosine of the direction
    #: toward the fragment's point of the mesh (``glsl/reflection_mesh_frag.glsl``; the
    #: sample-based camera's first-order triangles are held to the same).
    reflection_cosine = REFLECTION_COSINE
    #: The same test in a render (Render Image): a pass whose answers are approximate can
    #: ask for a tighter one there, where a dropped fragment is traced or shows the world
    #: rather than a wrong object.
    rendered_reflection_cosine = REFLECTION_COSINE

    #: The Accuracy (px) the pass answers to, which sets the live view's snapping grid
    #: (``reflected_meshes.SNAP_SHARE``); None: the pass's images are not that accurate
    #: (the blended grids), and are not snapped.
    accuracy_px = None

    @classmethod
    def factory(cls, methods):
        """What a renderer calls with its :class:`PassInputs` to make this pass for
        ``methods`` (the method plan's engines: ``MethodPlan.pass_factories``)."""
        return functools.partial(cls.of_inputs, tuple(methods))

    @classmethod
    def of_inputs(cls, methods: tuple, inputs: PassInputs) -> "FramePass":
        raise NotImplementedError

    @property
    def reflector_indices(self) -> list:
        """Every reflector this pass may draw."""
        return [method.index for method in self.methods]

    def update(self, view, warm: bool = False, skip=frozenset()) -> None:
        """This frame's answers for ``view``. ``warm``: start from the last frame's (a
        viewport moving a little); a render is cold, so that its image depends on its
        view alone. ``skip``: reflectors a sample-based camera draws this frame instead."""
        raise NotImplementedError

    def answers(self) -> list:
        """(reflector index, answer texture) of the last update, for ``ReflectedMeshes.draw``."""
        raise NotImplementedError

    def drawn_in(self, view) -> frozenset:
        """The reflectors whose first-order reflections this pass draws in ``view`` (a
        camera made for the view leaves them out)."""
        return frozenset(self.reflector_indices)

    @property
    def searched_reflectors(self) -> list:
        """Reflectors answered by a search per vertex: vertices go unanswered along their
        silhouette, so the band there is traced."""
        return self.reflector_indices if self.searches else []

    @property
    def folded_reflectors(self) -> list:
        """Reflectors whose images may crowd or fold (not convex, or not alone): the
        pixels next to their drawn reflections are traced too."""
        return []

    @property
    def mirrored_reflectors(self) -> list:
        """Reflectors every image of which is mirrored, as in a flat mirror (a convex
        mirror: its caustic lies behind the surface, no image is flipped): on screen a
        mirror reverses the winding of every triangle, so the far sides of closed
        solids can be culled by winding (``ReflectedMeshes.draw``)."""
        return []

    @property
    def gap_reflectors(self) -> list:
        """Reflectors the last update drew with gaps a render may trace (``trace_gaps``)."""
        return []

    @property
    def traces_band(self) -> bool:
        """Whether a render traces the band of this pass's reflectors at all."""
        return bool(self.searched_reflectors)

    def statistics(self) -> list:
        """Lines for the panel's Statistics (what the pass holds, e.g. on the GPU)."""
        return []

    def frame_stats(self) -> dict:
        """What a render reports about this pass's last frame (read back from the GPU)."""
        return {}

    def status_counts(self) -> dict:
        """{reflector index: {"found": n, "unanswered": n}} of the last frame's answers,
        read back from the GPU (the live statistics; costly: not every frame)."""
        return {}

    # Work off the drawing thread (the live view and an animation run it between frames).

    def collect(self) -> None:
        """Take up the work a worker finished since the last call (put it on the GPU)."""

    def prefetch(self, view, submit, **options) -> bool:
        """Start work ``view`` will need soon on a worker (``submit``, an executor's);
        returns whether any was started."""
        return False

    @property
    def prefetching(self) -> bool:
        """Whether work started by :meth:`prefetch` is still running."""
        return False

    @property
    def prefetched(self) -> bool:
        """Whether work landed that the next draw should show (the caller redraws)."""
        return False
