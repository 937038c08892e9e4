# SPDX-License-Identifier: GPL-3.0-or-later
"""The GLSL sources of ``drawing/glsl``, read where every pass and method finds them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

GLSL_DIR = Path(__file__).resolve().parent / "glsl"


def glsl_source(name: str, defines: dict | None = None, prelude: str = "") -> str:
    """``glsl/<name>``, behind one ``#define`` line per item of ``defines`` and then
    ``prelude`` (generated functions the file calls)."""
    text = prelude + (GLSL_DIR / name).read_text(encoding="utf-8")
    if not defines:
        return text
    return "\n".join(f"#define {key} {value}" for key, value in defines.items()) + "\n" + text


def normal_equations_glsl(unknowns: int, ridge=None) -> str:
    """GLSL for least squares in ``unknowns`` scalars: ``fit_clear()``, then
    ``fit_add(r0, .., r<n-1>, value)`` per equation (row . c = value), then
    ``fit_solve()``, which leaves c in ``fit_b0`` .. ``fit_b<n-1>``.

    The normal equations (``ridge`` added to them: one value per unknown for their
    diagonal, by default 1e-10 each, as the numpy twin's, or a symmetric matrix, a
    penalty on combinations of unknowns) are solved by Cholesky factorisation, written
    out term by term: llvmpipe keeps the same code written with arrays and loops in
    memory, which makes the morphing blend, one fit per vertex and frame, about twice as
    slow (``glsl/morph_blend.glsl``).
    """
    lower = [(i, j) for i in range(unknowns) for j in range(i + 1)]
    terms = range(unknowns)

    def m(i, j):
        return f"fit_m{i}{j}"

    def b(i):
        return f"fit_b{i}"

    def minus(first, products):
        """``first - a0 * b0 - a1 * b1 ...`` for the (a, b) name pairs ``products``."""
        return " - ".join([first] + [f"{x} * {y}" for x, y in products])

    ridge = np.full(unknowns, 1e-10) if ridge is None else np.asarray(ridge, dtype=np.float64)
    penalty = ridge if ridge.ndim == 2 else np.diag(ridge)
    clear = ([f"  {m(i, j)} = {penalty[i, j]:.9e};" for i, j in lower]
             + [f"  {b(i)} = 0.0;" for i in terms])
    add = [f"  {m(i, j)} += r{i} * r{j};" for i, j in lower] + [f"  {b(i)} += r{i} * value;" for i in terms]
    solve = []
    for j in terms:  # m = L L^T, L over m's lower triangle
        solve.append(f"  {m(j, j)} = sqrt(max({minus(m(j, j), [(m(j, k), m(j, k)) for k in range(j)])}, 1e-30));")
        solve += [f"  {m(i, j)} = ({minus(m(i, j), [(m(i, k), m(j, k)) for k in range(j)])}) / {m(j, j)};"
                  for i in range(j + 1, unknowns)]
    solve += [f"  {b(i)} = ({minus(b(i), [(m(i, k), b(k)) for k in range(i)])}) / {m(i, i)};"
              for i in terms]  # L y = b
    solve += [f"  {b(i)} = ({minus(b(i), [(m(k, i), b(k)) for k in range(i + 1, unknowns)])}) / {m(i, i)};"
              for i in reversed(terms)]  # L^T c = y
    rows = ", ".join(f"float r{i}" for i in terms)
    return "\n".join([f"float {m(i, j)};" for i, j in lower] + [f"float {b(i)};" for i in terms]
                     + ["void fit_clear()", "{"] + clear + ["}", f"void fit_add({rows}, float value)", "{"] + add
                     + ["}", "void fit_solve()", "{"] + solve + ["}", ""])
