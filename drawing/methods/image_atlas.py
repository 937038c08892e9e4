# SPDX-License-Identifier: GPL-3.0-or-later
"""Every image texture a ray trace samples, packed into one texture: rows ("shelves") of
images side by side, the tallest first, so that a trace samples any number of them with
one sampler (``glsl/scene_colors.glsl``'s ``scene_image``: each image's rectangle in a
table, its texels wrapped within it, as the CPU's tracer wraps the image itself).

An image that does not fit within :data:`~.sbc_pack.MAX_TEXTURE_HEIGHT` rows gets an
empty rectangle: a ray meeting its mesh is left to another method."""

from __future__ import annotations

import numpy as np

from .sbc_pack import MAX_TEXTURE_HEIGHT

#: Texels a row of the atlas at least (wider where an image is wider): at 16384 rows, 64
#: million texels, sixteen 2048 x 2048 images.
ATLAS_WIDTH = 4096


def shelf_places(sizes) -> tuple[np.ndarray, int, int]:
    """((N, 2) lower left texel of each image of ``sizes`` ((N, 2) width, height) in the
    atlas, -1 for one that does not fit; its width and height in texels). One place per
    image, a few dozen images a scene: a loop over images, not texels."""
    sizes = np.asarray(sizes, dtype=np.int64).reshape(-1, 2)
    width = max([ATLAS_WIDTH] + [int(w) for w, _ in sizes])
    places = np.full((len(sizes), 2), -1, dtype=np.int64)
    x = y = shelf = 0
    for k in np.argsort(-sizes[:, 1], kind="stable"):
        w, h = (int(v) for v in sizes[k])
        if x + w > width:
            x, y, shelf = 0, y + shelf, 0
        if y + h > MAX_TEXTURE_HEIGHT:
            continue
        places[k] = (x, y)
        x, shelf = x + w, max(shelf, h)
    return places, width, max(1, y + shelf)


def fits(sizes) -> bool:
    """Whether every image of ``sizes`` ((N, 2) width, height) has a place in the atlas."""
    return bool((shelf_places(sizes)[0] >= 0).all())


def image_atlas(images) -> tuple[np.ndarray, np.ndarray]:
    """((H, W, 4) float32 atlas, (max(1, N), 4) float32 rectangles: lower left texel,
    width and height, all 0 for an image that does not fit) of ``images`` ((h, w, 4)
    arrays, rows bottom to top, as ``data_texture`` uploads them)."""
    sizes = [(image.shape[1], image.shape[0]) for image in images]
    places, width, height = shelf_places(sizes)
    atlas = np.zeros((height, width, 4), np.float32)
    rects = np.zeros((max(1, len(images)), 4), np.float32)
    for k, (image, (x, y)) in enumerate(zip(images, places)):
        if x < 0:
            continue
        h, w = image.shape[:2]
        atlas[y:y + h, x:x + w] = image
        rects[k] = (x, y, w, h)
    return atlas, rects
