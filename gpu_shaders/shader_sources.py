# SPDX-License-Identifier: GPL-3.0-or-later
"""The GLSL sources of ``gpu_shaders/glsl``, read where every pass and method finds them."""

from __future__ import annotations

from pathlib import Path

GLSL_DIR = Path(__file__).resolve().parent / "glsl"


def glsl_source(name: str, defines: dict | None = None) -> str:
    """``glsl/<name>``, behind one ``#define`` line per item of ``defines``."""
    text = (GLSL_DIR / name).read_text(encoding="utf-8")
    if not defines:
        return text
    return "\n".join(f"#define {key} {value}" for key, value in defines.items()) + "\n" + text
