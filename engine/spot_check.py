# SPDX-License-Identifier: GPL-3.0-or-later
"""A method's accuracy in the current view, measured on a few of its answers.

Every method answers with first reflector points; whichever drew a reflector, a handful
of its answers (a seeded sample of vertices that have one) are checked against exactly
traced rays: the answer's pixel starts Gauss-Newton on the true reflection law of the
mesh (``true_rays.polish_on_true_rays``, the iteration Roger & Holzschuch 2006, section
3.2, use to find reflections), which converges to the exact reflection nearest to it.
The distance between the two pixels is the answer's error. An answer whose iteration
does not converge within MAX_ERROR_PX (no true reflection near it: a reflection drawn
where there is none, or one off by more) is counted as *unconfirmed*. Cheap: a few
hundred traced rays, so the live view runs it whenever the view settles.

It measures what is drawn, not what is missing: a reflection a method leaves out has no
answer to check (the benchmarks measure coverage against the exact solver).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry.raytrace import ReflectorSet
from .reference.true_rays import polish_on_true_rays
from .view import View

#: Answers checked per reflector and view.
SAMPLE = 96
#: An answer more than this many pixels from every exact reflection is unconfirmed.
MAX_ERROR_PX = 12.0


@dataclass(frozen=True)
class SpotCheck:
    """Errors (desired-view px) of the answers checked for one reflector in one view."""

    checked: int  # answers checked
    errors: np.ndarray  # (confirmed,) px from each confirmed answer to the exact reflection

    @property
    def confirmed(self) -> int:
        return len(self.errors)

    @property
    def unconfirmed(self) -> int:
        return self.checked - self.confirmed

    def percentile(self, q: float) -> float:
        return float(np.percentile(self.errors, q)) if len(self.errors) else float("nan")

    def within(self, accuracy_px: float) -> bool:
        """Whether 95 % of the checked answers lie within ``accuracy_px`` of an exact
        reflection (unconfirmed ones count as beyond it)."""
        return self.checked > 0 and np.count_nonzero(self.errors <= accuracy_px) >= 0.95 * self.checked

    def summary(self) -> str:
        """One panel line, e.g. ``p95 0.31 px, max 0.8 px (96 checked)``."""
        if self.checked == 0:
            return "no reflection to check in this view"
        text = (f"p95 {self.percentile(95):.2f} px, max {self.errors.max():.1f} px" if self.confirmed
                else "no answer confirmed")
        text += f" ({self.checked} checked"
        if self.unconfirmed:
            text += f", {self.unconfirmed} more than {MAX_ERROR_PX:.0f} px off or not there"
        return text + ")"


def spot_check(reflector_set: ReflectorSet, view: View, reflector_index: int, points: np.ndarray,
               answers: np.ndarray, sample: int = SAMPLE, seed: int = 0) -> SpotCheck:
    """Check up to ``sample`` of a method's first-order answers for one reflector.

    ``points`` (P, 3) are the vertices the method answered for, ``answers`` (K, P, 3) its
    first reflector points in world space per image slot, NaN where none (the layout of
    every GPU pass's answer textures and of ``Projection.reflector_points``).
    """
    answers = np.asarray(answers, dtype=np.float64).reshape(-1, len(points), 3)
    slot, vertex = np.nonzero(np.isfinite(answers[..., 0]))
    if len(vertex) == 0:
        return SpotCheck(0, np.zeros(0))
    chosen = np.random.default_rng(seed).choice(len(vertex), size=min(sample, len(vertex)), replace=False)
    slot, vertex = slot[chosen], vertex[chosen]
    pixels, _ = view.to_pixels(answers[slot, vertex])
    on_screen = np.isfinite(pixels).all(axis=1)
    pixels, vertex = pixels[on_screen], vertex[on_screen]
    exact, _, _, ok = polish_on_true_rays(reflector_set, view, reflector_index, pixels, points[vertex],
                                          cell_px=MAX_ERROR_PX / 12.0)
    errors = np.linalg.norm(exact - pixels, axis=1)
    return SpotCheck(len(vertex), errors[ok & (errors <= MAX_ERROR_PX)])
