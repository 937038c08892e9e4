# SPDX-License-Identifier: GPL-3.0-or-later
"""The sRGB transfer function (IEC 61966-2-1) and its inverse, numpy only.

Materials and the world store *linear* RGB; images shown and written are *display* sRGB
in [0, 1] (Blender's "Standard" view transform on an sRGB display, what a PNG holds
divided by 255). Capture linearises sRGB image textures, the demo scenes pick their flat
colours in display space and store them linear, and Render Image turns its linear result
into display values before writing it.
"""

from __future__ import annotations

import numpy as np


def linear_to_srgb(linear) -> np.ndarray:
    """sRGB transfer function (IEC 61966-2-1): linear [0, 1] -> display [0, 1]."""
    c = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1.0 / 2.4) - 0.055)


def srgb_to_linear(srgb) -> np.ndarray:
    """Inverse of :func:`linear_to_srgb`: display [0, 1] -> linear [0, 1]."""
    c = np.clip(np.asarray(srgb, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, np.power((c + 0.055) / 1.055, 2.4))
