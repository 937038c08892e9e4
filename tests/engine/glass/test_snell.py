# SPDX-License-Identifier: GPL-3.0-or-later
"""One interface (engine/glass/snell.py): Snell's law, total internal reflection, Fresnel."""

import numpy as np

from curved_reflections.engine.glass import fresnel_dielectric, refract

UP = np.array([[0.0, 0.0, 1.0]])


def _incoming(degrees):
    """Unit directions going down onto the plane z = 0 at these incidence angles."""
    angle = np.radians(np.atleast_1d(degrees))
    return np.stack([np.sin(angle), np.zeros_like(angle), -np.cos(angle)], axis=1)


def test_refraction_keeps_snells_law_and_bends_toward_the_normal_in_glass():
    degrees = np.array([0.0, 10.0, 30.0, 60.0, 89.0])
    bent, total = refract(_incoming(degrees), np.repeat(UP, 5, axis=0), 1.0 / 1.5)
    assert not total.any()
    assert np.allclose(np.linalg.norm(bent, axis=1), 1.0)
    sin_t = np.linalg.norm(np.cross(bent, UP), axis=1)
    assert np.allclose(1.0 * np.sin(np.radians(degrees)), 1.5 * sin_t, atol=1e-12)
    assert np.allclose(bent[0], (0.0, 0.0, -1.0))  # normal incidence goes straight on
    assert np.all(bent[:, 1] == 0.0) and np.all(bent[:, 2] < 0)  # in the plane of incidence, through


def test_leaving_glass_past_the_critical_angle_is_total_internal_reflection():
    """Inside glass of index 1.5 the critical angle is asin(1 / 1.5) = 41.81 degrees:
    below it the ray leaves, bent away from the normal; above it, it is reflected, and
    Fresnel reflects all of it. Crossing back undoes a refraction."""
    critical = np.degrees(np.arcsin(1.0 / 1.5))
    normals = np.repeat(UP, 2, axis=0)
    bent, total = refract(_incoming([critical - 0.1, critical + 0.1]), normals, 1.5)
    assert list(total) == [False, True]
    assert np.allclose(bent[1], _incoming(critical + 0.1)[0] * (1.0, 1.0, -1.0))
    assert np.allclose(fresnel_dielectric(np.cos(np.radians(critical + 0.1)), 1.5), 1.0)
    there, _ = refract(_incoming(25.0), UP, 1.0 / 1.5)
    back, _ = refract(-there, -UP, 1.5)
    assert np.allclose(back, -_incoming(25.0))


def test_fresnel_reflectance_at_normal_incidence_and_brewsters_angle():
    """((n - 1) / (n + 1))^2 = 0.04 head on for glass from either side; at Brewster's
    angle atan(1.5) the p-polarised part vanishes, so unpolarised reflectance is half the
    s part; at grazing incidence all is reflected."""
    assert np.isclose(fresnel_dielectric(1.0, 1.0 / 1.5), 0.04)
    assert np.isclose(fresnel_dielectric(1.0, 1.5), 0.04)
    brewster = np.arctan(1.5)
    cos_i, cos_t = np.cos(brewster), np.cos(np.arcsin(np.sin(brewster) / 1.5))
    r_s = ((cos_i - 1.5 * cos_t) / (cos_i + 1.5 * cos_t)) ** 2
    assert np.isclose(fresnel_dielectric(cos_i, 1.0 / 1.5), 0.5 * r_s)
    assert np.isclose(fresnel_dielectric(0.0, 1.0 / 1.5), 1.0)
