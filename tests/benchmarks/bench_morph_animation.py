# SPDX-License-Identifier: GPL-3.0-or-later
"""Render Image's animations in Morphing mode (issue 17) or Octree mode (issue 20): time
per frame against Workbench's, and label disagreement against Cycles on sampled frames,
in one run.

    .venv/bin/python tests/benchmarks/bench_morph_animation.py      # docs/benchmarks/morph_animation.md
    .venv/bin/python tests/benchmarks/bench_morph_animation.py --mode OCTREE    # docs/benchmarks/octree_animation.md
    .venv/bin/python tests/benchmarks/bench_morph_animation.py --quick --out /tmp/morph_animation.md

The sbc_fig3 demo (its flat emission palette: every pixel's colour names an object) at
``--width`` x ``--height``, its mirror ball in ``--mode`` (Morphing: panoramic cameras at
the nodes, blended over a tetrahedron; Octree: ray octrees, blended over a cube), the grid (``--grid``, the
default 9x9x5) baked first into a temporary cache folder (the scene's *Cache Folder*;
the bake is timed and reported apart). The camera circles the ball at 2.3 radii, inside
the grid, turning ``--orbit-degrees`` a frame and tracking the ball. Then:

- ``render_image(animation=True)`` against Workbench's ``render.render(animation=True)``
  over the same frames (seconds per frame, both writing PNGs);
- on ``--sampled`` frames spread over the animation, Cycles (16 samples, the demo's
  reference) and our frame in that mode (also with its gaps ray traced, ``trace_gaps``)
  and in Runtime mode, each timed; label disagreement on the mirror's pixels (Workbench
  mask), as ``make demo`` measures it. ``--images`` writes each sampled frame side by
  side: Cycles, the mode, the mode with gaps traced, Runtime.
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
import animation_runs  # noqa: E402  (same folder: the animation runs shared with bench_perturbation.py)
import bench_draw  # noqa: E402  (same folder: machine facts with the GPU)
import bench_sbc  # noqa: E402  (same folder: package import)

REPO_ROOT = Path(__file__).resolve().parents[2]
OUT_OF_MODE = {"MORPHING": REPO_ROOT / "docs" / "benchmarks" / "morph_animation.md",
               "OCTREE": REPO_ROOT / "docs" / "benchmarks" / "octree_animation.md"}
LABELS = {"MORPHING": "Morphing", "OCTREE": "Octree"}
MIRROR = "MirrorSphere"


def measure(width: int, height: int, grid: tuple, frames: int, degrees: float, sampled: int, samples: int,
            images: Path | None = None, mode: str = "MORPHING", polish: str | None = None) -> dict:
    import bpy

    from curved_reflections.blender import demo_scenes
    from curved_reflections.blender.png import write_png
    from curved_reflections.tools import reference_render as rr
    from curved_reflections.blender.gpu_init import ensure_gpu
    from curved_reflections.blender.render_image import render_scene

    ensure_gpu()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, width, height)
    scene.curved_reflections.max_order = 1
    scene.curved_reflections.morph_grid = grid
    if polish is not None:
        scene.curved_reflections.morph_polish_nodes = polish == "on"
    animation_runs.orbit(scene, bpy.data.objects[MIRROR], frames, degrees)  # inside the grid
    settings = bpy.data.objects[MIRROR].curved_reflections
    result = {"width": width, "height": height, "grid": grid, "frames": frames, "degrees": degrees, "samples": samples,
              "mode": mode, "polish": scene.curved_reflections.morph_polish_nodes}
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        scene.curved_reflections.morph_cache_dir = str(folder / "cache")
        settings.mode = mode
        start = time.perf_counter()
        assert bpy.ops.curved_reflections.bake_morphing() == {'FINISHED'}
        result["bake_seconds"] = time.perf_counter() - start

        scene.frame_set(1)
        check = render_scene(scene, bpy.context.evaluated_depsgraph_get())
        assert check.stats["methods"] == {MIRROR: mode} and "n_rays" not in check.stats, check.stats
        result["ours"], result["workbench"] = animation_runs.time_against_workbench(scene, folder, frames)

        def set_mode(name):
            return lambda: setattr(settings, "mode", name)

        rows = animation_runs.sampled_frames(scene, folder, frames, sampled, samples, [
            ("GRID", set_mode(mode), {}), ("GAPS", set_mode(mode), {"trace_gaps": True}),
            ("RUNTIME", set_mode('RUNTIME'), {})])
        settings.mode = mode
        for row in rows:
            assert all(row[f"{name}_methods"][MIRROR] == expected
                       for name, expected in (("GRID", mode), ("GAPS", mode), ("RUNTIME", "RUNTIME"))), row
            if images is not None:
                strip = np.concatenate([rr.read_png(folder / f"{name}_{row['frame']}.png")[..., :3]
                                        for name in ("cycles", "GRID", "GAPS", "RUNTIME")], axis=1)
                write_png(Path(images) / f"{mode.lower()}_animation_frame_{row['frame']}.png", strip)
        result["rows"] = rows
    return result


def report(result: dict, command: str) -> str:
    rows = result["rows"]
    ratio = result["ours"] / result["workbench"]
    label = LABELS[result["mode"]]
    grid = statistics.mean(r["GRID"] for r in rows)
    lines = [
        f"# Render Image in {label} mode: animations against Workbench, frames against Cycles",
        "",
        f"Generated {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC by `{command}` on "
        f"{bench_draw._machine()}.",
        "",
        f"sbc_fig3 at {result['width']}x{result['height']}, the mirror ball in {label} mode, its "
        f"{'x'.join(map(str, result['grid']))} grid baked first in {result['bake_seconds']:.1f} s (not in the "
        f"times below); the camera circles the ball at 2.3 radii inside the grid, {result['degrees']:g} degrees a "
        f"frame, {result['frames']} frames; Polish Node Images {'on' if result['polish'] else 'off'}.",
        "",
        "| ours s/frame | Workbench s/frame | ratio |",
        "|---:|---:|---:|",
        f"| {result['ours']:.3f} | {result['workbench']:.3f} | **{ratio:.2f}x** |",
        "",
        f"Label disagreement with Cycles ({result['samples']} samples) on the mirror's pixels, sampled frames:",
        "",
        f"| frame | mirror px | {label} | s | {label}, gaps traced | s | Runtime | s |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(f"| {r['frame']} | {r['mirror_px']:,} | {100 * r['GRID']:.1f} % | {r['GRID_seconds']:.2f} | "
                     f"{100 * r['GAPS']:.1f} % | {r['GAPS_seconds']:.2f} | {100 * r['RUNTIME']:.1f} % | "
                     f"{r['RUNTIME_seconds']:.2f} |")
    gaps = statistics.mean(r["GAPS"] for r in rows)
    lines += ["", f"{label}: **{ratio:.2f}x** Workbench's time per frame (target <= 2x), **{100 * grid:.1f} %** "
              f"label disagreement on the sampled frames (target <= 2 %); with its gaps ray traced "
              f"(`render_image(trace_gaps=True)`) {100 * gaps:.1f} %, at the single-frame times above.", ""]
    return "\n".join(lines)


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mode", choices=sorted(OUT_OF_MODE), default="MORPHING", help="the grid's kind")
    parser.add_argument("--out", type=Path, default=None, help="markdown file to write (default: per mode, "
                        "docs/benchmarks/morph_animation.md or octree_animation.md)")
    parser.add_argument("--width", type=int, default=480)
    parser.add_argument("--height", type=int, default=320)
    parser.add_argument("--grid", type=int, nargs=3, default=(9, 9, 5), help="morphing grid nodes")
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--orbit-degrees", type=float, default=2.0, help="camera turn per frame")
    parser.add_argument("--sampled", type=int, default=3, help="frames compared with Cycles")
    parser.add_argument("--samples", type=int, default=16, help="Cycles samples")
    parser.add_argument("--images", type=Path, default=None,
                        help="folder for the sampled frames side by side (Cycles, Morphing, Runtime)")
    parser.add_argument("--quick", action="store_true", help="small: 160x120, a 3x3x2 grid, 3 frames, 1 sampled")
    parser.add_argument("--polish", choices=("on", "off"), default=None,
                        help="the scene's Polish Node Images (default: as a new scene has it)")
    args = parser.parse_args(argv)
    args.out = args.out or OUT_OF_MODE[args.mode]
    if args.quick:
        args.width, args.height, args.grid, args.frames, args.sampled, args.samples = 160, 120, (3, 3, 2), 3, 1, 4
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    bench_sbc.import_package()
    command = bench_draw.command_line("bench_morph_animation.py", argv)
    result = measure(args.width, args.height, tuple(args.grid), args.frames, args.orbit_degrees, args.sampled,
                     args.samples, args.images, args.mode, args.polish)
    text = report(result, command)
    return bench_draw.write_report(args.out, text)


if __name__ == "__main__":
    sys.exit(main())
