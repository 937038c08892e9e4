# SPDX-License-Identifier: GPL-3.0-or-later
"""What the animation benchmarks share: Render Image's animation timed against
Workbench's on the same frames, and sampled frames against Cycles.

Used by bench_morph_animation.py (Morphing and Octree mode), bench_perturbation.py
(Perturbation mode) and bench_methods.py (every mode); each sets its scene up, the camera
path often with :func:`orbit` (a view without a camera: :func:`turned_view`), then calls
these.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np


def turned_view(view, degrees: float):
    """``view`` (``engine.view.View``) turned by ``degrees`` about the world's vertical
    axis through the origin: the live view's orbit without a camera."""
    from curved_reflections.engine.view import View

    angle = np.radians(degrees)
    rotation = np.eye(4)
    rotation[:2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
    return View(np.asarray(view.view_matrix) @ rotation, view.projection_matrix, view.width, view.height)


def orbit_views(view, degrees: float, frames: int) -> list:
    """``frames`` views, each turned ``degrees`` further (:func:`turned_view`)."""
    return [turned_view(view, degrees * k) for k in range(frames)]


def orbit(scene, target, frames: int, degrees: float, radius: float | None = None) -> None:
    """The scene camera on a circle of 2.3 radii of ``target`` (an object) around it,
    0.7 radii up, turning ``degrees`` a frame and tracking it, with a 70-degree lens
    (near the mirror, its surroundings stay in view), keyframed over ``frames``.
    ``radius``: default half the target's largest dimension (give it for an empty
    standing for several mirrors)."""
    centre = np.array(target.matrix_world.translation)
    radius = 0.5 * float(max(target.dimensions)) if radius is None else float(radius)
    camera = scene.camera
    camera.data.angle = np.radians(70.0)
    camera.constraints.clear()
    track = camera.constraints.new('TRACK_TO')
    track.target = target
    scene.frame_start, scene.frame_end = 1, frames
    for frame in range(1, frames + 1):
        angle = np.radians(-100.0 + degrees * (frame - 1))
        camera.location = centre + radius * np.array([2.3 * np.cos(angle), 2.3 * np.sin(angle), 0.7])
        camera.keyframe_insert("location", frame=frame)


def time_against_workbench(scene, folder: Path, frames: int) -> tuple[float, float]:
    """Seconds per frame of ``render_image(animation=True)`` and of Workbench's
    ``render.render(animation=True)`` over the scene's frames, both writing PNGs."""
    import bpy

    start = time.perf_counter()
    assert bpy.ops.curved_reflections.render_image(filepath=str(folder / "ours_###"), animation=True) == {
        'FINISHED'}
    ours = (time.perf_counter() - start) / frames
    return ours, workbench_seconds(scene, folder, frames)


def workbench_seconds(scene, folder: Path, frames: int) -> float:
    """Seconds per frame of Workbench's ``render.render(animation=True)`` over the
    scene's frames (PNGs written to ``folder``), the scene's own Workbench settings."""
    import bpy

    engine = scene.render.engine
    scene.render.engine = 'BLENDER_WORKBENCH'
    scene.render.filepath = str(folder / "workbench_")
    start = time.perf_counter()
    bpy.ops.render.render(animation=True)
    workbench = (time.perf_counter() - start) / frames
    scene.render.engine = engine
    return workbench


def sampled_frames(scene, folder: Path, frames: int, sampled: int, samples: int, variants) -> list:
    """On ``sampled`` frames spread over the animation: the mirrors' mask, Cycles
    (``samples``) and every variant, as one row per frame with ``mirror_px`` and, per
    variant name, its label disagreement with Cycles on the mask and ``<name>_seconds``.
    ``variants``: (name, set_up, render keyword arguments); ``set_up()`` prepares the
    scene for the variant (modes, settings) before its single-frame render."""
    import bpy

    from curved_reflections.blender import demo_scenes
    from curved_reflections.blender.png import write_png
    from curved_reflections.tools import metrics, reference_render as rr
    from curved_reflections.blender.render_image import render_scene

    palette = demo_scenes.palette(scene)
    reflectors = demo_scenes.reflectors(scene)
    rows = []
    for frame in np.linspace(1, frames, sampled).round().astype(int):
        scene.frame_set(int(frame))
        depsgraph = bpy.context.evaluated_depsgraph_get()
        mask, _ = rr.render_mask(scene, folder / f"mask_{frame}.png", reflectors)
        cycles = rr.render_cycles(scene, folder / f"cycles_{frame}.png", samples=samples)
        row = {"frame": int(frame), "mirror_px": int(mask.sum())}
        for name, set_up, options in variants:
            set_up()
            start = time.perf_counter()
            ours = render_scene(scene, depsgraph, **options)
            row[f"{name}_seconds"] = time.perf_counter() - start
            path = write_png(folder / f"{name}_{frame}.png", ours.display)
            row[name] = metrics.label_disagreement(rr.read_png(path), cycles.image, mask, palette)
            row[f"{name}_methods"] = ours.stats["methods"]
        rows.append(row)
    return rows
