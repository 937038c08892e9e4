# SPDX-License-Identifier: GPL-3.0-or-later
"""Sample-based cameras on refracted rays: where a point appears through glass.

The SBC paper renders refraction through a lens with the machinery of reflection: the
refracted rays are stored in a ray map as reflected ones are, and the cameras built on
them project the scene (section VII, Fig. 20b). Here every down-sampled pixel's eye ray
is followed through the glass (``paths.GlassSet.trace``); a ray that comes out becomes
one ray of the map:

- its *history* is the glass it first enters (one "order": the whole crossing is one
  event of the path), so a glass's images are one group, drawn where the pre-pass sees
  that glass;
- its *surface history* is the whole crossing (the glass met at each interface and the
  total internal reflections): rays that crossed differently are split into their own
  trees, as rays across a mirror's sharp edge are (``sbc_build.surface_sets``);
- its *first point* is where the eye's ray enters the glass, its *tail* where it leaves,
  and its *head* where it leaves the scene box.

``sbc_build.build_from_ray_map`` builds the BSP trees of pinhole leaves on that map, and
the camera projects points as a mirror's does. Nothing is polished on true rays (the
reflection's polish follows reflected paths), and no mixed or fold cells are traced.

Not shipped yet: Render Image ray traces glass per pixel (``blender/glass_layer.py``);
these cameras are measured against the exact solver (``tools/exact_refraction.py``) for
the GPU path that will draw glass live.
"""

from __future__ import annotations

import numpy as np

from ..engine.glass.paths import GlassSet
from ..engine.methods.sbc.raymap import RayMap, assemble_ray_map, box_exit_distance
from ..engine.methods.sbc.sbc import SampleBasedCamera
from ..engine.methods.sbc.sbc_build import build_from_ray_map
from ..engine.view import View


def trace_refraction_map(glass: GlassSet, view: View, bounds, downsample: int = 2) -> RayMap:
    """The ray map of ``view``'s rays refracted through ``glass`` (see the module);
    ``bounds`` (lo, hi) is the scene box where they end."""
    columns, rows = view.width // downsample, view.height // downsample
    cells = np.stack(np.meshgrid(np.arange(columns), np.arange(rows)), axis=-1).reshape(-1, 2)
    origins, directions = view.pixel_rays(view.pixel_grid(downsample))
    paths = glass.trace(origins, directions)
    alive = np.flatnonzero(paths.through_glass)
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    vertices = glass.surfaces.vertices
    lo, hi = np.minimum(lo, vertices.min(axis=0)), np.maximum(hi, vertices.max(axis=0))
    tail, outgoing = paths.origin[alive], paths.direction[alive]
    first_point = paths.first_position[alive]
    crossing = np.concatenate([paths.history[alive], paths.total_reflections[alive, None]], axis=1)
    _, surface = np.unique(crossing, axis=0, return_inverse=True)
    rays = (alive, 1, paths.history[alive, :1], first_point, np.linalg.norm(first_point - origins[alive], axis=1),
            tail, outgoing, box_exit_distance(tail, outgoing, lo, hi), paths.first_triangle[alive],
            np.zeros(len(alive), dtype=bool), surface.reshape(-1, 1))
    return assemble_ray_map(view, downsample, columns, rows, cells, [rays])


def build_glass_camera(glass: GlassSet, view: View, bounds, downsample: int = 2,
                       accuracy_px: float = 1.0) -> SampleBasedCamera:
    """The sample-based camera of ``view`` through ``glass``: its groups' histories are
    glass indices (``GlassSet.glasses``)."""
    sbc = build_from_ray_map(trace_refraction_map(glass, view, bounds, int(downsample)), accuracy_px)
    sbc.true_rays = None
    return sbc
