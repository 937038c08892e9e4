# SPDX-License-Identifier: GPL-3.0-or-later
"""Iterative search for reflection points (Roger & Holzschuch 2006), numpy side.

A *star-shaped* reflector (one point O sees all of its surface, section 3.3.1) is
stored once as a cube map of its radius and normal around O (:mod:`.reflector_map`,
chosen and checked by :mod:`.star`); every diffuse vertex then finds its reflection
point by a secant search on that map (:mod:`.search`), which the GLSL compute shader
``drawing/glsl/iterative_search.glsl`` runs every frame.
"""

from .reflector_map import ReflectorMap, bake_reflector_map
from .search import IterativeReflector, SearchResult, search_reflections
from .star import StarShape, check_star_shaped, prepare_iterative

__all__ = ["IterativeReflector", "ReflectorMap", "SearchResult", "StarShape", "bake_reflector_map",
           "check_star_shaped", "prepare_iterative", "search_reflections"]
