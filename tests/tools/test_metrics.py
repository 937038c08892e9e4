# SPDX-License-Identifier: GPL-3.0-or-later
"""Label metrics on synthetic images whose disagreement is known exactly."""

import math

import numpy as np
import pytest

from curved_reflections.engine.srgb import linear_to_srgb
from curved_reflections.tools import metrics

PALETTE = {
    "world": (0.2140, 0.2140, 1.0),  # display (0.5, 0.5, 1)
    "red": (1.0, 0.0, 0.0),
    "green": (0.0, 1.0, 0.0),
    "cream": (1.0, 1.0, 0.2140),
}


def _image(labels: np.ndarray) -> np.ndarray:
    """Display-sRGB image showing each label's palette colour."""
    colours = linear_to_srgb(np.array(list(PALETTE.values())))
    return colours[labels]


def test_label_image_recovers_labels():
    rng = np.random.default_rng(1)
    labels = rng.integers(0, len(PALETTE), size=(24, 32))
    assert np.array_equal(metrics.label_image(_image(labels), PALETTE), labels)
    assert metrics.palette_names(PALETTE)[labels[0, 0]] in PALETTE


def test_label_image_ignores_alpha_and_marks_unknown_colours():
    image = np.concatenate([_image(np.array([[1, 2]])), np.ones((1, 2, 1))], axis=2)
    image[0, 1, :3] = 0.0  # black: nearest is red (distance 1), yet far from every colour
    assert metrics.label_image(image, PALETTE).tolist() == [[1, 1]]
    assert metrics.label_image(image, PALETTE, max_distance=0.25).tolist() == [[1, -1]]


def test_seven_changed_of_hundred_masked_pixels_is_seven_percent():
    reference = np.zeros((20, 20), dtype=np.int64)
    reference[5:15, 5:15] = 1
    mask = np.zeros((20, 20), dtype=bool)
    mask[5:15, 5:15] = True  # 100 pixels
    test = reference.copy()
    changed = np.argwhere(mask)[[0, 9, 13, 42, 57, 88, 99]]
    test[changed[:, 0], changed[:, 1]] = 2
    test[0:3, 0:3] = 3  # outside the mask: never counted
    assert metrics.share_differing(test, reference, mask) == 0.07
    assert metrics.label_disagreement(_image(test), _image(reference), mask, PALETTE) == 0.07


def test_disagreement_tolerates_render_noise():
    rng = np.random.default_rng(2)
    labels = rng.integers(0, len(PALETTE), size=(30, 40))
    noisy = np.clip(_image(labels) + rng.uniform(-0.12, 0.12, size=(30, 40, 3)), 0, 1)
    mask = np.ones((30, 40), dtype=bool)
    assert metrics.label_disagreement(noisy, _image(labels), mask, PALETTE) == 0.0


def test_empty_mask_gives_nan():
    labels = np.zeros((4, 4), dtype=np.int64)
    assert math.isnan(metrics.share_differing(labels, labels, np.zeros((4, 4), bool)))


def _dilate_brute_force(binary, radius):
    ys, xs = np.nonzero(binary)
    gy, gx = np.mgrid[: binary.shape[0], : binary.shape[1]]
    out = np.zeros(binary.shape, bool)
    for y, x in zip(ys, xs):
        out |= (gy - y) ** 2 + (gx - x) ** 2 <= radius**2
    return out


def test_dilate_disk_single_pixel_is_a_lattice_disc():
    binary = np.zeros((15, 15), dtype=bool)
    binary[7, 7] = True
    assert metrics.dilate_disk(binary, 3.0).sum() == 29  # lattice points with x^2 + y^2 <= 9


@pytest.mark.parametrize("radius", [0.0, 1.0, 2.5, 6.0])
def test_dilate_disk_matches_brute_force(radius):
    rng = np.random.default_rng(3)
    binary = rng.random((25, 31)) < 0.02
    binary[0, 0] = binary[-1, -1] = True  # touches the borders
    assert np.array_equal(metrics.dilate_disk(binary, radius), _dilate_brute_force(binary, radius))


def _disc_next_to_box(height=100, width=160):
    """A mirror disc (mask) with a diffuse box (label 1) to its right, world (0) elsewhere."""
    gy, gx = np.mgrid[:height, :width]
    mask = (gx - 60) ** 2 + (gy - 50) ** 2 <= 25**2
    labels = np.zeros((height, width), dtype=np.int64)
    labels[mask] = 2  # what the mirror shows is irrelevant to the region
    labels[30:70, 86:120] = 1  # box starts 1 px right of the disc's rightmost pixel (x = 85)
    return mask, labels


def test_contact_region_is_the_mirror_near_the_box():
    mask, labels = _disc_next_to_box()
    radius = metrics.CONTACT_RADIUS_FRACTION * mask.shape[1]  # 5 px
    region = metrics.contact_region(mask, labels, background_labels=[0])
    expected = mask & _dilate_brute_force(labels == 1, radius)
    assert np.array_equal(region, expected)
    assert region.sum() > 0
    assert not region[:, :60].any()  # the far side of the disc borders only the world
    assert np.all(np.nonzero(region)[1] >= 85 - radius)


def test_contact_region_ignores_world_and_scales_with_width():
    mask, labels = _disc_next_to_box()
    assert not metrics.contact_region(mask, labels, background_labels=[0, 1]).any()
    narrow = metrics.contact_region(mask, labels, [0], radius_fraction=1 / 160)
    wide = metrics.contact_region(mask, labels, [0], radius_fraction=8 / 160)
    assert narrow.sum() < wide.sum() and not (narrow & ~wide).any()
