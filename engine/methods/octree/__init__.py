# SPDX-License-Identifier: GPL-3.0-or-later
"""Reflection morphing with ray octrees (Martin & Popescu 2004): a ray octree at every
node of a regular grid around the reflector (:mod:`.node`, :mod:`.ray_octree`), the eight
nodes of the eye's cell blended trilinearly (:mod:`.grid`). Baked, cached and drawn on
the GPU like the tetrahedral grid (``engine/methods/morphing/morphing.py``), whose interface it shares."""

from .grid import OctreeGrid, locate_cell, octree_grid_on_demand
from .node import OctreeNode, build_octree_node, octree_node_arrays, octree_node_from_arrays
from .ray_octree import RayOctree, build_ray_octree

__all__ = ["OctreeGrid", "OctreeNode", "RayOctree", "build_octree_node", "build_ray_octree", "locate_cell",
           "octree_grid_on_demand", "octree_node_arrays", "octree_node_from_arrays"]
