# SPDX-License-Identifier: GPL-3.0-or-later
"""The one question every method answers: where does this 3D point appear, reflected,
in this view?

Every method (the sample-based camera of ``engine/methods/sbc/sbc.py``, its morphing grid, the
iterative search of ``engine/methods/iterative``) answers with a :class:`Projection`:
for each reflection group (a reflection history; a history repeats where one method
needs several sheets of it) and each point, whether it appears, its first reflector
point, the pixel where that point is seen and the distance from the last reflector
point to the point along the reflected ray. The benchmarks and the accuracy tests
compare methods through it alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: ``Projection.leaf_kind`` values: how an answer was found.
NOT_PROJECTED, CAMERA_LEAF_ANSWER, RAY_LIST_ANSWER, SEARCH_ANSWER, PERTURBATION_ANSWER = 0, 1, 2, 3, 4


@dataclass(frozen=True)
class Projection:
    """Where P points appear in G reflection groups."""

    groups: list  # G reflection histories, tuples of reflector indices
    reflector_points: np.ndarray  # (G, P, 3) first reflector point, NaN where not projected
    valid: np.ndarray  # (G, P) bool
    leaf_kind: np.ndarray  # (G, P) int8: NOT_PROJECTED ... PERTURBATION_ANSWER
    pixels: np.ndarray  # (G, P, 2) desired-view pixel of the reflection, NaN where not projected
    ray_distance: np.ndarray  # (G, P) distance from the last reflector point along the ray
