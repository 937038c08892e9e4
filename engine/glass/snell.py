# SPDX-License-Identifier: GPL-3.0-or-later
"""One interface between two media: Snell's law and the dielectric Fresnel equations.

A ray crossing from a medium of index n1 into one of index n2 keeps its tangential
component scaled by eta = n1 / n2 (Snell: n1 sin(theta_i) = n2 sin(theta_t)); where
eta sin(theta_i) > 1 no refracted ray exists and all light is reflected (total internal
reflection). The SBC paper stores refracted rays as it stores reflected ones (section
VII, Fig. 20b); Chen & Arvo extend path perturbation to them (section VI). The share
reflected at the interface is the exact Fresnel reflectance of unpolarised light, or
Schlick's approximation of it (what the mirrors' Fresnel uses, SBC V-D).
"""

from __future__ import annotations

import numpy as np


def refract(directions: np.ndarray, normals: np.ndarray, eta) -> tuple[np.ndarray, np.ndarray]:
    """Refracted unit directions of unit ``directions`` crossing an interface whose unit
    ``normals`` face the side they come from (d . n < 0), with ``eta`` = n1 / n2 (a
    scalar or (R,)). Returns ((R, 3) directions, (R,) bool total internal reflection);
    where it is total, the direction is the mirror reflection (what the light does)."""
    directions = np.asarray(directions, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    eta = np.broadcast_to(np.asarray(eta, dtype=np.float64), directions.shape[:1])
    cos_i = -np.einsum("ij,ij->i", directions, normals)
    sin2_t = eta * eta * np.maximum(0.0, 1.0 - cos_i * cos_i)
    total = sin2_t > 1.0
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    refracted = eta[:, None] * directions + (eta * cos_i - cos_t)[:, None] * normals
    reflected = directions + 2.0 * cos_i[:, None] * normals
    out = np.where(total[:, None], reflected, refracted)
    return out / np.linalg.norm(out, axis=1, keepdims=True), total


def fresnel_dielectric(cos_i, eta) -> np.ndarray:
    """Share of unpolarised light reflected at a dielectric interface, for the cosine
    of the incidence angle and eta = n1 / n2: the mean of the s- and p-polarised
    Fresnel reflectances; 1 under total internal reflection."""
    cos_i = np.clip(np.abs(np.asarray(cos_i, dtype=np.float64)), 0.0, 1.0)
    eta = np.asarray(eta, dtype=np.float64)
    sin2_t = eta * eta * (1.0 - cos_i * cos_i)
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    with np.errstate(divide="ignore", invalid="ignore"):
        r_s = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
        r_p = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    return np.where(sin2_t >= 1.0, 1.0, 0.5 * (r_s * r_s + r_p * r_p))

