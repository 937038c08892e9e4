# SPDX-License-Identifier: GPL-3.0-or-later
"""Ray tracing of the thin band along a reflector's visible edge (numpy only).

A sample-based camera projects a point only between four neighbouring rays of its
reflection group (``addon/sbc.py``, after SBC paper section IV: the rays' frustums),
so no reflection can be drawn in the last ray-map cell before the reflector's
silhouette, or before an object in front of it: there the neighbour rays do not exist
(they miss the reflector). That band is up to the down-sampling factor d pixels wide,
and on small images it is a large share of a mirror (the whole rim of a sphere).

The reflected rays of those few pixels are traced instead, as the ray map itself is
traced (``addon/raymap.py``, SBC section III-B), but against the diffuse meshes too:
the view ray's first hit, then reflections off the reflectors up to the highest order
drawn; the colour is the diffuse mesh's interpolated vertex colour where a reflected
ray meets one, and the world's where it leaves the scene (or would need a higher
order). The work is proportional to the perimeter of the footprint, not its area.
"""

from __future__ import annotations

import numpy as np

from .raytrace import ReflectorSet, reflect, reflection_valid
from .scene import Reflector


class BandTracer:
    """Reflectors and diffuse meshes in one BVH (``addon.raytrace.ReflectorSet``).

    The diffuse meshes join the set as pseudo-reflectors (their normals are never
    used: a hit on one ends the path), after the reflectors, so a hit's owner below
    the number of reflectors is a mirror.
    """

    def __init__(self, reflectors, meshes):
        self.n_reflectors = len(reflectors)
        pseudo = [Reflector(f"{m.name} (diffuse)", m.vertices, m.triangles,
                            np.tile([0.0, 0.0, 1.0], (len(m.vertices), 1))) for m in meshes]
        self.everything = ReflectorSet(list(reflectors) + pseudo)
        self.colors = [np.asarray(m.colors, dtype=np.float64) for m in meshes]
        self.offsets = np.cumsum([0] + [len(r.vertices) for r in list(reflectors) + pseudo])
        self.mesh_colors = np.concatenate(self.colors) if self.colors else np.zeros((0, 4))

    def trace(self, view, pixels: np.ndarray, max_order: int, world_color) -> np.ndarray:
        """Linear RGBA (K, 4) seen through pixel centres ``pixels`` (K, 2), mirrors included.

        Paths stop at the first diffuse hit, when they leave the scene (world colour), at
        an invalid reflection (a grazing ray turned into the mirror: world colour), or
        on a reflector after ``max_order`` reflections (world colour, as the drawing
        shows where no reflection group of that order exists).
        """
        pixels = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        out = np.tile(np.asarray(world_color, dtype=np.float64)[:4], (len(pixels), 1))
        if len(pixels) == 0:
            return out
        origins, directions = view.pixel_rays(pixels)
        alive = np.arange(len(pixels))
        hits = self.everything.intersect(origins, directions)
        for order in range(max_order + 1):
            hit = hits.hit
            owner = np.where(hit, hits.reflector, -1)
            diffuse = hit & (owner >= self.n_reflectors)
            if diffuse.any():
                out[alive[diffuse]] = self._color(hits.triangle[diffuse], hits.barycentric[diffuse])
            mirror = hit & (owner >= 0) & (owner < self.n_reflectors)
            if order == max_order:
                break
            valid = mirror & reflection_valid(directions, np.nan_to_num(hits.normal), np.nan_to_num(hits.face_normal))
            keep = np.flatnonzero(valid)
            if len(keep) == 0:
                break
            alive = alive[keep]
            origins = hits.position[keep]
            directions = reflect(directions[keep], hits.normal[keep])
            hits = self.everything.intersect(origins, directions, source_triangles=hits.triangle[keep])
        return out

    def _color(self, triangles: np.ndarray, barycentric: np.ndarray) -> np.ndarray:
        """Barycentric mix of the diffuse triangle's vertex colours."""
        corners = self.everything.triangles[triangles] - self.offsets[self.n_reflectors]
        return np.einsum("ij,ijk->ik", barycentric, self.mesh_colors[corners])


def band_pixels(labels: np.ndarray, drawn: np.ndarray, radius: int, edges_of_drawn: bool = False) -> np.ndarray:
    """(K, 2) integer pixels (x, y) of reflector pixels without a drawn reflection that lie
    within ``radius`` pixels (Chebyshev) of a pixel with another id (or the image edge),
    and with ``edges_of_drawn`` also those within ``radius`` of a drawn reflection.

    ``labels`` (H, W) ids of the pre-pass (0 none or diffuse, reflector index + 1);
    ``drawn`` (H, W) bool where the reflection pass drew.
    """
    ids = np.rint(labels).astype(np.int64)
    height, width = ids.shape
    radius = max(0, int(radius))
    padded = np.pad(ids, radius, constant_values=-1)
    padded_drawn = np.pad(np.asarray(drawn, dtype=bool), radius, constant_values=False)
    near_edge = np.zeros(ids.shape, dtype=bool)
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            window = (slice(radius + dy, radius + dy + height), slice(radius + dx, radius + dx + width))
            near_edge |= padded[window] != ids
            if edges_of_drawn:
                near_edge |= padded_drawn[window]
    rows, columns = np.nonzero((ids > 0) & ~drawn & near_edge)
    return np.stack([columns, rows], axis=1)
