# SPDX-License-Identifier: GPL-3.0-or-later
"""Image metrics for reflections, measured in labels rather than colours (numpy only).

The demo scenes give every diffuse object, and the world, a flat, distinct emission
colour, so each pixel's colour says *which object* it shows. Two renderers then agree
on a reflector pixel exactly when they show the same object there; the share of
reflector pixels where they do not is a resolution- and shading-independent measure of
how wrong a reflection is, the quantity the papers' difference images (SBC paper,
Fig. 17) show.

Colours: palettes hold *linear* RGB (what the materials store); rendered images are
*display* sRGB in [0, 1] (Blender's "Standard" view transform on an sRGB display, i.e.
what a PNG holds divided by 255; ``engine/srgb.py``). Labels are assigned in display
space, where the palette's colours are spread evenly.

The scripts, tests and benchmarks measure with these; the extension does not, so they are
not shipped.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..engine.srgb import linear_to_srgb

#: Radius of the near-contact region as a share of the image width (see contact_region).
CONTACT_RADIUS_FRACTION = 1.0 / 32.0


def palette_names(palette: Mapping[str, tuple]) -> list[str]:
    """Label k of :func:`label_image` is ``palette_names(palette)[k]``."""
    return list(palette)


def label_image(image, palette: Mapping[str, tuple], max_distance: float | None = None) -> np.ndarray:
    """Label each pixel of a display-sRGB image with its nearest palette colour.

    ``image`` is (H, W, 3 or 4) in [0, 1] (alpha ignored); ``palette`` maps names to
    linear RGB. Returns (H, W) int64 indices into ``palette_names(palette)``. With
    ``max_distance`` (Euclidean, display units), pixels farther than that from every
    palette colour get -1, so a black hole never passes for a dark object.
    """
    pixels = np.asarray(image, dtype=np.float64)[..., :3]
    flat = pixels.reshape(-1, 3)
    colours = linear_to_srgb(np.array([palette[name][:3] for name in palette], dtype=np.float64))
    # |x - p|^2 = |x|^2 - 2 x.p + |p|^2, as one (pixels, colours) matrix product.
    distance2 = (flat**2).sum(1)[:, None] - 2.0 * flat @ colours.T + (colours**2).sum(1)[None, :]
    labels = distance2.argmin(axis=1)
    if max_distance is not None:
        nearest = np.take_along_axis(distance2, labels[:, None], axis=1)[:, 0]
        labels = np.where(nearest <= max_distance**2, labels, -1)
    return labels.reshape(pixels.shape[:2]).astype(np.int64)


def share_differing(test_labels, reference_labels, mask) -> float:
    """Share of ``mask`` pixels where the two label images differ; NaN for an empty mask."""
    mask = np.asarray(mask, dtype=bool)
    count = int(mask.sum())
    if count == 0:
        return float("nan")
    differ = np.asarray(test_labels) != np.asarray(reference_labels)
    return float((differ & mask).sum()) / count


def label_disagreement(test, reference, mask, palette: Mapping[str, tuple],
                       max_distance: float | None = None) -> float:
    """Share of ``mask`` pixels whose labels differ between two display-sRGB images.

    Both images are labelled with :func:`label_image`; 0.07 means 7 % of the masked
    pixels show another object in ``test`` than in ``reference``.
    """
    return share_differing(label_image(test, palette, max_distance),
                           label_image(reference, palette, max_distance), mask)


def dilate_disk(binary, radius_px: float) -> np.ndarray:
    """Binary dilation of a (H, W) image by a disc of ``radius_px`` pixels (Euclidean).

    Each row offset dy of the disc is a horizontal run of half-width
    floor(sqrt(r^2 - dy^2)); runs are evaluated with a cumulative sum, so the cost is
    O(r) whole-image operations.
    """
    binary = np.asarray(binary, dtype=bool)
    height, width = binary.shape
    r = int(np.floor(radius_px))
    summed = np.zeros((height, width + 1), dtype=np.int64)
    np.cumsum(binary, axis=1, out=summed[:, 1:])
    x = np.arange(width)
    out = np.zeros_like(binary)
    for dy in range(-r, r + 1):
        half = int(np.floor(np.sqrt(max(radius_px**2 - dy**2, 0.0))))
        lo, hi = np.clip(x - half, 0, width), np.clip(x + half + 1, 0, width)
        run = (summed[:, hi] - summed[:, lo]) > 0
        if dy >= 0:
            out[dy:] |= run[:height - dy]
        else:
            out[:dy] |= run[-dy:]
    return out


def contact_region(mask, reference_labels, background_labels=(), radius_fraction: float =
                   CONTACT_RADIUS_FRACTION) -> np.ndarray:
    """Reflector pixels near where a real object meets the mirror's silhouette, (H, W) bool.

    Definition: a pixel is *near contact* when it is a reflector pixel (``mask``) and lies
    within ``radius_fraction * width`` pixels (Euclidean) of a non-reflector pixel whose
    reference label is a diffuse object, i.e. not one of ``background_labels`` (the
    world). Those are the places where a real object borders the mirror in the image:
    objects touching or standing close to the mirror, and objects in front of it.

    Why: near such a border the correct reflection meets the object itself, and this is
    where methods that assume distant surroundings fail, tens of pixels off (SBC paper,
    Fig. 3 and §5: "the front columns and the cube are close to the surface of the
    reflector"). Far from the silhouette most mirrors show the distant world, which any
    method gets right, and which would dilute the measure.

    Why 1/32 of the width (10 px at 320, 20 px at 640): several times the 1-5 px accuracy
    the SBC paper reports at 640x480, so a good method's small errors stay a small share
    while a displaced reflection covers much of the region; and a share of the width
    keeps the region the same part of the picture at every resolution.
    """
    mask = np.asarray(mask, dtype=bool)
    labels = np.asarray(reference_labels)
    diffuse = ~mask & ~np.isin(labels, np.asarray(background_labels, dtype=labels.dtype))
    return mask & dilate_disk(diffuse, radius_fraction * mask.shape[1])
