# SPDX-License-Identifier: GPL-3.0-or-later
"""Sample-based camera projection in a vertex shader agrees with the numpy reference.

SBC paper section V-A: scene points are projected by the sample-based camera on the
GPU. ``drawing/glsl/sbc_projection.glsl`` reimplements
:meth:`engine.sbc.SampleBasedCamera.project` in float32 on textures packed by
``drawing/methods/sbc_pack.py``. Each point is drawn as one point primitive into its own
texel of a float target, and the texels are compared with numpy on the same
(float32-rounded) points: the accept/reject decision, the pixel, the leaf kind, the
first-reflector depth and the distance along the reflected ray.

The packing itself is checked without a GPU: unpacked arrays equal the camera's.
"""

import dataclasses
import time

import numpy as np
import pytest

from curved_reflections.engine import Reflector, look_at_view, scene_bounds
from curved_reflections.engine.methods.sbc import build_sample_based_camera
from curved_reflections.engine.geometry.shapes import vase
from curved_reflections.engine.methods.sbc import sbc_cells
from curved_reflections.engine.methods.sbc.bsp import descend_tree
from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.drawing.methods import sbc_pack

#: Share of (group, point) decisions allowed to differ: only points a hair from a
#: decision boundary (split plane, segment end, cell bound, Newton's residual threshold)
#: may fall on the other side in float32.
DECISION_SHARE = 0.001
PIXEL_TOLERANCE = 0.05  # desired-view pixels, largest difference
DEPTH_TOLERANCE = 1e-5  # relative, first-reflector depth
DISTANCE_TOLERANCE = 2e-5  # scene units, distance along the reflected ray


def _sphere():
    reflectors = [icosphere((0.0, 0.0, 0.0), 1.0, 4)]
    view = look_at_view((0.0, -4.0, 1.5), (0.0, 0.0, 0.0), width=320, height=240)
    return reflectors, view


def _vase_and_ball():
    """Two reflectors, two reflection groups; the open vase's inside gives many ray-list leaves."""
    shape = vase(segments=48, rings=32).moved(offset=(0.0, 0.0, -1.0), scale=0.8)
    reflectors = [Reflector("Vase", shape.vertices, shape.triangles, shape.normals),
                  icosphere((0.7, -1.2, -0.2), 0.45, 3, name="Ball")]
    view = look_at_view((0.8, -5.0, 2.2), (0.0, 0.0, -0.1), width=320, height=240)
    return reflectors, view


def _points(reflectors, bounds, rng, n_random=3000, n_near=1000):
    """Random points in the scene box, and points just off each reflector (both sides)."""
    parts = [rng.uniform(bounds[0], bounds[1], (n_random, 3))]
    for reflector in reflectors:
        k = rng.integers(0, len(reflector.vertices), n_near)
        offset = rng.uniform(-0.05, 0.3, (n_near, 1)) * reflector.normals[k]
        parts.append(reflector.vertices[k] + offset)
    return np.concatenate(parts).astype(np.float32)  # what the GPU sees; numpy gets the same values


@pytest.fixture(scope="module", params=["sphere", "vase_and_ball"])
def case(request):
    reflectors, view = {"sphere": _sphere, "vase_and_ball": _vase_and_ball}[request.param]()
    bounds = scene_bounds(reflectors, margin=3.0)
    sbc = build_sample_based_camera(reflectors, view, bounds, downsample=2)
    points = _points(reflectors, bounds, np.random.default_rng(11))
    return request.param, sbc, points


def test_gpu_projection_matches_numpy(gpu_ready, case):
    from curved_reflections.drawing.methods.sbc_gpu import SBCTextures, project_points

    name, sbc, points = case
    textures = SBCTextures(sbc)
    project_points(textures, points[:8])  # builds the shader: not part of the timing
    start = time.perf_counter()
    gpu = project_points(textures, points)
    gpu_seconds = time.perf_counter() - start
    start = time.perf_counter()
    cpu = sbc.project(points.astype(np.float64), polish=False)  # the GLSL twin interpolates only
    cpu_seconds = time.perf_counter() - start
    print(f"\n{name}: {len(points)} points x {len(cpu.groups)} groups, GPU {gpu_seconds:.4f} s, "
          f"numpy {cpu_seconds:.4f} s")

    assert gpu.groups == cpu.groups and len(set(cpu.groups)) == (1 if name == "sphere" else 2)
    differ = gpu.valid != cpu.valid
    assert differ.sum() <= DECISION_SHARE * differ.size, (
        f"{differ.sum()} of {differ.size} decisions differ: points {points[np.nonzero(differ)[1]][:10]}")
    both = gpu.valid & cpu.valid
    assert both.sum() > 0.5 * cpu.valid.sum() > 0

    pixel_error = np.abs(gpu.pixels[both] - cpu.pixels[both]).max()
    assert pixel_error <= PIXEL_TOLERANCE, pixel_error
    np.testing.assert_array_equal(gpu.leaf_kind[both], cpu.leaf_kind[both])
    assert set(np.unique(cpu.leaf_kind[both])) == {1, 2}  # both leaf kinds are exercised
    if name == "vase_and_ball":
        # The vase's banded camera leaves (bsp._depth_bands) hand points to their ray lists.
        handed = np.zeros_like(cpu.valid)
        for g, tree in enumerate(sbc.trees):
            leaf = tree.leaf[descend_tree(tree, points.astype(np.float64))]
            handed[g] = (tree.leaf_fallback[leaf] >= 0) & (cpu.leaf_kind[g] == 2)
        assert (handed & both).sum() >= 20

    # Answers in fold cells (the vase's concave inside) are solved again on traced sub-rays
    # (sbc_cells.FoldCells): the GPU does the same and agrees there too.
    g, k = np.nonzero(cpu.valid)
    cells = np.floor(cpu.pixels[g, k] / sbc.ray_map.downsample - 0.5).astype(np.int64)
    in_fold = np.zeros(cpu.valid.shape, dtype=bool)
    in_fold[g, k] = [sbc.folds[a].index[j, i] >= 0 for a, (i, j) in zip(g, cells)]
    if name == "vase_and_ball":
        assert sbc.stats["n_fold_cells"] > 100 and (in_fold & both).sum() > 100
        assert (gpu.valid != cpu.valid)[in_fold].sum() <= max(2, DECISION_SHARE * in_fold.sum() * 10)
        assert np.abs(gpu.pixels[in_fold & both] - cpu.pixels[in_fold & both]).max() <= PIXEL_TOLERANCE

    # The first reflector point is origin + first_depth * direction of the pixel's view ray.
    origins, directions = sbc.ray_map.view.pixel_rays(cpu.pixels[both])
    first_depth = np.einsum("ij,ij->i", cpu.reflector_points[both] - origins, directions)
    np.testing.assert_allclose(gpu.first_depth[both], first_depth, rtol=DEPTH_TOLERANCE)
    np.testing.assert_allclose(gpu.ray_distance[both], cpu.ray_distance[both], atol=DISTANCE_TOLERANCE)
    assert np.isnan(gpu.pixels[~gpu.valid]).all() and (gpu.leaf_kind[~gpu.valid] == 0).all()


def test_gpu_answers_polished_on_the_cpu_match_numpys_polished_projection(gpu_ready, case):
    """The renderer polishes the GPU's ray-list and fold-cell answers on the true rays
    with ``SampleBasedCamera.polish_answers`` (true_rays.py); that gives numpy's own
    polished projection, to the same tolerances as the unpolished twins."""
    from curved_reflections.drawing.methods.sbc_gpu import SBCTextures, project_points

    name, sbc, points = case
    gpu = project_points(SBCTextures(sbc), points)
    cpu = sbc.project(points.astype(np.float64))
    plain = sbc.project(points.astype(np.float64), polish=False)
    valid = np.zeros_like(gpu.valid)
    pixels = np.full(gpu.pixels.shape, np.nan)
    for g in range(len(gpu.groups)):
        answered = np.flatnonzero(gpu.valid[g])
        polished, _, _, ok = sbc.polish_answers(g, gpu.pixels[g, answered], points[answered], gpu.leaf_kind[g, answered])
        valid[g, answered[ok]] = True
        pixels[g, answered[ok]] = polished[ok]
    differ = valid != cpu.valid
    assert differ.sum() <= DECISION_SHARE * differ.size
    both = valid & cpu.valid
    assert np.abs(pixels[both] - cpu.pixels[both]).max() <= PIXEL_TOLERANCE
    moved = np.linalg.norm(cpu.pixels - plain.pixels, axis=2)[cpu.valid & plain.valid]
    assert (moved > 0.01).sum() > 10  # polishing moved answers: the comparison above is not vacuous
    if name == "vase_and_ball":  # the vase's inside: caustics; some answers are false and go
        assert cpu.valid.sum() < plain.valid.sum()
    else:  # a convex mirror: ray-list answers are only nudged
        assert moved.max() < 1.0


def test_packing_round_trip(case):
    """Unpacked texels give back every array the projection reads (integers exactly)."""
    name, sbc, _ = case
    packed = sbc_pack.pack_sample_based_camera(sbc)
    groups, rays = sbc_pack.unpack_sample_based_camera(packed)
    # The ball hides part of the vase's reflected rays: mixed cells get sub-ray heads.
    assert (sbc.stats["n_mixed_cells"] > 10) == (name == "vase_and_ball")
    assert len(groups) == len(sbc.trees) == packed.n_groups
    assert (packed.columns, packed.rows, packed.downsample) == (sbc.ray_map.columns, sbc.ray_map.rows, 2)

    def close(actual, expected, scale=1.0):
        np.testing.assert_allclose(actual, expected, rtol=1e-6, atol=1e-6 * scale)

    for g, (unpacked, tree, grid, mixed) in enumerate(zip(groups, sbc.trees, sbc.grids, sbc.mixed)):
        for name in ("left", "right", "leaf", "leaf_kind", "leaf_row", "leaf_rays", "leaf_fallback", "cell_start"):
            np.testing.assert_array_equal(unpacked[name], getattr(tree, name), err_msg=name)
        np.testing.assert_array_equal(unpacked["grid"], grid)
        np.testing.assert_array_equal(unpacked["owned"], sbc.owned[g])
        np.testing.assert_array_equal(unpacked["mixed_grid"] >= 0, mixed.index >= 0)
        j, i = np.nonzero(mixed.index >= 0)
        samples = mixed.heads[0].size if len(mixed.heads) else 0
        heads = packed.scalars[unpacked["mixed_grid"][j, i][:, None] + np.arange(samples)].astype(np.float64)
        expected = mixed.heads[mixed.index[j, i]].reshape(len(j), samples)
        close(heads, np.where(np.isfinite(expected), expected, -1.0), 10.0)
        # Fold cells: the grid points at each cell's first sub-cell patch, in [b][a] order.
        fold = sbc.folds[g]
        np.testing.assert_array_equal(unpacked["fold_grid"] >= 0, fold.index >= 0)
        j, i = np.nonzero(fold.index >= 0)
        per_cell = sbc_cells.FOLD_SAMPLES ** 2
        rows = (unpacked["fold_grid"][j, i][:, None] + np.arange(per_cell)).reshape(-1)
        sub = sbc_pack._unpack_patches(packed.patches.reshape(-1, sbc_pack.PATCH_TEXELS, 4)[rows].reshape(-1, 4))
        expected_rows = (fold.index[j, i][:, None] * per_cell + np.arange(per_cell)).reshape(-1)
        np.testing.assert_array_equal(sub["valid"], fold.valid[expected_rows])
        for field in ("tail", "direction", "lo", "hi"):
            close(sub[field], getattr(fold.patches, field)[expected_rows], 200.0)
        assert unpacked["depth"] == tree.depth
        close(unpacked["plane_normal"], tree.plane_normal)
        close(unpacked["plane_offset"], tree.plane_offset, 10.0)
        for key, patches in (("cameras", tree.cameras), ("cells", tree.cells)):
            if patches is None:
                assert len(unpacked[key]["lo"]) == 0
                continue
            got = unpacked[key]
            assert got["bilinear"].all() == patches.bilinear and len(got["lo"]) == len(patches.lo)
            if not patches.bilinear:
                close(got["origin"], patches.origin, 10.0)
            for field in ("tail", "direction", "cell", "lo", "hi"):
                close(got[field], getattr(patches, field), 200.0)
            if key == "cameras":  # bands of depth handed to the leaf's ray list (bsp._depth_bands)
                close(got["band"], tree.camera_band, 10.0)
        if tree.cells is not None:  # the cell-centre rays of sbc._closest_cells
            t, d = tree.cells.tail, tree.cells.direction
            centre = d[:, 0] + 0.5 * (d[:, 1] + d[:, 2]) + 0.25 * d[:, 4]
            close(unpacked["cells"]["centre_tail"], t[:, 0] + 0.5 * (t[:, 1] + t[:, 2]) + 0.25 * t[:, 4], 10.0)
            close(unpacked["cells"]["centre_direction"], centre / np.linalg.norm(centre, axis=1)[:, None])
    ray_map = sbc.ray_map
    for name in ("tail", "direction", "head_distance", "first_depth"):
        close(rays[name], getattr(ray_map, name), 10.0)
    np.testing.assert_array_equal(rays["blocked"], ray_map.blocked)


def test_tails_are_stored_relative_to_their_origin(case):
    """The GPU works near zero: constant tail terms are small offsets from the patch origin."""
    _, sbc, _ = case
    packed = sbc_pack.pack_sample_based_camera(sbc)
    patches = packed.patches.reshape(-1, sbc_pack.PATCH_TEXELS, 4)
    extent = np.ptp(sbc.ray_map.tail, axis=0).max()
    # Camera patches (all trees), then ray-list cells, then fold sub-cells (once per group): a
    # camera patch's constant tail term lies within its chart's extent of its origin; a cell's
    # or sub-cell's origin is its first corner's tail.
    folds = {id(f): f for f in sbc.folds}.values()
    bound = np.concatenate([t.cameras.scale for t in sbc.trees if t.cameras is not None]
                           + [np.full(len(t.cells.lo), 1e-6 * extent) for t in sbc.trees if t.cells is not None]
                           + [np.full(len(f.valid), 1e-6 * extent) for f in folds])
    assert np.all(np.linalg.norm(patches[:, 1, :3], axis=1) <= 2 * bound)
    assert np.abs(patches[:, 0, :3]).max() > 0.1 * extent  # origins themselves are not small


def test_texture_layout_and_limits(case):
    """Texel i of every array sits at (i % W, i // W); scalars four to a texel; bad input refused."""
    _, sbc, _ = case
    packed = sbc_pack.pack_sample_based_camera(sbc)
    images = packed.texture_arrays()
    width = sbc_pack.TEXTURE_WIDTH
    for name in sbc_pack.TEXTURE_NAMES:
        texels = getattr(packed, name)
        if name == "scalars":
            texels = np.pad(texels, (0, -len(texels) % 4)).reshape(-1, 4)
        image = images[name]
        assert image.dtype == np.float32 and image.shape[1:] == (width, 4)
        assert image.shape[0] == max(1, -(-len(texels) // width))
        index = np.unique(np.linspace(0, len(texels) - 1, 50).astype(np.int64))
        np.testing.assert_array_equal(image[index // width, index % width], texels[index])
    with pytest.raises(ValueError, match="ray_patch"):
        sbc_pack.pack_sample_based_camera(dataclasses.replace(sbc, model_name="pinhole"))
    with pytest.raises(ValueError, match="exactly"):
        sbc_pack._exact("grid", [0, 1 << 24])


def _looking_away():
    reflectors = [icosphere((0.0, 0.0, 1.0), 1.0, 3)]
    view = look_at_view((5.0, -4.0, 2.5), (10.0, -8.0, 2.5), width=32, height=24)
    return build_sample_based_camera(reflectors, view, scene_bounds(reflectors, margin=1.0), downsample=2)


def test_no_reflector_in_view_packs_empty_textures():
    sbc = _looking_away()
    packed = sbc_pack.pack_sample_based_camera(sbc)
    assert packed.n_groups == 0
    assert all(image.shape == (1, sbc_pack.TEXTURE_WIDTH, 4) and not image.any()
               for image in packed.texture_arrays().values())
    groups, rays = sbc_pack.unpack_sample_based_camera(packed)
    assert groups == [] and len(rays["tail"]) == 0


def test_no_reflector_in_view_projects_nothing(gpu_ready):
    from curved_reflections.drawing.methods.sbc_gpu import SBCTextures, project_points

    result = project_points(SBCTextures(_looking_away()), np.zeros((5, 3)))
    assert result.groups == [] and result.valid.shape == (0, 5) and result.pixels.shape == (0, 5, 2)
