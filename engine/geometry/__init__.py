# SPDX-License-Identifier: GPL-3.0-or-later
"""Geometry every method and the reference share: row-wise vectors, segment reductions,
the BVH and ray tracing of reflectors (with the band along their visible edges), the
demo scenes' shapes, geodesic spheres, and the pre-subdivision of diffuse meshes.
Nothing here knows about a projection method."""
