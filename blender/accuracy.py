# SPDX-License-Identifier: GPL-3.0-or-later
"""Accuracy shown live: per reflector, the method that drew it in the view, its error
there, measured on a few of its answers against exactly traced rays, and the exact
images it left out (``engine/spot_check.py``), once the view has settled.

The answers checked are the ones drawn: the per-frame passes' answer textures read back
(iterative search, baked grids, perturbation: ``ReflectionRenderer.answered``), or, for
a reflector the view's sample-based camera draws, that camera's projection of a sample
of the vertices. The live view (``blender/live.py``) runs :func:`measure` from its
timer when no view has changed for :data:`SETTLE_SECONDS`; the panel shows the figures,
and ``method_plan.note_measured`` lets Auto replace a method measured outside the scene's
Accuracy.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..engine.spot_check import (CONTACT_SHARE, SpotCheck, checked_points, coverage_check, mirror_distances,
                                 shown_answers, spot_check)
from ..drawing.frame_pass import FramePass
from ..drawing.reflected_meshes import REFLECTION_COSINE
from . import method_plan

#: A view unchanged this long (seconds) is checked.
SETTLE_SECONDS = 0.4
#: Vertices a Runtime camera projects for its check (on the CPU: a sample, not all).
CAMERA_SAMPLE = 3000


@dataclass(frozen=True)
class Measured:
    """What drew one reflector in the view checked, and how accurately."""

    method: str  # method_plan.ITERATIVE, MORPHING, OCTREE, PERTURBATION or RUNTIME
    check: SpotCheck


class Drawn(NamedTuple):
    """One reflector's answers in the last frame."""

    vertices: np.ndarray  # (P,) indices of the renderer's vertices answered for
    answers: np.ndarray  # (K, P, 3) first reflector points, world space, NaN where none
    per_frame: bool  # from a per-frame pass (else from the sample-based camera)


def drawn_answers(reflector_set, renderer, camera, sample: int | None = None, seed: int = 0,
                  chosen: np.ndarray | None = None, answered: dict | None = None) -> dict:
    """{reflector index: Drawn}: the first reflector points (world space, NaN where none)
    the last frame drew for the renderer's vertices: every vertex of the per-frame passes'
    reflectors, and ``sample`` vertices (seeded; default :data:`CAMERA_SAMPLE`, read at
    each call) projected by ``camera`` (the sample-based camera the frame was drawn with,
    or None) for the reflectors it drew (``chosen``: these vertex indices instead). What
    the live check and ``bench_methods.py`` measure, whichever method drew. ``answered``:
    ``renderer.answered()``, read back on the drawing thread already (the rest runs
    anywhere)."""
    vertices = renderer.geometry.vertices
    every = np.arange(len(vertices))
    answered = renderer.answered() if answered is None else answered
    found = {index: Drawn(every, answers, True) for index, answers in answered.items()}
    if camera is None or len(vertices) == 0:
        return found
    if chosen is None:
        sample = CAMERA_SAMPLE if sample is None else sample
        chosen = np.sort(np.random.default_rng(seed).choice(len(vertices), size=min(sample, len(vertices)),
                                                            replace=False))
    projection = camera.project(vertices[chosen])
    for index in range(len(reflector_set.reflectors)):
        rows = [g for g, history in enumerate(projection.groups) if tuple(history) == (index,)]
        if index not in found and rows:
            found[index] = Drawn(chosen, np.where(projection.valid[rows][..., None],
                                                  projection.reflector_points[rows], np.nan), False)
    return found


def measure(plan, reflector_set, renderer, view, camera, sample: int | None = None, drawn: dict | None = None) -> dict:
    """{reflector name: Measured} for the last frame ``renderer`` drew of ``view``;
    ``camera``: the sample-based camera it drew with (None when the per-frame passes
    drew every reflector); ``sample``: answers checked per reflector (default
    ``spot_check.SAMPLE``); ``drawn``: :func:`drawn_answers` when the caller has read
    them already. Per reflector, of a pool of the answered points, half of them the
    nearest to the mirror (``spot_check.checked_points``): the answers the picture shows
    (``shown_answers``), their error (``spot_check``) and the exact images they miss,
    object by object (``coverage_check``; a camera's band along the mirror's outline,
    which the render traces, not counted)."""
    vertices = renderer.geometry.vertices
    planned = {choice.reflector: choice.method for choice in plan.choices}
    options = {} if sample is None else {"sample": sample}
    if drawn is None:
        drawn = drawn_answers(reflector_set, renderer, camera)
    found = {}
    for index, answered in drawn.items():
        name = reflector_set.reflectors[index].name
        method = planned.get(name, method_plan.RUNTIME) if answered.per_frame else method_plan.RUNTIME
        mirror = reflector_set.reflectors[index].vertices
        distances = mirror_distances(vertices[answered.vertices], mirror)
        pool = checked_points(distances)
        points = vertices[answered.vertices[pool]]
        answers = shown_answers(reflector_set, view, index, points, answered.answers[:, pool], REFLECTION_COSINE,
                                FramePass.hidden_fraction)
        check = spot_check(reflector_set, view, index, points, answers, **options)
        owners = renderer.geometry.vertex_mesh[answered.vertices[pool]]
        contact = CONTACT_SHARE * float(renderer.geometry.reflector_sizes[index])
        band = 0 if answered.per_frame or camera is None else camera.ray_map.downsample
        coverage = coverage_check(reflector_set, view, index, points, answers, groups=owners,
                                  distances=distances[pool], contact_distance=contact, band_px=band)
        check = check.with_coverage(coverage, renderer.geometry.mesh_names[coverage.group] if coverage.group >= 0
                                    else "")
        found[name] = Measured(method, check)
    return found


def panel_line(measured: Measured) -> str:
    """The panel's line for one reflector, e.g. ``In this view: p95 0.21 px, max 0.62 px
    (96 checked)``."""
    return f"In this view ({measured.method.title()}): {measured.check.summary()}"
