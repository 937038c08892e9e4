# SPDX-License-Identifier: GPL-3.0-or-later
"""What the live view tells the panel about a landed camera (``live.py``): its
statistics, and the reflectors the view does not see."""

from __future__ import annotations



def update_stats(state, sbc, covering: list) -> None:
    """The panel's statistics of ``state`` (a ``live.LiveScene``) after ``sbc`` landed
    (None where grids draw every reflector), with the grids ``covering`` the view."""
    s = {} if sbc is None else sbc.stats
    geometry = state.renderer.geometry
    mesh_bytes = geometry.vertices.nbytes + geometry.colors.nbytes + geometry.triangles.nbytes
    camera_bytes = sum(c.sbc.stats.get("nbytes", 0) for c in state.cameras.values() if c.sbc is not None)
    state.stats.update({
        "rays": int(s.get("n_rays", 0)),
        "leaves": int(s.get("n_leaves", 0)),
        "build_ms": 1000.0 * (s.get("trace_seconds", 0.0) + s.get("build_seconds", 0.0)),
        "memory_mb": (camera_bytes + mesh_bytes) / 2.0 ** 20,
        "views": len(state.cameras),
        "reflected_triangles": int(len(geometry.triangles)),
        "morphing": ", ".join(grid.reflector_name for grid, _ in covering),
    })


def report_visibility(state, view, sbc) -> None:
    """Reflectors ``view`` does not see: a warning when none is seen (nothing to draw).
    A reflector a per-frame pass draws in the view counts as seen (its method decides per
    vertex); the frame's warnings (``FramePipeline.warnings``) come first."""
    names = [r.name for r in state.captured.reflectors]
    seen = {int(history[0]) for history in ([] if sbc is None else sbc.groups)}
    seen |= state.renderer.per_frame_reflectors(view)
    unseen = [name for k, name in enumerate(names) if k not in seen]
    quoted = ", ".join(repr(n) for n in unseen)
    warnings = state.warnings(view)
    if warnings:
        state.report('WARNING', warnings[0])
    elif not seen:
        state.report('WARNING', f"{quoted}: out of view, no reflection to draw (turn the view toward it)")
    elif unseen:
        state.report('INFO', f"{quoted}: out of view; reflections drawn in the others")
    else:
        state.report('INFO', "Reflections up to date")
