# SPDX-License-Identifier: GPL-3.0-or-later
"""A closed mirror that is not star-shaped, split into pieces seen from inside it
(engine/methods/iterative/pieces.py); their search against the exact solver, with maps
baked as Blender bakes them, is in tests/drawing/methods/test_iterative_draw.py."""

import numpy as np
import pytest

from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.engine.methods.iterative import pieces as pieces_module
from curved_reflections.engine.methods.iterative.pieces import choose_centres, split_into_pieces, uncovered_share
from curved_reflections.engine.methods.iterative.reflector_map import bake_reflector_map
from curved_reflections.engine.methods.iterative.star import MIN_COSINE
from curved_reflections.engine.scene import Reflector
from curved_reflections.tools.surfaces import torus

FACE_SIZE = 32


def _ring(segments=32, rings=16) -> Reflector:
    ring = torus((0.0, 0.0, 0.0), 1.0, 0.35, segments, rings)
    return Reflector("Ring", ring.vertices, ring.triangles, ring.normals)


@pytest.fixture(scope="module")
def ring_pieces():
    reflector = _ring()
    mirror = ReflectorSet([reflector])
    shape, maps = split_into_pieces(reflector, lambda _, centre: bake_reflector_map(mirror, centre, FACE_SIZE))
    return reflector, mirror, shape, maps


def test_a_torus_is_covered_by_a_few_pieces_seen_from_inside(ring_pieces):
    reflector, mirror, shape, maps = ring_pieces
    assert shape.usable, shape.reason
    assert 3 <= len(maps) <= pieces_module.MAX_PIECES
    assert uncovered_share(reflector, maps) <= pieces_module.MAX_UNCOVERED
    # Every centre lies inside the tube (distance from the core circle below the minor radius).
    core = np.hypot(np.hypot(shape.centres[:, 0], shape.centres[:, 1]) - 1.0, shape.centres[:, 2])
    assert (core < 0.35).all(), core
    assert all(rmap.patches is not None and len(rmap.patches) > 0 for rmap in maps)
    # The patches (where the search starts) are what each piece adds to the earlier ones,
    # and together they reach every part of the surface: each triangle's centroid lies in
    # the bounding sphere of a patch, and the later pieces, which add less, have fewer
    # (without that, each of the 8 pieces has all its 96).
    centroids = reflector.vertices[reflector.triangles].mean(axis=1)
    reached = np.zeros(len(centroids), dtype=bool)
    for rmap in maps:
        centres = rmap.centre + rmap.patches[:, 1, :3]
        distance = np.linalg.norm(centroids[:, None] - centres[None], axis=2)
        reached |= (distance <= 1.05 * rmap.patches[None, :, 1, 3]).any(axis=1)
    # (The spheres bound texels PATCH_STRIDE apart: a centroid between two patches may fall
    # just outside both; 98 % are inside one on this coarse map.)
    assert reached.mean() >= 0.97, reached.mean()
    counts = [len(rmap.patches) for rmap in maps]
    assert sum(counts[len(counts) // 2:]) < sum(counts[:len(counts) // 2])


def test_a_pieces_map_holds_the_surface_and_never_spans_two_walls(ring_pieces):
    """Bilinear lookups of a piece's map land on the mirror (its first surface from the
    centre) wherever they are valid: the texels beside a jump to a farther wall, and the
    grazing ones, are holes."""
    reflector, mirror, shape, maps = ring_pieces
    directions = np.random.default_rng(3).normal(size=(4000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    for rmap in maps:
        radius, _, valid = rmap.surface(directions)
        hits = mirror.intersect(np.broadcast_to(rmap.centre, directions.shape), directions)
        assert valid.mean() > 0.2
        # A lookup across a jump would land between two walls, tenths of a unit off; on
        # the wall, the bilinear radius of this coarse mesh is off by about 0.01 at most.
        error = np.abs(radius[valid] - hits.t[valid])
        assert error.max() <= 0.02, error.max()
        cosine = np.abs(np.einsum("ij,ij->i", hits.face_normal[valid], directions[valid]))
        # Every texel a lookup reads meets the wall at MIN_COSINE at least; between them a little less.
        assert cosine.min() >= 0.8 * MIN_COSINE


def test_an_open_mirror_is_not_split():
    ring = _ring(24, 12)
    open_ring = Reflector("Open", ring.vertices, ring.triangles[12:], ring.normals)
    shape = choose_centres(open_ring)
    assert not shape.usable
    assert "'Open'" in shape.reason and "not a closed surface" in shape.reason
