# SPDX-License-Identifier: GPL-3.0-or-later
"""bench_view_change.py's rows for mirrors that are not star-shaped (issue 44): how long
after a view change the live view shows the new view's reflection, against a Workbench
frame of the same scene.

A torus and a subdivided monkey head (``bench_real_mirrors.build``: the bumpy-ball demo's
stage, every setting at its default, the mirror in Auto mode) in the live view of the
scene camera, started and drawn once (shaders built). Then the view turns about the
vertical axis, by ``--orbit-degrees`` a step and by a 35 degree jump; per new view, what
the viewport does after the change (``live.process``, as its timer does, then
``live.draw``), timed to the GPU's finish. The drawn image is compared with the same
view's once it has rested (``bench_real_mirrors.live_rested``: every check and trace
the live view runs at rest landed): the share of the mirror's pixels (those the overlay
draws) whose colour differs by more than 0.05 says whether the first frame after the
change already showed the new view's reflection. A Workbench frame: ``render.render`` of
the same scene and size.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import animation_runs
import bench_draw
import bench_real_mirrors

#: The mirrors measured (``bench_real_mirrors.MIRRORS``).
SHAPES = ("torus", "monkey")
#: Issue 44's bar: the new view's reflection within this many Workbench frames.
TARGET_FRAMES = 3.0
#: A jump of the view, degrees (an orbit step is the command's ``--orbit-degrees``).
JUMP_DEGREES = 35.0
#: A pixel whose colour differs from the rested view's by more than this is stale.
STALE_COLOUR = 0.05


def orbit_views(view, degrees: float, frames: int) -> list:
    """``frames`` views turning about the world's vertical axis through the origin."""
    from curved_reflections.engine.view import View

    views = []
    for k in range(frames):
        angle = np.radians(degrees * k)
        rotation = np.eye(4)
        rotation[:2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
        views.append(View(np.asarray(view.view_matrix) @ rotation, view.projection_matrix, view.width,
                          view.height))
    return views


def measure_shape(kind: str, width: int, height: int, steps: int, orbit_degrees: float) -> dict:
    """One mirror's view changes (see the module docstring)."""
    import bpy
    import gpu

    from curved_reflections.blender import live, method_plan
    from curved_reflections.blender.capture import view_from_camera

    scene, _ = bench_real_mirrors.build(kind, width, height)
    scene.frame_start = scene.frame_end = 1  # one Workbench frame
    with tempfile.TemporaryDirectory() as folder:
        workbench = animation_runs.workbench_seconds(scene, Path(folder), 1)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    base = view_from_camera(scene.camera, scene, depsgraph)
    live.start(scene, depsgraph, {live.CAMERA_KEY: base}, wait=True)
    turns = [orbit_degrees * k for k in range(1, steps + 1)] + [orbit_degrees * steps + JUMP_DEGREES]
    rows = []
    bench_real_mirrors.live_overlay(scene, base)  # shaders built, the view drawn once
    offscreen = gpu.types.GPUOffScreen(width, height, format='RGBA32F')
    try:
        for degrees in turns:
            view = orbit_views(base, degrees, 2)[1]
            with offscreen.bind():
                framebuffer = gpu.state.active_framebuffer_get()
                framebuffer.clear(color=(0.0, 0.0, 0.0, 1.0), depth=1.0)
                start = time.perf_counter()
                live.process(scene, bpy.context.evaluated_depsgraph_get())
                live.draw(scene, live.CAMERA_KEY, view)
                framebuffer.read_color(0, 0, 1, 1, 4, 0, 'FLOAT')  # waits for the GPU to finish
                seconds = time.perf_counter() - start
            first = bench_real_mirrors.live_overlay(scene, view)
            rested = bench_real_mirrors.live_rested(scene, view)[0]
            # Drawn over black, the overlay covers the mirror's pixels only.
            mirror_px = (first[..., :3].max(axis=2) > 0.0) | (rested[..., :3].max(axis=2) > 0.0)
            stale = (np.abs(first[..., :3] - rested[..., :3]).max(axis=2) > STALE_COLOUR) & mirror_px
            rows.append({"degrees": degrees, "seconds": seconds, "mirror_px": int(mirror_px.sum()),
                         "stale": float(stale.sum()) / max(int(mirror_px.sum()), 1)})
    finally:
        offscreen.free()
    methods = {c.reflector: c.method for c in method_plan.last_choices(scene)}
    live.clear(scene)
    return {"kind": kind, "width": width, "height": height, "workbench": workbench, "methods": methods,
            "rows": rows, "median": statistics.median(r["seconds"] for r in rows)}


SHAPES_HEADING = "## Mirrors that are not star-shaped (Auto)"


def shapes_report(results: list, command: str) -> list:
    """The section's lines: per mirror, the first frame after each view change."""
    lines = [SHAPES_HEADING, "", f"Generated by `{command}` on {bench_draw._machine()}.", "",
             __doc__.split("\n\n", 1)[1].strip().replace("\n", " "), "",
             f"Issue 44's bar: the new view's reflection within {TARGET_FRAMES:g} Workbench frames' time.", "",
             "| mirror | Auto drew | size | view turned (deg) | mirror px | ms after the change | Workbench ms | "
             "x Workbench | stale px % |", "|---|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        drew = ", ".join(sorted(set(r["methods"].values()))).title()
        for row in r["rows"]:
            lines.append(f"| {r['kind']} | {drew} | {r['width']}x{r['height']} | {row['degrees']:g} | "
                         f"{row['mirror_px']:,} | {1000 * row['seconds']:.0f} | {1000 * r['workbench']:.0f} | "
                         f"**{row['seconds'] / r['workbench']:.2f}x** | {100 * row['stale']:.2f} |")
    lines.append("")
    for r in results:
        worst = max(row["seconds"] for row in r["rows"]) / r["workbench"]
        stale = max(row["stale"] for row in r["rows"])
        met = "met" if worst <= TARGET_FRAMES and stale <= 0.01 else "not met"
        lines.append(f"- {r['kind']}: the first frame after a change, at most {worst:.2f}x a Workbench frame, "
                     f"at most {100 * stale:.2f} % of the mirror's pixels unlike the rested view's: {met}.")
    return lines + [""]
