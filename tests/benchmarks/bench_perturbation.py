# SPDX-License-Identifier: GPL-3.0-or-later
"""Perturbation (Chen & Arvo 2000; issue 19) beside Runtime and Iterative, and its
animations against Workbench and Cycles, in one run.

    .venv/bin/python tests/benchmarks/bench_perturbation.py --images docs/images  # docs/benchmarks/perturbation.md
    .venv/bin/python tests/benchmarks/bench_perturbation.py --quick --out /tmp/perturbation.md

**Accuracy and time per view change** (the engine, numpy, one interface): on each
scene and view, the same points projected by Perturbation (``PERTURBATION``), the
sample-based camera (``RUNTIME``: its build and projection, down-sampling 2) and the
iterative search (``ITERATIVE``: its numpy twin, first order on star-shaped mirrors,
cube maps baked beforehand and not timed), against the exact reference: on meshes the
mesh solvers (``engine/reference/exact.py``, ``exact_paths.py``), on declared exact surfaces their
solutions polished onto the surface (``tools/exact_analytic.py``), so that a method is
charged with its own error and not the tessellation's. *Coverage*: the share of the
exact visible reflections answered within 1 px; errors: each answer's distance to the
nearest exact visible reflection of its point (answers farther than 1 px count as
*false*). Perturbation's seeds per view are the grid's and the adaptive ones.
Scenes (none used while the method was written): an exact sphere, an exact
ellipsoid and an exact superquadric (exponent 4; Perturbation uses the declared
surface), the same ellipsoid and superquadric as meshes, a bumpy sphere (amplitude
0.03, lobes 3 and 5: not convex, several images), and two spheres facing each other
at order 2 (exact, and as meshes from another view). The rim band (``rim.py``) was
then found on the bumpy sphere's misses, so a second bumpy sphere (amplitude 0.04,
lobes 4 and 6, other eyes) holds it out; the candidate scan's every seed and wider
spread (``projector.COARSE``, ``candidates.CANDIDATE_SPREAD``) were then found on that
one's misses, so a rippled ellipsoid (amplitude 0.035, lobes 6 and 3, other eyes)
holds those out; the neighbour candidates and the confirming seeds
(``projector.NEIGHBOUR_CELLS``, ``CONFIRM_PX``) were found on the first two bumpy
spheres too, and a second rippled ellipsoid (amplitude 0.045, lobes 5 and 4, other
radii and eyes) was added after them. 640x480, points uniform in a box of 3 radii
around the mirrors, outside them.

**Animation**: the sbc_fig3 demo at 480x320, its ball declared an exact sphere in
Perturbation mode, the camera orbiting it every frame: ``render_image(animation=True)``
against Workbench's ``render.render(animation=True)``, then on sampled frames label
disagreement with Cycles (16 samples) on the mirror's pixels.
"""

from __future__ import annotations

import argparse
import datetime
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import animation_runs  # noqa: E402  (same folder: the animation runs shared with bench_morph_animation.py)
import bench_draw  # noqa: E402  (same folder: machine facts with the GPU)
import bench_sbc  # noqa: E402  (same folder: package import)

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_OUT = REPO_ROOT / "docs" / "benchmarks" / "perturbation.md"
SEED = 20261125
WIDTH, HEIGHT, FOV = 640, 480, 40.0
MIRROR = "MirrorSphere"


def _placed(centre):
    matrix = np.eye(4)
    matrix[:3, 3] = centre
    return matrix


def scenes(subdivisions: int) -> list:
    """(name, reflectors, {index: AnalyticSurface}, eyes, max_order) of every scene."""
    from curved_reflections.engine.methods.perturbation import AnalyticSurface
    from curved_reflections.engine.geometry.sphere import bumpy_icosphere, icosphere
    from curved_reflections.tools.surfaces import ellipsoid, superellipsoid

    centre, radii = np.array([0.1, -0.2, 0.05]), (1.1, 0.75, 0.6)
    eyes = ((3.4, -2.3, 1.3), (-1.5, 3.1, -1.2))
    pair = (np.array([-1.25, 0.0, 0.0]), np.array([1.2, 0.25, 0.15]))
    return [
        ("exact sphere", [icosphere(centre, 1.0, subdivisions, "sphere")],
         {0: AnalyticSurface("sphere", "SPHERE", _placed(centre), (1.0,))}, eyes, 1),
        ("exact ellipsoid", [ellipsoid(centre, radii, subdivisions, "ellipsoid")],
         {0: AnalyticSurface("ellipsoid", "ELLIPSOID", _placed(centre), radii)}, eyes, 1),
        ("ellipsoid mesh", [ellipsoid(centre, radii, subdivisions, "ellipsoid")], {}, eyes, 1),
        ("exact superquadric", [superellipsoid(centre, (1.0, 0.8, 0.65), 4.0, subdivisions + 1, "superellipsoid")],
         {0: AnalyticSurface("superellipsoid", "SUPERQUADRIC", _placed(centre), (1.0, 0.8, 0.65), 4.0)}, eyes, 1),
        ("superellipsoid mesh", [superellipsoid(centre, (1.0, 0.8, 0.65), 4.0, subdivisions + 1, "superellipsoid")],
         {}, eyes, 1),
        ("bumpy sphere mesh", [bumpy_icosphere(centre, 1.0, subdivisions + 1, 0.03, lobes=(3, 5), name="bumpy")],
         {}, eyes, 1),
        ("two exact spheres, order 2", [icosphere(pair[0], 1.0, subdivisions, "A"),
                                        icosphere(pair[1], 0.8, subdivisions, "B")],
         {0: AnalyticSurface("A", "SPHERE", _placed(pair[0]), (1.0,)),
          1: AnalyticSurface("B", "SPHERE", _placed(pair[1]), (0.8,))}, ((0.3, -5.0, 1.2),), 2),
        ("two sphere meshes, order 2", [icosphere(pair[0], 1.0, subdivisions, "A"),
                                        icosphere(pair[1], 0.8, subdivisions, "B")], {}, ((-0.4, -4.8, -0.9),), 2),
        ("bumpy sphere mesh, held out", [bumpy_icosphere(centre, 1.0, subdivisions + 1, 0.04, lobes=(4, 6),
                                                         name="bumpy")], {}, ((2.7, 2.8, -1.5), (-3.3, -1.7, 2.1)), 1),
        ("rippled ellipsoid mesh, held out", [bench_sbc.rippled_ellipsoid((-0.1, 0.15, 0.0), (1.0, 0.85, 0.7), subdivisions + 1,
                                                                0.035)], {}, ((1.9, -3.1, 1.7), (-2.6, 2.2, -1.9)), 1),
        ("rippled ellipsoid mesh, held out 2", [bench_sbc.rippled_ellipsoid((0.05, -0.1, 0.1), (0.8, 1.0, 0.9), subdivisions + 1,
                                                                  0.045, lobes=(5, 4), name="rippled2")], {},
         ((-3.0, -2.4, 0.9), (2.2, 2.9, 1.6)), 1),
    ]


def points_outside(reflector_set, count: int, rng) -> np.ndarray:
    """``count`` points uniform in the box of 3 radii around the mirrors, outside each
    (farther from its centre, along the direction, than its mesh)."""
    from curved_reflections.engine.geometry.raytrace import ReflectorSet

    lo, hi = reflector_set.vertices.min(axis=0), reflector_set.vertices.max(axis=0)
    size = float(np.max(hi - lo))
    candidates = rng.uniform(lo - size, hi + size, (10 * count, 3))
    outside = np.ones(len(candidates), dtype=bool)
    for reflector in reflector_set.reflectors:
        centre = reflector.vertices.mean(axis=0)
        offset = candidates - centre
        distance = np.linalg.norm(offset, axis=1)
        hits = ReflectorSet([reflector]).intersect(np.broadcast_to(centre, offset.shape), offset / distance[:, None])
        outside &= ~hits.hit | (distance > 1.02 * hits.t)
    return candidates[outside][:count]


def exact_reference(reflector_set, view, points, analytic: dict, order: int):
    """(point, pixel, history) of every exact visible reflection of the order."""
    from curved_reflections.engine.reference.exact import solve_reflections
    from curved_reflections.tools.exact_analytic import polish_on_surfaces
    from curved_reflections.tools.exact_paths import solve_second_order

    if order == 1:
        exact = solve_reflections(reflector_set, view, points)
        exact = exact.select(exact.visible)
        positions, histories, pixels = exact.position[:, None], exact.reflector[:, None], exact.pixel
    else:
        exact = solve_second_order(reflector_set, view, points)
        exact = exact.select(exact.visible)
        positions, histories, pixels = np.stack([exact.first, exact.second], axis=1), exact.history, exact.pixel
    if analytic:
        _, pixels, converged = polish_on_surfaces(analytic, view, points[exact.point], positions, histories)
        keep = converged
        return exact.point[keep], pixels[keep], histories[keep]
    return exact.point, pixels, histories


def compare(projection, point, pixel, history) -> dict:
    errors, covered = [], 0
    answers = 0
    for g, h in enumerate(projection.groups):
        rows = history_rows(history, h)
        answered = np.flatnonzero(projection.valid[g])
        answers += len(answered)
        for p in answered:
            wanted = pixel[rows & (point == p)]
            errors.append(np.linalg.norm(wanted - projection.pixels[g, p], axis=1).min() if len(wanted) else np.inf)
    for k in range(len(point)):
        groups = [g for g, h in enumerate(projection.groups) if tuple(h) == tuple(history[k])]
        distance = np.linalg.norm(projection.pixels[groups, point[k]] - pixel[k], axis=1)
        covered += bool(np.isfinite(distance).any() and np.nanmin(distance) <= 1.0)
    errors = np.array(errors)
    close = errors[errors <= 1.0]
    stats = {"coverage": covered / max(len(point), 1), "answers": answers,
             "false": float((errors > 1.0).sum() / max(len(errors), 1))}
    for q in (50, 95, 99):
        stats[f"p{q}"] = float(np.percentile(close, q)) if len(close) else float("nan")
    return stats


def history_rows(history, h) -> np.ndarray:
    return (history == np.array(h)).all(axis=1)


def measure_scene(name, reflectors, analytic, eyes, order, n_points, rng) -> list:
    from curved_reflections.engine.methods.iterative import IterativeReflector, prepare_iterative
    from curved_reflections.engine.methods.perturbation import PerturbationMethod, PerturbationSettings
    from curved_reflections.engine.geometry.raytrace import ReflectorSet
    from curved_reflections.engine.methods.sbc import build_sample_based_camera
    from curved_reflections.engine.scene import scene_bounds
    from curved_reflections.engine.view import look_at_view

    reflector_set = ReflectorSet(reflectors)
    lo, hi = scene_bounds(reflectors, margin=2.0 * reflector_set.scale)
    iterative = None
    if order == 1 and len(reflectors) == 1:
        shape, bake = prepare_iterative(reflectors[0], 256)
        if shape.star_shaped:
            iterative = IterativeReflector(0, reflectors[0].name, bake.reflector_map, accuracy_px=1.0)
    rows = []
    for view_index, eye in enumerate(eyes):
        centre = reflector_set.vertices.mean(axis=0)
        view = look_at_view(eye, centre, fov_y_deg=FOV, width=WIDTH, height=HEIGHT)
        points = points_outside(reflector_set, n_points, rng)
        point, pixel, history = exact_reference(reflector_set, view, points, analytic, order)
        wanted = [tuple(h) for h in np.unique(history, axis=0)]
        method = PerturbationMethod(reflector_set, analytic, PerturbationSettings(accuracy_px=0.5, max_order=order))
        start = time.perf_counter()
        projection = method.project(view, points, histories=wanted)
        seconds = time.perf_counter() - start
        rows.append({"scene": name, "view": view_index + 1, "method": "PERTURBATION", "seconds": seconds,
                     "seeds": method.stats.grid_seeds + method.stats.adaptive_seeds,
                     **compare(projection, point, pixel, history)})
        start = time.perf_counter()
        camera = build_sample_based_camera(reflector_set, view, (lo, hi), max_order=order, downsample=2)
        sbc_projection = camera.project(points)
        seconds = time.perf_counter() - start
        keep = [g for g, h in enumerate(sbc_projection.groups) if tuple(h) in wanted]
        sbc_projection = _subset(sbc_projection, keep)
        rows.append({"scene": name, "view": view_index + 1, "method": "RUNTIME", "seconds": seconds,
                     "seeds": int(camera.ray_map.n_rays), **compare(sbc_projection, point, pixel, history)})
        if iterative is not None:
            start = time.perf_counter()
            searched = iterative.project(view, points)
            rows.append({"scene": name, "view": view_index + 1, "method": "ITERATIVE",
                         "seconds": time.perf_counter() - start, "seeds": 0,
                         **compare(searched, point, pixel, history)})
    return rows


def _subset(projection, groups):
    from curved_reflections.engine.projection import Projection

    return Projection([projection.groups[g] for g in groups], projection.reflector_points[groups],
                      projection.valid[groups], projection.leaf_kind[groups], projection.pixels[groups],
                      projection.ray_distance[groups])


# --- animation ------------------------------------------------------------------------------


def measure_animation(width: int, height: int, frames: int, degrees: float, sampled: int, samples: int,
                      images: Path | None = None) -> dict:
    import bpy

    from curved_reflections.blender import demo_scenes
    from curved_reflections.blender.gpu_init import ensure_gpu
    from curved_reflections.blender.render_image import render_scene

    ensure_gpu()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, width, height)
    scene.curved_reflections.max_order = 1
    mirror = bpy.data.objects[MIRROR]
    mirror.curved_reflections.mode = 'PERTURBATION'
    mirror.curved_reflections.analytic_shape = 'SPHERE'
    centre = np.array(mirror.matrix_world.translation)
    radius = 0.5 * float(max(mirror.dimensions))
    camera = scene.camera
    base = np.array(camera.location) - centre
    camera.constraints.clear()
    camera.constraints.new('TRACK_TO').target = mirror
    scene.frame_start, scene.frame_end = 1, frames
    for frame in range(1, frames + 1):
        angle = np.radians(degrees * (frame - 1))
        camera.location = centre + np.array([np.cos(angle) * base[0] - np.sin(angle) * base[1],
                                             np.sin(angle) * base[0] + np.cos(angle) * base[1], base[2]])
        camera.keyframe_insert("location", frame=frame)
    result = {"width": width, "height": height, "frames": frames, "degrees": degrees, "samples": samples,
              "radius": radius}
    settings = mirror.curved_reflections
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        scene.frame_set(1)
        check = render_scene(scene, bpy.context.evaluated_depsgraph_get())
        assert check.stats["methods"] == {MIRROR: "PERTURBATION"} and "n_rays" not in check.stats, check.stats
        result["ours"], result["workbench"] = animation_runs.time_against_workbench(scene, folder, frames)

        def use(mode, shape):
            def set_up():
                settings.mode, settings.analytic_shape = mode, shape
            return set_up

        result["rows"] = animation_runs.sampled_frames(scene, folder, frames, sampled, samples, [
            ("EXACT", use('PERTURBATION', 'SPHERE'), {}), ("MESH", use('PERTURBATION', 'NONE'), {}),
            ("RUNTIME", use('RUNTIME', 'NONE'), {})])
        settings.mode, settings.analytic_shape = 'PERTURBATION', 'SPHERE'
        if images is not None:
            from curved_reflections.blender.png import write_png
            from curved_reflections.tools import reference_render as rr

            for row in result["rows"]:
                strip = np.concatenate([rr.read_png(folder / f"{name}_{row['frame']}.png")[..., :3]
                                        for name in ("cycles", "EXACT", "MESH", "RUNTIME")], axis=1)
                write_png(Path(images) / f"perturbation_frame_{row['frame']}.png", strip)
    return result


# --- report ---------------------------------------------------------------------------------


def report(rows: list, animation: dict, command: str) -> str:
    lines = [
        "# Perturbation beside Runtime and Iterative; its animations against Workbench and Cycles",
        "",
        f"Generated {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC by `{command}` on "
        f"{bench_draw._machine()}.",
        "",
        f"Accuracy against the exact reference, {WIDTH}x{HEIGHT} (px), and time per view change (s; the engine "
        "in numpy: Perturbation's seeds and steps, Runtime's camera build and projection, Iterative's search "
        "twin). On the exact surfaces the reference is the true surface's reflection.",
        "",
        "| scene | view | method | coverage | false | p50 | p95 | p99 | s / view | rays or seeds |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['view']} | {r['method'].title()} | {100 * r['coverage']:.1f} % | "
                     f"{100 * r['false']:.2f} % | {r['p50']:.3f} | {r['p95']:.3f} | {r['p99']:.3f} | "
                     f"{r['seconds']:.2f} | {r['seeds']:,} |")
    ours = [r for r in rows if r["method"] == "PERTURBATION"]
    runtime = {(r["scene"], r["view"]): r for r in rows if r["method"] == "RUNTIME"}
    exact = [r for r in ours if r["scene"].startswith(("exact", "two exact"))]
    mesh = [r for r in ours if r not in exact]
    faster = sum(r["seconds"] <= runtime[(r["scene"], r["view"])]["seconds"] for r in ours)
    lines += [
        "",
        f"Perturbation: p99 <= {max(r['p99'] for r in exact):.2f} px on exact surfaces (target 0.5), "
        f"<= {max(r['p99'] for r in mesh):.2f} px on meshes (target 1); coverage "
        f"{100 * min(r['coverage'] for r in ours):.1f}-{100 * max(r['coverage'] for r in ours):.1f} % (target 99 %); "
        f"time per view change at most Runtime's on {faster} of {len(ours)} scene views.",
    ]
    if animation:
        a = animation
        ratio = a["ours"] / a["workbench"]
        lines += [
            "",
            f"## Render Image in Perturbation mode, {a['width']}x{a['height']}",
            "",
            f"sbc_fig3, its ball declared an exact sphere, the camera orbiting it {a['degrees']:g} degrees a frame, "
            f"{a['frames']} frames: `render_image(animation=True)` against Workbench's "
            "`render.render(animation=True)` (seconds per frame, both writing PNGs).",
            "",
            "| ours s/frame | Workbench s/frame | ratio |",
            "|---:|---:|---:|",
            f"| {a['ours']:.3f} | {a['workbench']:.3f} | **{ratio:.2f}x** |",
            "",
            f"Label disagreement with Cycles ({a['samples']} samples) on the mirror's pixels, sampled frames "
            "(single-frame renders, timed):",
            "",
            "| frame | mirror px | exact sphere | s | mesh | s | Runtime | s |",
            "|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for r in a["rows"]:
            lines.append(f"| {r['frame']} | {r['mirror_px']:,} | {100 * r['EXACT']:.1f} % | {r['EXACT_seconds']:.2f} | "
                         f"{100 * r['MESH']:.1f} % | {r['MESH_seconds']:.2f} | {100 * r['RUNTIME']:.1f} % | "
                         f"{r['RUNTIME_seconds']:.2f} |")
        mean = statistics.mean(r["EXACT"] for r in a["rows"])
        lines += ["", f"Perturbation: **{ratio:.2f}x** Workbench's time per frame (target <= 3x), "
                      f"**{100 * mean:.1f} %** label disagreement on the sampled frames (target <= 2 %)."]
    return "\n".join(lines) + "\n"


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="markdown file to write")
    parser.add_argument("--points", type=int, default=2000, help="points per view")
    parser.add_argument("--subdivisions", type=int, default=4, help="geodesic subdivisions of the meshes")
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--orbit-degrees", type=float, default=2.0, help="camera turn per frame")
    parser.add_argument("--sampled", type=int, default=3, help="frames compared with Cycles")
    parser.add_argument("--samples", type=int, default=16, help="Cycles samples")
    parser.add_argument("--no-animation", action="store_true", help="only the accuracy table")
    parser.add_argument("--images", type=Path, default=None,
                        help="folder for the sampled frames side by side (Cycles, exact sphere, mesh, Runtime)")
    parser.add_argument("--quick", action="store_true", help="small: 150 points, subdivisions 3, 3 frames at 160x120")
    args = parser.parse_args(argv)
    args.width, args.height = 480, 320
    if args.quick:
        args.points, args.subdivisions, args.frames, args.sampled, args.samples = 150, 3, 3, 1, 4
        args.width, args.height = 160, 120
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    bench_sbc.import_package()
    command = bench_draw.command_line("bench_perturbation.py", argv)
    rng = np.random.default_rng(SEED)
    rows = []
    for name, reflectors, analytic, eyes, order in scenes(args.subdivisions):
        rows += measure_scene(name, reflectors, analytic, eyes, order, args.points, rng)
        print(name, "done", flush=True)
    animation = None if args.no_animation else measure_animation(args.width, args.height, args.frames,
                                                                 args.orbit_degrees, args.sampled, args.samples,
                                                                 args.images)
    return bench_draw.write_report(args.out, report(rows, animation, command))


if __name__ == "__main__":
    sys.exit(main())
