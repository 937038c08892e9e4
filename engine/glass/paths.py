# SPDX-License-Identifier: GPL-3.0-or-later
"""Rays followed through a scene's glass, interface after interface.

Every glass object of a scene is traced together through one
:class:`~..geometry.raytrace.ReflectorSet` (the mirrors' surface model: flat
triangles, interpolated normals, two-sided). A ray starts in air; each time it meets a
glass surface it crosses into the other medium and bends (``snell.refract``), or, past
the critical angle, is reflected and stays where it is (total internal reflection). A
closed solid is entered and left, so it refracts twice; an open sheet (a water surface)
is crossed once and the ray goes on in its medium. The media are tracked by which glass
a ray is in, one at a time: a ray meeting one glass while inside another (glass in
glass, or two solids that overlap) crosses from the first's index into the second's and
is marked ``nested``, for the panel to say so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SceneInputError
from ..geometry.raytrace import ReflectorSet
from ..scene import Reflector
from .snell import refract

#: Interfaces a path may cross before it is given up as trapped (total internal
#: reflections bouncing inside a solid count too).
MAX_INTERFACES = 8
#: A new segment starts this share of the glass's size (``ReflectorSet.scale``) along its direction from the
#: interface, so that it does not meet the surface it leaves.
LEAVE_FRACTION = 1e-9


@dataclass(frozen=True)
class Glass:
    """A glass object: its surface, as a mirror's (``scene.Reflector``), its index of
    refraction (vacuum 1; window glass about 1.5, water 1.33), and whether its surface
    also reflects, by the Fresnel reflectance (a Glass BSDF; a Refraction BSDF does not)."""

    surface: Reflector
    ior: float
    reflects: bool = True

    def __post_init__(self):
        ior = float(self.ior)
        if not np.isfinite(ior) or ior <= 0.0:
            raise SceneInputError(self.surface.name, f"has an index of refraction of {self.ior}: it must be above 0")

    @property
    def name(self) -> str:
        return self.surface.name


@dataclass(frozen=True)
class GlassPaths:
    """R rays followed through the glass: where each last segment starts and goes, and
    the path behind it."""

    origin: np.ndarray  # (R, 3) start of the last segment (the eye's origin where no glass was met)
    direction: np.ndarray  # (R, 3) unit direction of the last segment
    medium: np.ndarray  # (R,) glass the last segment runs in, -1 for air
    history: np.ndarray  # (R, MAX_INTERFACES) glass met at each interface, -1 past the last
    total_reflections: np.ndarray  # (R,) interfaces at which the ray was reflected, not refracted
    first_position: np.ndarray  # (R, 3) the first glass point met (NaN where none)
    first_normal: np.ndarray  # (R, 3) its interpolated normal, facing the ray's origin
    first_triangle: np.ndarray  # (R,) its triangle in ``GlassSet.surfaces``, -1 where none
    trapped: np.ndarray  # (R,) still meeting glass after MAX_INTERFACES interfaces
    nested: np.ndarray  # (R,) met one glass while inside another
    #: The last crossing out of glass into air: the glass left (-1: none), where, the
    #: direction the ray came in with and the normal facing it (for the Fresnel
    #: reflectance there, and the ray reflected back inside).
    exit_glass: np.ndarray  # (R,)
    exit_position: np.ndarray  # (R, 3)
    exit_incoming: np.ndarray  # (R, 3)
    exit_normal: np.ndarray  # (R, 3)

    @property
    def interfaces(self) -> np.ndarray:
        """(R,) how many interfaces each ray crossed or was reflected at."""
        return (self.history >= 0).sum(axis=1)

    @property
    def through_glass(self) -> np.ndarray:
        """(R,) rays that met glass and came out of it into a medium they go on in."""
        return (self.first_triangle >= 0) & ~self.trapped


class GlassSet:
    """Every glass object of a scene, traced together."""

    def __init__(self, glasses: list[Glass]):
        if not glasses:
            raise SceneInputError("scene", "has no glass: mark at least one object as a refractor")
        self.glasses = list(glasses)
        self.surfaces = ReflectorSet([glass.surface for glass in self.glasses])
        self.iors = np.array([float(glass.ior) for glass in self.glasses])
        self.reflects = np.array([bool(glass.reflects) for glass in self.glasses])
        self._leave = LEAVE_FRACTION * self.surfaces.scale

    def reflecting(self, glass: np.ndarray) -> np.ndarray:
        """(R,) bool: the glass of each index (-1: none) reflects as well as refracts."""
        glass = np.asarray(glass)
        return (glass >= 0) & self.reflects[np.maximum(glass, 0)]

    def trace(self, origins, directions, max_interfaces: int = MAX_INTERFACES, media=None,
              near_surface=None) -> GlassPaths:
        """Follow rays (``origins``, unit ``directions``) through the glass; ``media``
        (R,): the glass each starts in (-1, the default: air). ``near_surface`` (R, 3),
        NaN where unknown: where each ray likely meets the glass first (a pre-pass's
        depth); the triangles around it are tried first there (``ReflectorSet.intersect``),
        the same hits for fewer BVH descents."""
        origin = np.array(origins, dtype=np.float64, copy=True)
        direction = np.array(directions, dtype=np.float64, copy=True)
        n = len(origin)
        medium = np.full(n, -1, dtype=np.int64) if media is None else np.array(media, dtype=np.int64)
        exit_glass = np.full(n, -1, dtype=np.int64)
        exit_position, exit_incoming, exit_normal = (np.full((n, 3), np.nan) for _ in range(3))
        history = np.full((n, max_interfaces), -1, dtype=np.int64)
        total = np.zeros(n, dtype=np.int64)
        nested = np.zeros(n, dtype=bool)
        first_position = np.full((n, 3), np.nan)
        first_normal = np.full((n, 3), np.nan)
        first_triangle = np.full(n, -1, dtype=np.int64)
        active = np.arange(n)
        near = None if near_surface is None else self.surfaces.triangle_grid.nearby(np.asarray(near_surface))
        for step in range(max_interfaces):
            hits = self.surfaces.intersect(origin[active], direction[active],
                                           near_triangles=near if step == 0 and near is not None else None)
            active, hit = active[hits.hit], np.flatnonzero(hits.hit)
            if len(active) == 0:
                break
            glass = hits.reflector[hit]
            if step == 0:
                first_position[active] = hits.position[hit]
                first_normal[active] = hits.normal[hit]
                first_triangle[active] = hits.triangle[hit]
            inside = medium[active]
            nested[active] |= (inside >= 0) & (inside != glass)
            leaving = inside == glass
            n_from = np.where(inside >= 0, self.iors[np.maximum(inside, 0)], 1.0)
            n_to = np.where(leaving, 1.0, self.iors[glass])
            bent, reflected = refract(direction[active], hits.normal[hit], n_from / n_to)
            history[active, step] = glass
            total[active] += reflected
            out = np.flatnonzero(leaving & ~reflected)
            exit_glass[active[out]] = glass[out]
            exit_position[active[out]] = hits.position[hit[out]]
            exit_incoming[active[out]] = direction[active[out]]
            exit_normal[active[out]] = hits.normal[hit[out]]
            medium[active] = np.where(reflected, inside, np.where(leaving, -1, glass))
            direction[active] = bent
            origin[active] = hits.position[hit] + self._leave * bent
        trapped = np.zeros(n, dtype=bool)
        if len(active):
            trapped[active] = self.surfaces.intersect(origin[active], direction[active]).hit
        return GlassPaths(origin, direction, medium, history, total, first_position, first_normal, first_triangle,
                          trapped, nested, exit_glass, exit_position, exit_incoming, exit_normal)
