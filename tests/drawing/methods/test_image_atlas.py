# SPDX-License-Identifier: GPL-3.0-or-later
"""The atlas every image texture of a trace is packed into (drawing/methods/image_atlas.py):
each image whole at its rectangle, none overlapping, and those past the rows a texture
may have marked empty. Sampling it on the GPU is tested with the glass trace
(tests/drawing/methods/test_glass_trace.py)."""

import numpy as np

from curved_reflections.drawing.methods import image_atlas


def _images(sizes, seed=3):
    rng = np.random.default_rng(seed)
    return [rng.uniform(0.0, 1.0, (h, w, 4)).astype(np.float32) for w, h in sizes]


def test_every_image_lies_whole_at_its_rectangle_and_none_overlap():
    sizes = [(3, 2), (1, 5), (4000, 7), (300, 300), (2, 2), (4096, 1), (17, 300)]
    images = _images(sizes)
    atlas, rects = image_atlas.image_atlas(images)
    assert atlas.shape[1] == image_atlas.ATLAS_WIDTH and len(rects) == len(images)
    covered = np.zeros(atlas.shape[:2], int)
    for image, (x, y, w, h) in zip(images, rects.astype(int)):
        assert (w, h) == image.shape[1::-1]
        assert (atlas[y:y + h, x:x + w] == image).all()
        covered[y:y + h, x:x + w] += 1
    assert covered.max() == 1
    # Tallest first: the 300-high images share the first shelf, the 1-high one the last.
    assert rects[3, 1] == rects[6, 1] == 0 and rects[5, 1] == atlas.shape[0] - 1


def test_images_past_the_rows_a_texture_may_have_get_empty_rectangles(monkeypatch):
    monkeypatch.setattr(image_atlas, "MAX_TEXTURE_HEIGHT", 10)
    sizes = [(4096, 6), (4096, 6), (8, 3)]  # the second 6-high image would end at row 12
    atlas, rects = image_atlas.image_atlas(_images(sizes))
    assert atlas.shape[0] == 9 and (rects[1] == 0).all() and not image_atlas.fits(sizes)
    assert rects[0].tolist() == [0, 0, 4096, 6] and rects[2].tolist() == [0, 6, 8, 3]
    assert image_atlas.fits(sizes[::2])


def test_an_image_wider_than_the_atlas_widens_it_and_no_image_leaves_one_texel():
    atlas, rects = image_atlas.image_atlas(_images([(5000, 2)]))
    assert atlas.shape == (2, 5000, 4) and rects[0].tolist() == [0, 0, 5000, 2]
    atlas, rects = image_atlas.image_atlas([])
    assert atlas.shape == (1, image_atlas.ATLAS_WIDTH, 4) and rects.shape == (1, 4) and (rects == 0).all()
