# SPDX-License-Identifier: GPL-3.0-or-later
"""The reflector map rasterised on the GPU (drawing/methods/iterative_bake.py) against the
CPU ray-cast bake (engine/methods/iterative/reflector_map.py)."""

import numpy as np
import pytest

from curved_reflections.engine.methods.iterative.reflector_map import bake_reflector_map
from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.engine.scene import Reflector
from curved_reflections.engine.geometry.sphere import icosphere

SPHERE_CENTRE = (0.1, -0.2, 0.3)
#: Texels whose hole flag may differ: rays exactly on a silhouette, where the
#: rasteriser's coverage rules and the tracer's tolerance may disagree.
SILHOUETTE_TEXELS = 4


def _sphere():
    return icosphere(SPHERE_CENTRE, 1.0, 3)


def _fine_sphere():
    """20,480 triangles, more than the cube map's texels at face size 48 (the timed bake of this
    sphere at face size 256 is tests/benchmarks/bench_iterative_bake.py)."""
    return icosphere(SPHERE_CENTRE, 1.0, 5)


def _two_spheres():
    """Not star-shaped from inside the first: rays toward the second cross it twice."""
    a = icosphere((0.0, 0.0, 0.0), 1.0, 3)
    b = icosphere((2.4, 0.3, -0.2), 0.8, 2)
    return Reflector("Two spheres", np.concatenate([a.vertices, b.vertices]),
                     np.concatenate([a.triangles, b.triangles + len(a.vertices)]),
                     np.concatenate([a.normals, b.normals]))


def _bowl():
    """An open mirror (the sphere's lower part): holes with silhouettes."""
    sphere = icosphere(SPHERE_CENTRE, 1.0, 3)
    centroids = sphere.vertices[sphere.triangles].mean(axis=1)
    return Reflector("Bowl", sphere.vertices, sphere.triangles[centroids[:, 2] < SPHERE_CENTRE[2] + 0.3],
                     sphere.normals)


def _compare(gpu_bake, cpu_bake):
    g, c = gpu_bake.reflector_map, cpu_bake.reflector_map
    assert g.texels.dtype == np.float32 and g.texels.shape == c.texels.shape
    assert g.face_size == c.face_size and np.array_equal(g.centre, c.centre)
    assert g.convex == c.convex
    g_hit, c_hit = g.texels[..., 0] > 0, c.texels[..., 0] > 0
    assert (g_hit != c_hit).sum() <= SILHOUETTE_TEXELS
    both = g_hit & c_hit
    np.testing.assert_allclose(g.texels[both, 0], c.texels[both, 0], rtol=1e-4)
    np.testing.assert_allclose(g.texels[both, 1:], c.texels[both, 1:], atol=1e-3)
    assert gpu_bake.coverage == pytest.approx(cpu_bake.coverage, abs=0.01)
    assert gpu_bake.min_cosine == pytest.approx(cpu_bake.min_cosine, abs=1e-4)
    assert g.min_radius == pytest.approx(c.min_radius, rel=1e-4)
    assert g.max_radius == pytest.approx(c.max_radius, rel=1e-4)
    return int((g_hit != c_hit).sum())


@pytest.mark.parametrize("make_reflector, centre, face_size, star", [
    (_sphere, SPHERE_CENTRE, 24, True),
    (_sphere, (0.45, 0.1, -0.05), 32, True),
    (_two_spheres, (0.15, 0.1, -0.05), 32, False),
    (_bowl, (0.2, -0.1, 0.35), 32, True),
    (_fine_sphere, (0.3, -0.1, 0.2), 48, True),
], ids=["centred", "off-centre", "two-spheres", "open-bowl", "fine-mesh"])
def test_gpu_bake_matches_the_ray_cast_bake(gpu_ready, make_reflector, centre, face_size, star):
    from curved_reflections.drawing.methods.iterative_bake import bake_reflector_map_gpu

    reflector = make_reflector()
    gpu_bake = bake_reflector_map_gpu(reflector, centre, face_size)
    cpu_bake = bake_reflector_map(ReflectorSet([reflector]), centre, face_size)
    differing = _compare(gpu_bake, cpu_bake)
    print(f"\n{reflector.name} from {centre}, S={face_size}: coverage {gpu_bake.coverage:.4f} (CPU "
          f"{cpu_bake.coverage:.4f}), hole flags differ at {differing} texels, crossings "
          f"{gpu_bake.crossings} (CPU {cpu_bake.crossings}), min cosine {gpu_bake.min_cosine:.6f}")
    if star:
        assert gpu_bake.crossings == 0 and cpu_bake.crossings == 0
    else:
        # The CPU bake counts rays meeting the surface again outside the first hit's
        # one-ring, the GPU texels with any later crossing: only both non-zero is shared.
        assert gpu_bake.crossings > 0 and cpu_bake.crossings > 0


def test_gpu_bake_restores_the_draw_state(gpu_ready):
    from curved_reflections.drawing.methods.iterative_bake import bake_reflector_map_gpu

    gpu = gpu_ready
    before = (gpu.state.depth_test_get(), gpu.state.depth_mask_get(), gpu.state.blend_get())
    bake_reflector_map_gpu(_sphere(), SPHERE_CENTRE, 8)
    assert (gpu.state.depth_test_get(), gpu.state.depth_mask_get(), gpu.state.blend_get()) == before
