# SPDX-License-Identifier: GPL-3.0-or-later
"""The sRGB transfer function and its inverse (engine/srgb.py)."""

import numpy as np
import pytest

from curved_reflections.engine.srgb import linear_to_srgb, srgb_to_linear


def test_srgb_round_trip_and_known_values():
    x = np.linspace(0.0, 1.0, 101)
    assert np.allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-12)
    assert linear_to_srgb(0.2140) == pytest.approx(0.5, abs=1e-4)
    assert srgb_to_linear(0.5) == pytest.approx(0.21404, abs=1e-5)
