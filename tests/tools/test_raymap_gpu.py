# SPDX-License-Identifier: GPL-3.0-or-later
"""The GPU ray map (reflectors rasterised into float targets) agrees with CPU ray tracing.

Both producers share every step after the first hit, so they may differ only where
rasterisation and ray tracing disagree about coverage or visibility: on a thin band of
cells along footprint silhouettes. Elsewhere the rays match to float32 precision
(``refine=False``, the paper's read-back) or to rounding (``refine=True``). The views
include sizes not divisible by the down-sampling factor.
"""

import numpy as np
import pytest

from curved_reflections.engine.methods.sbc.raymap import trace_ray_map
from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.engine.scene import Reflector, scene_bounds
from curved_reflections.engine.geometry.shapes import vase
from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.engine.view import look_at_view

#: Agreement of rays that both producers found, relative to the reflectors' size where
#: they are lengths. Without refinement the GPU's float32 samples sit up to ~1/512 pixel
#: off their rays (sub-pixel vertex snapping), which obliquely seen curved mirrors turn
#: into ~1e-5 of the scene in position and ~2e-4 in direction; refined hits are float64.
TOLERANCES = {
    False: dict(tail=1e-4, direction=1e-3, head=1e-3),
    True: dict(tail=1e-9, direction=1e-9, head=1e-9),
}
#: Largest share of cells (over all histories) that one producer has and the other lacks.
DIFFERING_SHARE = 0.01


def _sphere_scene():
    reflectors = ReflectorSet([icosphere((0.0, 0.0, 0.0), 1.0, 3)])
    view = look_at_view((0.0, -4.0, 1.5), (0.0, 0.0, 0.0), width=320, height=240)
    return reflectors, view, scene_bounds(reflectors.reflectors, margin=3.0)


def _vase_and_sphere_scene():
    """The open Chen-Arvo vase (its inside visible) and a sphere partly in front of it.

    The view size is not divisible by the down-sampling factor, so the GPU target needs
    the cropped projection to sample the same pixel centres as the CPU rays.
    """
    shape = vase(segments=48, rings=32).moved(offset=(0.0, 0.0, -1.0), scale=0.8)
    reflectors = ReflectorSet([
        Reflector("Vase", shape.vertices, shape.triangles, shape.normals),
        icosphere((0.7, -1.2, -0.2), 0.45, 3, name="Ball"),
    ])
    view = look_at_view((0.8, -5.0, 2.2), (0.0, 0.0, -0.1), width=323, height=241)
    return reflectors, view, scene_bounds(reflectors.reflectors, margin=2.0)


def _keys(ray_map, histories):
    """One integer per ray: its cell and its reflection history (numbered in ``histories``)."""
    history_id = np.array([histories[h] for h in ray_map.histories], dtype=np.int64)
    cell = ray_map.cell[:, 1] * ray_map.columns + ray_map.cell[:, 0]
    return cell * len(histories) + history_id[ray_map.group]


def _on_boundary(mask: np.ndarray) -> np.ndarray:
    """Cells whose 3x3 neighbourhood holds both members and non-members of ``mask``."""
    padded = np.pad(mask, 1, mode="edge")
    rows, columns = mask.shape
    windows = [padded[i:i + rows, j:j + columns] for i in range(3) for j in range(3)]
    return np.any(windows, axis=0) & ~np.all(windows, axis=0)


def _compare(cpu, gpu, scale):
    """Agreement figures of two ray maps of the same view; asserts the silhouette band."""
    histories = {h: k for k, h in enumerate(sorted(set(cpu.histories) | set(gpu.histories), key=lambda h: (len(h), h)))}
    cpu_keys, gpu_keys = _keys(cpu, histories), _keys(gpu, histories)
    assert len(np.unique(cpu_keys)) == cpu.n_rays and len(np.unique(gpu_keys)) == gpu.n_rays
    common, in_cpu, in_gpu = np.intersect1d(cpu_keys, gpu_keys, return_indices=True)
    differing = np.setxor1d(cpu_keys, gpu_keys)

    # Every ray one producer lacks lies on the silhouette of its history's footprint.
    n_cells = cpu.columns * cpu.rows
    boundary = np.zeros((len(histories), n_cells), dtype=bool)
    for ray_map, keys in ((cpu, cpu_keys), (gpu, gpu_keys)):
        for h in range(len(histories)):
            footprint = np.zeros(n_cells, dtype=bool)
            footprint[keys[keys % len(histories) == h] // len(histories)] = True
            boundary[h] |= _on_boundary(footprint.reshape(cpu.rows, cpu.columns)).ravel()
    assert boundary[differing % len(histories), differing // len(histories)].all()
    assert len(differing) < DIFFERING_SHARE * n_cells

    tail = np.linalg.norm(cpu.tail[in_cpu] - gpu.tail[in_gpu], axis=1) / scale
    direction = np.linalg.norm(cpu.direction[in_cpu] - gpu.direction[in_gpu], axis=1)
    head = np.abs(cpu.head_distance[in_cpu] - gpu.head_distance[in_gpu]) / scale
    first = np.linalg.norm(cpu.first_point[in_cpu] - gpu.first_point[in_gpu], axis=1) / scale
    np.testing.assert_array_equal(cpu.order[in_cpu], gpu.order[in_gpu])
    return dict(common=len(common), differing=len(differing), cells=n_cells, tail=tail.max(),
                first=first.max(), direction=direction.max(), head=head, head_max=head.max())


def _assert_agree(figures, refine, head_share=1.0):
    tolerance = TOLERANCES[refine]
    assert figures["tail"] < tolerance["tail"] and figures["first"] < tolerance["tail"]
    assert figures["direction"] < tolerance["direction"]
    assert np.mean(figures["head"] < tolerance["head"]) >= head_share


@pytest.mark.parametrize("refine", [False, True])
@pytest.mark.parametrize("downsample", [2, 3])
def test_sphere_gpu_ray_map_matches_cpu(gpu_ready, downsample, refine):
    from curved_reflections.tools.raymap_gpu import gpu_ray_map

    reflectors, view, bounds = _sphere_scene()
    cpu = trace_ray_map(reflectors, view, bounds, downsample)
    gpu = gpu_ray_map(reflectors, view, bounds, downsample, refine=refine)
    assert (gpu.columns, gpu.rows) == (cpu.columns, cpu.rows) == (view.width // downsample, view.height // downsample)
    assert gpu.histories == cpu.histories == [(0,)]
    figures = _compare(cpu, gpu, reflectors.scale)
    assert figures["common"] > 0.2 * figures["cells"]
    _assert_agree(figures, refine)


@pytest.mark.parametrize("refine", [False, True])
def test_two_reflectors_second_order_matches_cpu(gpu_ready, refine):
    from curved_reflections.tools.raymap_gpu import gpu_ray_map

    reflectors, view, bounds = _vase_and_sphere_scene()
    cpu = trace_ray_map(reflectors, view, bounds, 2, max_order=2)
    gpu = gpu_ray_map(reflectors, view, bounds, 2, max_order=2, refine=refine)
    assert (gpu.columns, gpu.rows) == (cpu.columns, cpu.rows) == (161, 120)
    figures = _compare(cpu, gpu, reflectors.scale)
    # Both reflectors seen directly, the vase's inside in itself, and each in the other:
    # the depth test and two-sided surfaces work as in the tracer.
    for history in [(0,), (1,), (0, 0), (0, 1), (1, 0)]:
        assert history in cpu.histories and history in gpu.histories
    assert figures["common"] > 0.1 * figures["cells"]
    # A reflected ray grazing the other reflector may hit it in one map and miss in the other.
    _assert_agree(figures, refine, head_share=0.999 if not refine else 1.0)


def test_target_projection_samples_desired_pixel_centres(gpu_ready):
    """Target pixel k + 0.5 of the cropped projection is desired pixel d (k + 0.5)."""
    from curved_reflections.tools.raymap_gpu import target_projection

    _, view, _ = _vase_and_sphere_scene()
    for d in (1, 2, 3, 4):
        columns, rows = view.width // d, view.height // d
        origins, directions = view.pixel_rays(view.pixel_grid(d))
        clip = np.concatenate([origins + directions, np.ones((len(origins), 1))], axis=1)
        clip = clip @ (target_projection(view, d) @ view.view_matrix).T
        target = (clip[:, :2] / clip[:, 3:] * 0.5 + 0.5) * [columns, rows]
        cells = np.stack(np.meshgrid(np.arange(columns), np.arange(rows)), axis=-1).reshape(-1, 2)
        np.testing.assert_allclose(target, cells + 0.5, atol=1e-9)
