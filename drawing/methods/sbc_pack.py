# SPDX-License-Identifier: GPL-3.0-or-later
"""A sample-based camera packed into float textures, for projection in a vertex shader.

SBC paper (Popescu, Sacks, Mei 2006), section V-A: scene points are projected by the
sample-based camera in the vertex shader, so the camera's data (BSP trees, leaf
models, ray map) must live in GPU memory; section VII-B: "the BSP trees are packed and
loaded into texture memory using the vertex texture technique". Storage buffers are
not exposed to Python in Blender, so everything goes into RGBA32F textures read with
``texelFetch``, which works in vertex shaders.

Every array is a list of *records* of a fixed number of texels (RGBA, float32). Record
texel ``k`` sits at texel index ``i`` and texel index ``i`` at (i % W, i // W) of a 2D
texture ``TEXTURE_WIDTH`` (W) texels wide. Integers (children, leaf ids, offsets, ray
indices) are stored as floats, which is exact below 2^24; packing refuses larger ones.

Textures (names as the GLSL samplers, ``sbc_`` + name):

``groups``  4 texels per reflection group (the group's offsets into the shared arrays)
    0: (node offset, leaf offset, camera-patch offset, cell-patch offset)  [records]
    1: (cell-start offset, grid offset, tree depth, number of ray-list leaves) [scalars]
    2: (ray-map columns, rows, down-sampling factor, number of groups)
    3: (lo u, lo v, hi u, hi v) the ray-map cells the sheet owns (``sbc.owned``)
``nodes``   2 texels per BSP node: (plane normal xyz, plane offset), (left, right, leaf, 0);
            children and leaf ids are local to the group's tree, -1 where none.
``leaves``  1 texel per leaf: (kind, row, rays in leaf, fallback); row local to the group
            (camera-leaf patch or ray-list leaf); fallback: a banded camera leaf's ray-list
            row (``BSPTree.leaf_fallback``), else -1.
``patches`` 16 texels per ray patch; the camera-leaf patches of all groups, then the
            bilinear ray-list cell patches of all groups (offsets in ``groups``), then
            the bilinear sub-cell patches of every group's fold cells (engine.sbc_cells.FoldCells,
            FOLD_SAMPLES^2 per fold cell, row-major [b][a], lo/hi in sub-cell units):
    0: (chart origin xyz, 1 if bilinear else 0; -1 for a fold sub-cell whose rays do not
       all hit the group's reflector)
    1..6: (tail coefficient k xyz, cell coefficient k x), k = 1, u, v, u^2, uv, v^2
    7..12: (direction coefficient k xyz, cell coefficient k y)
    13: (lo.x, lo.y, hi.x, hi.y) the member cells' bounds
    14: (cell-centre tail xyz, 0), relative to the origin (bilinear cells only);
        camera leaves: (band lo, band hi, 0, 0), the distances along the ray whose
        answers go to the leaf's ray list (``BSPTree.camera_band``)
    15: (cell-centre unit direction xyz, 0) (bilinear cells only)
``scalars`` 1 float per entry, 4 per texel: each group's ray-list CSR offsets
            ``cell_start``; once per reflection history (its sheets share the block,
            at the header's grid offset): its ray grid (rows x columns, row-major, ray
            index or -1),
            right after it its mixed-cell grid (same layout: the scalar index of the
            cell's sub-ray heads, or -1 where the cell is not mixed; engine.sbc_cells.MixedCells),
            its fold-cell grid (same layout: the patch index of the fold cell's first
            sub-cell, or -1 where the cell is not a fold cell), then the mixed-cell heads, SUBCELL_SAMPLES^2 per mixed cell, row-major [b][a], the head
            distance of the sub-ray, or -1 where it leaves the scene box (unblocked).
``rays``    2 texels per ray of the ray map: (tail xyz, head distance, negative where
            the head is where the ray leaves the scene box rather than on a reflector),
            (unit direction xyz, first-hit depth).

Why relative coordinates: float32 has about 7 digits, and a point's projection is a
Newton solve whose answer is a small correction to a position of the size of the
scene. Tails are therefore stored relative to a chart origin near them: the constant
tail coefficient has the (float32-rounded) origin subtracted in float64 before
rounding, and the shader solves for ``p - origin``. Camera leaves use their chart
origin (the tails' centroid); bilinear cells, which have no chart, use the tail of
their first corner ray. The chart axes and scale are not stored: projection needs only
the coefficients, which are already functions of the chart coordinates.

:func:`pack_sample_based_camera` is plain numpy (testable without a GPU);
:func:`unpack_sample_based_camera` reads the arrays back for tests;
``sbc_gpu.SBCTextures`` uploads them as ``gpu`` textures.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...engine.methods.sbc.bsp import CAMERA_LEAF
from ...engine.methods.sbc.sbc_cells import FOLD_SAMPLES

#: Texels per row of every packed texture; index i lives at (i % W, i // W).
TEXTURE_WIDTH = 4096
GROUP_TEXELS, NODE_TEXELS, LEAF_TEXELS, PATCH_TEXELS, RAY_TEXELS = 4, 2, 1, 16, 2
#: Floats hold integers exactly below this.
EXACT_INTEGER_LIMIT = 1 << 24
#: Largest texture height assumed available (OpenGL 4.5 guarantees at least 16384).
MAX_TEXTURE_HEIGHT = 16384
TEXTURE_NAMES = ("groups", "nodes", "leaves", "patches", "scalars", "rays")


@dataclass(frozen=True)
class PackedSBC:
    """Texel arrays of one sample-based camera, each (n_texels, 4) float32 (``scalars`` (n,))."""

    groups: np.ndarray
    nodes: np.ndarray
    leaves: np.ndarray
    patches: np.ndarray
    scalars: np.ndarray
    rays: np.ndarray
    n_groups: int
    columns: int
    rows: int
    downsample: int

    def texture_arrays(self) -> dict:
        """Each array as a (height, TEXTURE_WIDTH, 4) float32 image, zero-padded (at least one row)."""
        images = {}
        for name in TEXTURE_NAMES:
            texels = getattr(self, name)
            if name == "scalars":
                texels = np.pad(texels, (0, -len(texels) % 4)).reshape(-1, 4)
            height = max(1, -(-len(texels) // TEXTURE_WIDTH))
            if height > MAX_TEXTURE_HEIGHT:
                raise ValueError(f"{name}: {len(texels)} texels need a texture {height} rows high "
                                 f"(at most {MAX_TEXTURE_HEIGHT})")
            image = np.zeros((height * TEXTURE_WIDTH, 4), dtype=np.float32)
            image[:len(texels)] = texels
            images[name] = image.reshape(height, TEXTURE_WIDTH, 4)
        return images

    @property
    def nbytes(self) -> int:
        return int(sum(getattr(self, name).nbytes for name in TEXTURE_NAMES))


def _exact(name: str, values) -> np.ndarray:
    values = np.asarray(values)
    if values.size and np.abs(values).max() >= EXACT_INTEGER_LIMIT:
        raise ValueError(f"{name}: {int(np.abs(values).max())} is too large to store exactly in float32")
    return values.astype(np.float32)


def _pack_patches(patches, bilinear: bool, valid=None, band=None) -> np.ndarray:
    """(n * PATCH_TEXELS, 4) float32 texels of ray patches, tails relative to their origin."""
    n = len(patches.lo)
    tail = patches.tail.astype(np.float64).copy()
    if bilinear:
        origin = tail[:, 0].astype(np.float32)
    else:
        origin = patches.origin.astype(np.float32)
    tail[:, 0] -= origin.astype(np.float64)  # in float64, then rounded: the GPU works near zero
    out = np.zeros((n, PATCH_TEXELS, 4), dtype=np.float64)
    out[:, 0, :3] = origin
    out[:, 0, 3] = 1.0 if bilinear else 0.0
    out[:, 1:7, :3] = tail
    out[:, 1:7, 3] = patches.cell[:, :, 0]
    out[:, 7:13, :3] = patches.direction
    out[:, 7:13, 3] = patches.cell[:, :, 1]
    out[:, 13, :2] = patches.lo
    out[:, 13, 2:] = patches.hi
    if valid is not None:
        out[:, 0, 3] = np.where(valid, 1.0, -1.0)
    if bilinear:
        centre_tail, centre_direction, _, _ = patches.centre_rays  # as sbc._closest_cells uses them
        out[:, 14, :3] = centre_tail - origin.astype(np.float64)
        out[:, 15, :3] = centre_direction
    if band is not None:
        out[:, 14, :2] = band
    return out.reshape(-1, 4).astype(np.float32)


def pack_sample_based_camera(sbc) -> PackedSBC:
    """Pack every reflection group of ``sbc`` (a :class:`engine.methods.sbc.sbc.SampleBasedCamera`).

    Only the ``"ray_patch"`` leaf model is supported (the paper's pinhole leaves are a
    CPU baseline).
    """
    if sbc.model_name != "ray_patch":
        raise ValueError(f"GPU projection supports the 'ray_patch' leaf model only, not {sbc.model_name!r}")
    ray_map = sbc.ray_map
    groups, nodes, leaves, camera_patches, cell_patches, fold_patches, scalars = [], [], [], [], [], [], []
    n_cameras = sum(0 if t.cameras is None else len(t.cameras.lo) for t in sbc.trees)
    cell_base = n_cameras  # cell patches follow all camera patches
    fold_base = cell_base + sum(0 if t.cells is None else len(t.cells.lo) for t in sbc.trees)
    folds = getattr(sbc, "folds", None)
    fold_offsets = {}  # patch index of each distinct FoldCells' first sub-cell (shared by sheets)
    # Scalar offset of each grid's block (its grid, mixed-cell grid and fold-cell grid,
    # then its mixed cells' heads), one per history and surface set: the sheets of a set
    # share them, so a view's scalars grow with its grids, not its sheets (each grid is a
    # whole ray map).
    blocks = {}
    n_fold_patches = 0
    n_scalars = n_cells = 0
    n_nodes = n_leaves = n_camera_rows = 0
    for g, (tree, grid) in enumerate(zip(sbc.trees, sbc.grids)):
        n_raylists = len(tree.cell_start) - 1
        header = np.zeros((GROUP_TEXELS, 4))
        header[0] = (n_nodes, n_leaves, n_camera_rows, cell_base + n_cells)
        header[1] = (n_scalars, -1, tree.depth, n_raylists)  # the block offset is set below
        header[2] = (ray_map.columns, ray_map.rows, ray_map.downsample, len(sbc.trees))
        header[3] = (0, 0, ray_map.columns, ray_map.rows) if sbc.owned is None else sbc.owned[g]
        groups.append(header)

        node = np.zeros((len(tree.leaf), NODE_TEXELS, 4))
        node[:, 0, :3] = tree.plane_normal
        node[:, 0, 3] = tree.plane_offset
        node[:, 1, 0] = tree.left
        node[:, 1, 1] = tree.right
        node[:, 1, 2] = tree.leaf
        nodes.append(node.reshape(-1, 4))
        leaf = np.zeros((len(tree.leaf_kind), 4))
        leaf[:, 0], leaf[:, 1], leaf[:, 2] = tree.leaf_kind, tree.leaf_row, tree.leaf_rays
        leaf[:, 3] = -1 if tree.leaf_fallback is None else tree.leaf_fallback
        leaves.append(leaf)
        n_nodes += len(tree.leaf)
        n_leaves += len(tree.leaf_kind)
        if tree.cameras is not None:
            camera_patches.append(_pack_patches(tree.cameras, bilinear=False, band=tree.camera_band))
            n_camera_rows += len(tree.cameras.lo)
        if tree.cells is not None:
            cell_patches.append(_pack_patches(tree.cells, bilinear=True))
            n_cells += len(tree.cells.lo)
        scalars.append(_exact("cell_start", tree.cell_start))
        n_scalars += n_raylists + 1
        block = id(grid)  # one grid object per history and surface set, shared by its sheets
        if block in blocks:
            header[1, 1] = blocks[block]
            continue
        blocks[block] = header[1, 1] = n_scalars
        scalars.append(_exact("grid", grid.reshape(-1)))
        n_scalars += grid.size
        mixed = None if getattr(sbc, "mixed", None) is None else sbc.mixed[g]
        heads_start = n_scalars + 2 * grid.size  # after the mixed-cell and fold-cell grids
        mixed_grid = np.full(grid.size, -1, dtype=np.int64)
        heads = np.zeros(0)
        if mixed is not None and len(mixed.heads):
            per_cell = mixed.heads[0].size
            index = mixed.index.reshape(-1)
            mixed_grid = np.where(index >= 0, heads_start + index * per_cell, -1)
            heads = np.where(np.isfinite(mixed.heads), mixed.heads, -1.0).reshape(-1)
        scalars.append(_exact("mixed grid", mixed_grid).astype(np.float32))
        fold = None if folds is None else folds[g]
        fold_grid = np.full(grid.size, -1, dtype=np.int64)
        if fold is not None and len(fold.valid):
            if id(fold) not in fold_offsets:
                fold_offsets[id(fold)] = fold_base + n_fold_patches
                fold_patches.append(_pack_patches(fold.patches, bilinear=True, valid=fold.valid))
                n_fold_patches += len(fold.valid)
            index = fold.index.reshape(-1)
            fold_grid = np.where(index >= 0, fold_offsets[id(fold)] + index * FOLD_SAMPLES ** 2, -1)
        scalars.append(_exact("fold grid", fold_grid).astype(np.float32))
        scalars.append(heads.astype(np.float32))
        n_scalars += 2 * grid.size + len(heads)

    def stack(parts):
        return np.concatenate(parts).astype(np.float32) if parts else np.zeros((0, 4), np.float32)

    group_texels = stack(groups)
    node_texels = stack(nodes)
    _exact("offsets", group_texels)
    _exact("tree indices", node_texels[1::2, :3])
    rays = np.zeros((ray_map.n_rays, RAY_TEXELS, 4))
    # The head distance's sign says whether the head is on a reflector (+) or where the
    # ray leaves the scene box (-): only the former limits projection (sbc._project_group).
    rays[:, 0, :3], rays[:, 0, 3] = ray_map.tail, np.where(ray_map.blocked, 1.0, -1.0) * ray_map.head_distance
    rays[:, 1, :3], rays[:, 1, 3] = ray_map.direction, ray_map.first_depth
    _exact("ray count", [ray_map.n_rays])
    _exact("patch count", [n_cameras + n_cells + n_fold_patches])
    all_patches = camera_patches + cell_patches + fold_patches
    return PackedSBC(
        groups=group_texels, nodes=node_texels, leaves=_exact("leaves", stack(leaves)),
        patches=np.concatenate(all_patches) if all_patches else np.zeros((0, 4), np.float32),
        scalars=np.concatenate(scalars) if scalars else np.zeros(0, np.float32),
        rays=rays.reshape(-1, 4).astype(np.float32), n_groups=len(sbc.trees),
        columns=int(ray_map.columns), rows=int(ray_map.rows), downsample=int(ray_map.downsample),
    )


def _unpack_patches(texels: np.ndarray) -> dict:
    patch = texels.astype(np.float64).reshape(-1, PATCH_TEXELS, 4)
    origin = patch[:, 0, :3]
    tail = patch[:, 1:7, :3].copy()
    tail[:, 0] += origin
    return {
        "origin": origin, "bilinear": patch[:, 0, 3] > 0.5, "tail": tail, "direction": patch[:, 7:13, :3],
        "cell": np.stack([patch[:, 1:7, 3], patch[:, 7:13, 3]], axis=2), "lo": patch[:, 13, :2],
        "hi": patch[:, 13, 2:], "valid": patch[:, 0, 3] > -0.5, "centre_tail": patch[:, 14, :3] + origin, "centre_direction": patch[:, 15, :3],
        "band": patch[:, 14, :2],
    }


def unpack_sample_based_camera(packed: PackedSBC) -> tuple[list, dict]:
    """The arrays read back from the texels (the inverse of packing): per group a dict
    (tree, patches, CSR offsets, grid), and a dict of the per-ray arrays.

    Integer arrays come back exactly; float arrays at float32 precision (tails relative
    to their origin, which is added back here).
    """
    out = []
    rays = packed.rays.astype(np.float64).reshape(-1, RAY_TEXELS, 4)
    header = packed.groups.astype(np.int64).reshape(-1, GROUP_TEXELS, 4)
    for g in range(packed.n_groups):
        node_start, leaf_start, camera_start, cell_start = header[g, 0]
        scalar_start, grid_start, depth, n_raylists = header[g, 1]
        owned = header[g, 3]
        node_stop = header[g + 1, 0, 0] if g + 1 < packed.n_groups else len(packed.nodes) // NODE_TEXELS
        leaf_stop = header[g + 1, 0, 1] if g + 1 < packed.n_groups else len(packed.leaves)
        node = packed.nodes.reshape(-1, NODE_TEXELS, 4)[node_start:node_stop].astype(np.float64)
        leaf = packed.leaves[leaf_start:leaf_stop].astype(np.float64)
        kind = leaf[:, 0].astype(np.int8)
        row = leaf[:, 1].astype(np.int64)
        offsets = packed.scalars[scalar_start:scalar_start + n_raylists + 1].astype(np.int64)
        n_cameras = int(row[kind == CAMERA_LEAF].max() + 1) if np.any(kind == CAMERA_LEAF) else 0
        n_cells = int(offsets[-1])
        patches = packed.patches.reshape(-1, PATCH_TEXELS, 4)
        size = packed.rows * packed.columns
        grid = packed.scalars[grid_start:grid_start + size].astype(np.int64)
        mixed_grid = packed.scalars[grid_start + size:grid_start + 2 * size].astype(np.int64)
        fold_grid = packed.scalars[grid_start + 2 * size:grid_start + 3 * size].astype(np.int64)
        out.append({
            "plane_normal": node[:, 0, :3], "plane_offset": node[:, 0, 3],
            "left": node[:, 1, 0].astype(np.int64), "right": node[:, 1, 1].astype(np.int64),
            "leaf": node[:, 1, 2].astype(np.int64), "leaf_kind": kind, "leaf_row": row,
            "leaf_rays": leaf[:, 2].astype(np.int64), "leaf_fallback": leaf[:, 3].astype(np.int64),
            "depth": int(depth), "cell_start": offsets,
            "n_raylists": int(n_raylists),
            "cameras": _unpack_patches(patches[camera_start:camera_start + n_cameras].reshape(-1, 4)),
            "cells": _unpack_patches(patches[cell_start:cell_start + n_cells].reshape(-1, 4)),
            "grid": grid.reshape(packed.rows, packed.columns),
            "mixed_grid": mixed_grid.reshape(packed.rows, packed.columns),
            "fold_grid": fold_grid.reshape(packed.rows, packed.columns), "owned": owned,
        })
    return out, {"tail": rays[:, 0, :3], "head_distance": np.abs(rays[:, 0, 3]), "blocked": rays[:, 0, 3] > 0,
                 "direction": rays[:, 1, :3], "first_depth": rays[:, 1, 3]}
