# SPDX-License-Identifier: GPL-3.0-or-later
"""One sampling location of reflection morphing with ray octrees (Martin & Popescu 2004,
sections 4.1-4.2): the cube ray map traced from the node and the octree over its rays,
and how a node is stored in the bake cache."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ...errors import SceneInputError
from ..morphing.morph_grid import NODE_INSIDE, NODE_OK, MorphSettings, _face_sees_sphere, cube_face_views
from ..sbc.raymap import trace_ray_map
from ...geometry.raytrace import ReflectorSet
from ..sbc.sbc_build import check_view_outside_reflectors
from .ray_octree import RayOctree, build_ray_octree


@dataclass
class OctreeNode:
    """A node's status and ray octree (None inside the mirror), with its build times."""

    status: int
    octree: RayOctree | None
    seconds: float = 0.0
    cpu_seconds: float = 0.0

    @property
    def nbytes(self) -> int:
        return 0 if self.octree is None else self.octree.nbytes


def build_octree_node(reflector_set: ReflectorSet, eye, bounds, settings: MorphSettings) -> OctreeNode:
    """Trace the cube ray map at ``eye`` (faces that see the mirror only) and build its octree
    over ``bounds`` (the box where reflected rays end) at ``settings.octree_depth``."""
    start, cpu = time.perf_counter(), time.process_time()
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    reach = float(np.linalg.norm(hi - lo))
    views = cube_face_views(eye, settings, near=reach * 1e-4, far=2.0 * reach + 1.0)
    try:
        check_view_outside_reflectors(reflector_set, views[0])
    except SceneInputError:
        return OctreeNode(NODE_INSIDE, None, time.perf_counter() - start, time.process_time() - cpu)
    centre, radius = reflector_set.bounding_sphere
    faces = [(k, trace_ray_map(reflector_set, view, (lo, hi), downsample=1, max_order=1))
             for k, view in enumerate(views) if _face_sees_sphere(view, centre, radius)]
    size = float(np.max(reflector_set.vertices.max(axis=0) - reflector_set.vertices.min(axis=0)))
    octree = build_ray_octree([(k, rm) for k, rm in faces if rm.n_rays], settings.face_resolution, (lo, hi),
                              settings.octree_depth, size)
    return OctreeNode(NODE_OK, octree, time.perf_counter() - start, time.process_time() - cpu)


def octree_node_arrays(node: OctreeNode) -> dict:
    """A node as arrays for the bake cache (``engine/baking/bake_cache.py``)."""
    return {"status": np.array(node.status), "seconds": np.array(node.seconds), **node.octree.to_arrays("octree_")}


def octree_node_from_arrays(data) -> OctreeNode:
    return OctreeNode(int(data["status"]), RayOctree.from_arrays(data, "octree_"), float(data["seconds"]))
