# SPDX-License-Identifier: GPL-3.0-or-later
"""A chosen mode's picture of a mirror against the same view ray traced, pixel by pixel.

The spot check (``blender/accuracy.py``) measures a method's answers at sampled vertices:
each may be exact while the triangles between them are wrong. Where a mirror folds its
reflections, two neighbouring vertices of a mesh can take different images of it, and
the reflected triangle between them spans the fold: a shard across the mirror, with
every vertex checked right (perturbation on a bumpy ball, a sample-based camera whose
rays cross). Auto draws its per-vertex methods only on mirrors that do not fold (it
traces the others); a chosen mode may draw any. So a frame drawn in a chosen mode (in
Render Image, and once per renderer in the resting live view: ``live_check.py``) is also
drawn with every reflector ray traced (each pixel's exact ray,
``drawing/methods/traced_pass.py``), and a reflector whose pixels differ from the
trace's on more than :data:`MAX_UNLIKE_SHARE` of them is passed over like a method the
spot check failed (``method_plan.note_outside``): the trace draws it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..drawing.gpu_data import read_texture
from ..drawing.reflection_draw import ReflectionRenderer
from . import method_plan

#: A pixel whose linear colour differs from the trace's by more than this in a channel
#: shows something else (another object, or the world): the shading of one surface seen
#: along two rays a fraction of a pixel apart differs far less.
UNLIKE_COLOUR = 0.1
#: A picture is the trace's when at most this share of the mirror's pixels is unlike it
#: (issue 44's bar against Cycles): a method right at every vertex still differs from the
#: exact rays on 1-1.5 % of a ball's pixels at 480x320, where a fine checker's edges cross
#: pixels; a shard across a fold, or a fold's image left out, costs more.
MAX_UNLIKE_SHARE = 0.02
#: A mirror of fewer pixels than this (about 50 across) is not judged: there the edges of
#: a fine pattern, which the raster and the rays cut a little differently, make up more
#: than the share allowed (sbc_fig3's ball at 80x60, 700 px, drawn right: 2.1 %).
MIN_PIXELS = 2000


@dataclass(frozen=True)
class PictureCheck:
    """One reflector's pixels in a frame and how many of them were unlike the trace's."""

    pixels: int
    unlike: int

    @property
    def share(self) -> float:
        return self.unlike / self.pixels if self.pixels else 0.0

    def within(self) -> bool:
        return self.pixels < MIN_PIXELS or self.share <= MAX_UNLIKE_SHARE

    def shortfall(self) -> str:
        return f"{100.0 * self.share:.1f} % of its pixels unlike the same view ray traced"


def compare(image: np.ndarray, traced: np.ndarray, labels: np.ndarray, indices) -> dict:
    """{reflector index: PictureCheck} of ``image`` against ``traced`` (both (H, W, 4)
    linear RGBA of one view) on each reflector's pixels (``labels``: (H, W) reflector
    index + 1 of the pixels it covers, 0 elsewhere)."""
    unlike = np.abs(np.asarray(image)[..., :3] - np.asarray(traced)[..., :3]).max(axis=2) > UNLIKE_COLOUR
    ids = np.rint(labels).astype(np.int64)
    return {index: PictureCheck(int(np.count_nonzero(ids == index + 1)),
                                int(np.count_nonzero(unlike & (ids == index + 1)))) for index in indices}


class TracedReference:
    """A renderer of a pipeline's capture with every reflector ray traced, made on the
    first check of a renderer and kept for the checks of its later frames."""

    def __init__(self):
        self._renderer = None
        self._of = None

    def render(self, pipeline, view) -> tuple:
        """(image, labels) of ``view`` (``pipeline``: a ``frame_pipeline.FramePipeline``):
        the trace's frame and the reflector index + 1 of each pixel (as :func:`compare`
        reads them)."""
        if self._of is not pipeline.renderer:
            plan = method_plan.traced_plan(pipeline.captured.reflectors)
            self._renderer = ReflectionRenderer(pipeline.captured.reflectors, pipeline.captured.meshes,
                                                passes=plan.pass_factories(), settings=pipeline.settings,
                                                reflector_set=pipeline.reflector_set,
                                                glasses=pipeline.captured.glass, **pipeline.properties)
            self._of = pipeline.renderer
        image = self._renderer.render(view, None, pipeline.world)
        targets = self._renderer.targets(view.width, view.height)
        labels = read_texture(targets.prepass_labels, view.width, view.height)[..., 0]
        return image, np.where(targets.outside_box(), 0.0, labels)


def judged(scene, plan) -> list:
    """The indices of the reflectors a chosen mode draws with another method than the
    trace: the ones whose picture is checked."""
    return [index for index, choice in enumerate(plan.choices)
            if choice.method != method_plan.TRACED and method_plan.mode_of(scene, choice.reflector) != method_plan.AUTO]


def check_picture(scene, pipeline, view, image: np.ndarray) -> bool:
    """Compare the frame ``image`` of ``view`` that ``pipeline`` (a
    ``frame_pipeline.FramePipeline``) drew with the trace (its ``traced_reference``)
    where a chosen mode drew a reflector with another method; pass that method over
    where the picture differs (``method_plan.note_outside``). Returns whether one was:
    the caller plans again."""
    chosen = judged(scene, pipeline.plan)
    if not chosen:
        return False
    traced, labels = pipeline.traced_reference.render(pipeline, view)
    replaced = False
    for index, check in compare(image, traced, labels, chosen).items():
        choice = pipeline.plan.choices[index]
        method_plan.note_picture(scene, choice.reflector, check)
        if not check.within():
            replaced |= method_plan.note_outside(scene, choice.reflector, choice.method, check.shortfall())
    return replaced
