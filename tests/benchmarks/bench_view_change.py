# SPDX-License-Identifier: GPL-3.0-or-later
"""Cost of a view change in the live view (issue #5): runtime mode against morphing mode,
measured in one run.

    .venv/bin/python tests/benchmarks/bench_view_change.py          # docs/benchmarks/view_change.md
    .venv/bin/python tests/benchmarks/bench_view_change.py --quick --out /tmp/view_change.md

The sbc_fig3 demo (mirror ball) is built with bpy and captured, and a
``ReflectionRenderer`` made for its meshes, as the live view does. The eye walks a path
inside the ball's morphing grid (default settings, 9x9x5 nodes, 96 px faces; nodes built
on demand before the clock runs, their build reported apart): small steps, so that
several views share a tetrahedron, and jumps into others. Per view, what the live view
does after the view changed (``operators/live.py``):

- **runtime** (SBC paper IV-V): build the view's sample-based camera (ray map and trees),
  then the renderer's projection with it (textures uploaded, every vertex projected on
  the GPU and read back, reflected triangles decided);
- **morphing** (SBC paper VI, ``gpu_shaders/morph_source.py``): the renderer's projection
  from the grid: in a tetrahedron the eye has just entered, the four nodes project the
  vertices (on the GPU, ``GPUFaceImages``; also timed with numpy) and the images are
  matched and blended; in the same tetrahedron as before, only the blend.

Medians over the path's views. On this project's machines the GPU is Mesa llvmpipe
(the CPU): compare the ratios measured in this one run, not absolute times.
"""

from __future__ import annotations

import argparse
import datetime
import shlex
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_draw  # noqa: E402  (same folder: machine facts with the GPU)
import bench_sbc  # noqa: E402  (same folder: package import)

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_OUT = REPO_ROOT / "docs" / "benchmarks" / "view_change.md"


def eye_path(centre: np.ndarray, radius: float, steps: int, jumps: int) -> list:
    """Eyes at 2.3 radii from the ball: ``jumps`` arcs apart, ``steps`` views 0.4 degree apart on each."""
    eyes = []
    for jump in range(jumps):
        base = np.radians(-100.0 + 35.0 * jump)
        for step in range(steps):
            angle = base + np.radians(0.4 * step)
            eyes.append(centre + radius * np.array([2.3 * np.cos(angle), 2.3 * np.sin(angle), 0.7]))
    return eyes


def measure(width: int, height: int, steps: int, jumps: int) -> dict:
    import bpy

    from curved_reflections.addon import look_at_view, morphing
    from curved_reflections.addon.sbc import build_sample_based_camera
    from curved_reflections.addon.scene import scene_bounds
    from curved_reflections.gpu_shaders.morph_source import GPUFaceImages, MorphSource
    from curved_reflections.gpu_shaders.projection import SBCTextures
    from curved_reflections.gpu_shaders.reflection_draw import ReflectionRenderer
    from curved_reflections.operators import demo_scenes
    from curved_reflections.operators.capture import capture_scene
    from curved_reflections.operators.gpu_init import ensure_gpu
    from curved_reflections.operators.render_image import BOUNDS_MARGIN, reflector_appearance

    ensure_gpu()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, width, height)
    captured = capture_scene(bpy.context.evaluated_depsgraph_get())
    mirror = captured.reflectors[0]
    matrix = np.array(bpy.data.objects[mirror.name].matrix_world, dtype=np.float64)
    lo, hi = scene_bounds(captured.reflectors, captured.meshes)
    bounds = scene_bounds(captured.reflectors, captured.meshes, BOUNDS_MARGIN * float(np.linalg.norm(hi - lo)))
    settings = scene.curved_reflections
    colors, reflectivity = reflector_appearance(captured.reflectors, scene)
    renderer = ReflectionRenderer(captured.reflectors, captured.meshes, colors, reflectivity, polish=False)  # as live

    local = morphing.reflector_in_frame(mirror, morphing.rigid_frame(matrix))
    grid = morphing.grid_on_demand(local, morphing.MorphSettings())
    centre = mirror.vertices.mean(axis=0)
    radius = float(np.max(np.linalg.norm(mirror.vertices - centre, axis=1)))
    views = [look_at_view(eye, centre, fov_y_deg=45.0, width=width, height=height)
             for eye in eye_path(centre, radius, steps, jumps)]
    start = time.perf_counter()
    tetrahedra = [grid.check_view(view, matrix)[0] for view in views]  # builds the nodes used
    node_seconds = time.perf_counter() - start

    def projection_ms(source, view, camera=None) -> float:
        begin = time.perf_counter()
        renderer.projection(source, view, camera)
        return 1000.0 * (time.perf_counter() - begin)

    # Warm-up: shaders compiled, textures of a first camera packed.
    warm = build_sample_based_camera(captured.reflectors, views[0], bounds, downsample=settings.downsample,
                                     accuracy_px=settings.accuracy_px)
    projection_ms(SBCTextures(warm), views[0], warm)
    rows = []
    for face_images in (GPUFaceImages(), None):
        grid.face_images = face_images
        grid._static.clear()
        previous = None
        for index, (view, tet) in enumerate(zip(views, tetrahedra)):
            row = rows[index] if face_images is None else {"tetrahedron": tet, "entered": tet != previous}
            previous = tet
            key = "morph_gpu" if face_images is not None else "morph_numpy"
            row[key] = projection_ms(MorphSource([(grid, matrix)], view), view)
            row["morph_sub_triangles"] = renderer.stats["mixed_sub_triangles"]
            if face_images is not None:
                begin = time.perf_counter()
                sbc = build_sample_based_camera(captured.reflectors, view, bounds, downsample=settings.downsample,
                                                accuracy_px=settings.accuracy_px)
                row["build"] = 1000.0 * (time.perf_counter() - begin)
                row["runtime_projection"] = projection_ms(SBCTextures(sbc), view, sbc)
                row["runtime_sub_triangles"] = renderer.stats["mixed_sub_triangles"]
                row["runtime"] = row["build"] + row["runtime_projection"]
                rows.append(row)
    return {"width": width, "height": height, "vertices": int(len(renderer.geometry.vertices)),
            "views": len(views), "node_seconds": node_seconds, "nodes_built": len(grid.nodes), "rows": rows}


def _median(rows: list, key: str, entered: bool | None = None) -> float:
    values = [r[key] for r in rows if entered is None or r["entered"] == entered]
    return statistics.median(values) if values else float("nan")


def report(result: dict, command: str, machine: str) -> str:
    rows = result["rows"]
    runtime = _median(rows, "runtime")
    same, entered = _median(rows, "morph_gpu", False), _median(rows, "morph_gpu", True)
    lines = [
        "# Cost of a view change: runtime mode against morphing mode",
        "",
        f"Generated {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC by `{command}` on {machine}.",
        "",
        f"sbc_fig3 at {result['width']}x{result['height']}, {result['vertices']:,} drawn diffuse vertices "
        f"(the renderer's pre-subdivided meshes), {result['views']} views on a path inside the default "
        f"9x9x5 grid; {result['nodes_built']} nodes built on demand first ({result['node_seconds']:.1f} s, "
        "not in the times below). Milliseconds, medians over the views:",
        "",
        "| what runs after the view changed | ms |",
        "|---|---:|",
        f"| runtime: camera build | {_median(rows, 'build'):.0f} |",
        f"| runtime: projection (GPU) | {_median(rows, 'runtime_projection'):.0f} |",
        f"| **runtime: total** | **{runtime:.0f}** |",
        f"| morphing, same tetrahedron (blend only) | {same:.0f} |",
        f"| morphing, new tetrahedron, node projections on the GPU | {entered:.0f} |",
        f"| morphing, new tetrahedron, node projections in numpy | {_median(rows, 'morph_numpy', True):.0f} |",
        "",
        f"Runtime over morphing: **{runtime / same:.1f}x** in the same tetrahedron, "
        f"{runtime / entered:.1f}x entering a new one "
        f"({sum(r['entered'] for r in rows)} of {len(rows)} views entered one).",
        "",
        "Per view (ms):",
        "",
        "| view | tetrahedron | entered | runtime build | runtime projection | morph (GPU nodes) | morph (numpy nodes) |",
        "|---:|---:|:---:|---:|---:|---:|---:|",
    ]
    for k, r in enumerate(rows):
        lines.append(f"| {k} | {r['tetrahedron']} | {'yes' if r['entered'] else ''} | {r['build']:.0f} | "
                     f"{r['runtime_projection']:.0f} | {r['morph_gpu']:.0f} | {r['morph_numpy']:.0f} |")
    lines += ["", "Accuracy of morphing against the exact solver: [morphing.md](morphing.md). The GPU here is "
              "Mesa llvmpipe, which runs on the same two CPU cores as numpy, so the node projections' "
              "GPU/numpy ratio on a hardware GPU is not measured by this table.", ""]
    return "\n".join(lines)


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="markdown file to write")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--steps", type=int, default=6, help="views per arc (0.4 degree apart)")
    parser.add_argument("--jumps", type=int, default=3, help="arcs, 35 degrees apart")
    parser.add_argument("--quick", action="store_true", help="small: 160x120, 2 arcs of 3 views")
    args = parser.parse_args(argv)
    if args.quick:
        args.width, args.height, args.steps, args.jumps = 160, 120, 3, 2
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    bench_sbc.import_package()
    result = measure(args.width, args.height, args.steps, args.jumps)
    command = " ".join([".venv/bin/python", "tests/benchmarks/bench_view_change.py"] + [shlex.quote(a) for a in argv])
    text = report(result, command, bench_draw._machine())
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text, encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
