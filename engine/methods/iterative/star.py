# SPDX-License-Identifier: GPL-3.0-or-later
"""Is a reflector star-shaped, and from which centre? (Roger & Holzschuch 2006, 3.3.1)

The iterative search needs a point O from which every point of the reflector's surface
is seen directly, so that the surface is one radius per direction (Fig. 4). A few
candidate centres are tried (volume and area centroids, box centre, vertex mean); from
each, rays through a coarse cube map must meet the surface exactly once and never graze
it, and every
surface sample (the vertices and face centroids) must be the first thing its ray from O
meets. The first candidate that passes is O; the full-resolution bake
(:func:`prepare_iterative`) checks its rays once more. A torus (its hole), a monkey
head (ears, eye sockets) or a teapot (handle, spout) fail, and the message says why.
So does an open mirror (a vase open at the top, a bowl): every ray from O must meet the
surface, since the map holds one radius per direction and the inner side of an open
mirror, seen through its opening, would have none (the Chen-Arvo vase, open at both
ends, is seen whole from a point on its axis, and drawn as star-shaped most of its
pixels would show the wrong object).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...geometry.raytrace import ReflectorSet
from ...scene import Reflector, triangle_areas
from ...geometry.vectors import lengths
from .reflector_map import DEFAULT_FACE_SIZE, MapBake, bake_reflector_map

#: Smallest cosine allowed between a ray from O and the face it meets: below it r(d)
#: is too steep there for the texture to hold the surface and for the search to settle.
#: Measured on three fused metaballs (cosine 0.10 at their necks): 4,700 of 16,000
#: vertices did not converge and 22.9 % of the mirror's pixels showed another object than
#: Cycles (10.7 % in Runtime mode); the demo's and the benchmark's star-shaped mirrors
#: stay above 0.5.
MIN_COSINE = 0.25
#: Face size of the coarse maps that screen the candidate centres.
CHECK_FACE_SIZE = 24
#: Surface samples (vertices and face centroids) tested for being seen from O.
SURFACE_SAMPLES = 4000
#: A sample is seen when its ray from O meets nothing closer than this share of its distance.
SEEN_TOLERANCE = 1e-6


@dataclass(frozen=True)
class StarShape:
    """The verdict on one reflector: ``centre`` O (the best one tried), and ``reason``
    (empty when star-shaped) naming what failed, for the panel."""

    name: str
    star_shaped: bool
    centre: np.ndarray
    reason: str
    crossings: int
    hidden_share: float
    min_cosine: float


def centre_candidates(reflector: Reflector) -> list:
    """Candidate centres, most likely first."""
    corners = reflector.vertices[reflector.triangles]
    areas = triangle_areas(reflector.vertices, reflector.triangles)
    centroids = corners.mean(axis=1)
    area_centroid = (centroids * areas[:, None]).sum(axis=0) / max(areas.sum(), 1e-300)
    lo, hi = reflector.bounds
    candidates = [area_centroid, 0.5 * (lo + hi), reflector.vertices.mean(axis=0)]
    # Signed tetrahedra from the area centroid: the volume centroid of a closed mesh.
    a, b, c = (corners[:, k] - area_centroid for k in range(3))
    volumes = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    if abs(volumes.sum()) > 1e-9 * float(np.prod(np.maximum(hi - lo, 1e-12))):
        tetra_centroids = area_centroid + (a + b + c) / 4.0
        candidates.insert(0, (tetra_centroids * volumes[:, None]).sum(axis=0) / volumes.sum())
    return [np.asarray(c, dtype=np.float64) for c in candidates]


def _surface_samples(reflector: Reflector) -> np.ndarray:
    centroids = reflector.vertices[reflector.triangles].mean(axis=1)
    samples = np.concatenate([np.unique(reflector.vertices, axis=0), centroids])
    if len(samples) > SURFACE_SAMPLES:
        samples = samples[np.random.default_rng(0).choice(len(samples), SURFACE_SAMPLES, replace=False)]
    return samples


def _hidden_share(reflector_set: ReflectorSet, centre: np.ndarray, samples: np.ndarray) -> float:
    """Share of ``samples`` that something of the reflector hides from ``centre``."""
    offset = samples - centre
    distance = lengths(offset)
    usable = distance > SEEN_TOLERANCE * reflector_set.scale
    if not usable.all():
        return 1.0  # the centre lies on the surface
    hits = reflector_set.intersect(np.broadcast_to(centre, samples.shape), offset / distance[:, None])
    seen = hits.t >= distance * (1.0 - SEEN_TOLERANCE) - SEEN_TOLERANCE * reflector_set.scale
    return float(1.0 - seen.mean())


def verdict(name: str, centre, bake: MapBake, hidden: float) -> StarShape:
    """The verdict from a centre's baked map and its share of hidden surface samples."""
    if bake.crossings:
        reason = (f"{name!r} is not star-shaped: from its best centre, rays meet its surface more than once "
                  f"(a hole, a handle or a deep fold)")
    elif hidden > 0:
        reason = (f"{name!r} is not star-shaped: {100 * hidden:.1f} % of its surface is hidden from every "
                  "centre tried")
    elif bake.coverage < 1.0:
        reason = (f"{name!r} is open: {100 * (1 - bake.coverage):.0f} % of the directions from its centre "
                  "leave through a hole, and its inner side, which shows through it, has no place in the map")
    elif bake.min_cosine < MIN_COSINE:
        reason = (f"{name!r} is not star-shaped enough: part of its surface is seen nearly edge-on from every "
                  f"centre tried (cosine {bake.min_cosine:.2f} < {MIN_COSINE:g})")
    else:
        reason = ""
    return StarShape(name, not reason, np.asarray(centre, dtype=np.float64), reason, bake.crossings, hidden,
                     bake.min_cosine)


def check_star_shaped(reflector: Reflector, reflector_set: ReflectorSet | None = None, bake_map=None) -> StarShape:
    """The first candidate centre that passes the coarse checks, or the best one tried
    (fewest crossings and hidden samples, then the largest cosine) with the reason.
    ``bake_map(centre, face_size)``: the coarse maps' bake (default
    ``bake_reflector_map`` on the CPU; the GPU's rasterised twin is faster)."""
    reflector_set = reflector_set or ReflectorSet([reflector])
    if bake_map is None:
        def bake_map(centre, face_size):
            return bake_reflector_map(reflector_set, centre, face_size)
    samples = _surface_samples(reflector)
    best, best_key = None, None
    for centre in centre_candidates(reflector):
        bake = bake_map(centre, CHECK_FACE_SIZE)
        hidden = _hidden_share(reflector_set, centre, samples) if not bake.crossings else 1.0
        shape = verdict(reflector.name, centre, bake, hidden)
        if shape.star_shaped:
            return shape
        key = (bake.crossings, hidden, -bake.min_cosine)
        if best_key is None or key < best_key:
            best, best_key = shape, key
    return best


def prepare_iterative(reflector: Reflector, face_size: int = DEFAULT_FACE_SIZE) -> tuple[StarShape, MapBake | None]:
    """The star-shape verdict and, when star-shaped, the full-resolution map, whose rays
    are checked again (a thin fold the coarse map missed fails here)."""
    reflector_set = ReflectorSet([reflector])
    shape = check_star_shaped(reflector, reflector_set)
    if not shape.star_shaped:
        return shape, None
    bake = bake_reflector_map(reflector_set, shape.centre, face_size)
    shape = verdict(reflector.name, shape.centre, bake, shape.hidden_share)
    return shape, (bake if shape.star_shaped else None)
