# SPDX-License-Identifier: GPL-3.0-or-later
"""GLSL sources (``drawing/shader_sources.py``): the generated least-squares solver,
run here as the statements it writes (GLSL's arithmetic reads as Python's), solves what
numpy solves."""

import math
import re

import numpy as np

from curved_reflections.engine.methods.morphing.morph_surface import sphere_prior
from curved_reflections.drawing.shader_sources import normal_equations_glsl


def _run(source: str, function: str, names: dict) -> None:
    """Executes the body of ``function`` in ``source`` on ``names`` (statements only)."""
    body = re.search(r"void " + function + r"\([^)]*\)\n\{\n(.*?)\n\}", source, re.S).group(1)
    for statement in body.splitlines():
        exec(statement.strip().rstrip(";"), {"sqrt": math.sqrt, "max": max}, names)


def _solved(source: str, rows, values) -> np.ndarray:
    """The generated solver's answer for equations ``rows`` . c = ``values``."""
    names = {}
    _run(source, "fit_clear", names)
    for row, value in zip(rows, values):
        names.update({f"r{i}": float(x) for i, x in enumerate(row)}, value=float(value))
        _run(source, "fit_add", names)
    _run(source, "fit_solve", names)
    return np.array([names[f"fit_b{i}"] for i in range(rows.shape[1])])


def test_generated_normal_equations_solve_least_squares():
    rng = np.random.default_rng(3)
    unknowns = 6
    rows, values = rng.normal(size=(12, unknowns)), rng.normal(size=12)
    source = normal_equations_glsl(unknowns)
    solved = _solved(source, rows, values)
    expected = np.linalg.lstsq(rows, values, rcond=None)[0]
    np.testing.assert_allclose(solved, expected, rtol=1e-7, atol=1e-9)
    assert source.count("fit_m") > unknowns * (unknowns + 1) // 2  # one scalar per entry, no arrays
    assert "[" not in source


def test_generated_normal_equations_add_the_ridge_per_unknown():
    """Nine unknowns, the last three held by a ridge per unknown."""
    rng = np.random.default_rng(4)
    unknowns, ridge = 9, np.array([1e-10] * 6 + [0.5] * 3)
    rows, values = rng.normal(size=(12, unknowns)), rng.normal(size=12)
    source = normal_equations_glsl(unknowns, ridge)
    solved = _solved(source, rows, values)
    expected = np.linalg.solve(rows.T @ rows + np.diag(ridge), rows.T @ values)
    np.testing.assert_allclose(solved, expected, rtol=1e-7, atol=1e-9)
    assert not np.allclose(solved, np.linalg.lstsq(rows, values, rcond=None)[0], atol=1e-3)


def test_generated_normal_equations_add_a_penalty_matrix():
    """A symmetric penalty on combinations of unknowns (the blend's sphere prior,
    morph_surface.FIT_PENALTY) is added to the normal equations whole."""
    rng = np.random.default_rng(6)
    penalty = sphere_prior(0.5)
    rows, values = rng.normal(size=(12, 9)), rng.normal(size=12)
    solved = _solved(normal_equations_glsl(9, penalty), rows, values)
    np.testing.assert_allclose(solved, np.linalg.solve(rows.T @ rows + penalty, rows.T @ values), rtol=1e-7,
                               atol=1e-9)
    diagonal_only = np.linalg.solve(rows.T @ rows + np.diag(np.diag(penalty)), rows.T @ values)
    assert not np.allclose(solved, diagonal_only, atol=1e-3)
