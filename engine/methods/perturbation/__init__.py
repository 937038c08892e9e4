# SPDX-License-Identifier: GPL-3.0-or-later
"""Perturbation of traced reflection paths (Chen & Arvo 2000), numpy side.

Per view, a sparse grid of exact reflection paths is traced from the eye
(:mod:`.seeds`); every diffuse vertex then finds its reflection by a second-order
Taylor step from the nearest path (:mod:`.taylor_step`), with the path Jacobian and
Hessian of the implicit-function theorem (:mod:`.path_derivatives`), more paths being
traced where the step's error bound asks for them (:mod:`.projector`). Each bounce is a
quadric: a reflector declared an exact sphere or ellipsoid uses its true surface, a mesh
its osculating quadric at the path's point (:mod:`.quadrics`).
"""

from .path_derivatives import Paths, newton, perturb
from .projector import PerturbationMethod, PerturbationReflector, PerturbationSettings, PerturbationStats
from .quadrics import ELLIPSOID, SHAPES, SPHERE, SUPERQUADRIC, AnalyticSurface, osculating_quadrics
from .seeds import SeedPaths, trace_seed_paths

__all__ = ["AnalyticSurface", "ELLIPSOID", "Paths", "PerturbationMethod", "PerturbationReflector",
           "PerturbationSettings", "PerturbationStats", "SHAPES", "SPHERE", "SUPERQUADRIC", "SeedPaths", "newton",
           "osculating_quadrics", "perturb", "trace_seed_paths"]
