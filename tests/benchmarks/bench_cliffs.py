# SPDX-License-Identifier: GPL-3.0-or-later
"""Views that used to cost many ordinary frames (issue 18, part 4: "no cliffs"): the
camera's clip start cutting into the mirror, the eye on its surface, grazing views.

    .venv/bin/python tests/benchmarks/bench_cliffs.py      # docs/benchmarks/cliffs.md
    .venv/bin/python tests/benchmarks/bench_cliffs.py --quick --out /tmp/cliffs.md

The sbc_fig3 demo (a mirror ball of radius 1 on a checker floor, columns, a cube), its
mirror in Runtime mode (the sample-based camera: the other modes build nothing per
view), max order 2, Render Image's frame (``render_image.render_scene``) from the scene
camera and from each view below, one process, in this order; per view the median of
``--repeats`` frames after a first one that fills the caches, and the process's peak
resident memory after it (it only grows, so a row's figure bounds that view's own peak).
Target: every view within 3x the ordinary frame. Last, another scene, in a process of
its own: the same with the ball subdivided to about a million triangles (issue 18: peak
memory under 1 GB), its peak resident memory measured first over Blender's own
Workbench frame of the scene (the mesh evaluated and drawn: Blender's share), then,
the peak reset, over our frames (``/proc/self/clear_refs``).
"""

from __future__ import annotations

import argparse
import datetime
import json
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_draw  # noqa: E402  (same folder: machine facts with the GPU)
import bench_sbc  # noqa: E402  (same folder: package import)

DEFAULT_OUT = bench_sbc.REPO_ROOT / "docs" / "benchmarks" / "cliffs.md"
#: Target: each view's frame over the ordinary view's.
TARGET_RATIO = 3.0
#: (name, what it is, eye offset from the ball's centre in radii (x, y, z), yaw in degrees
#: from looking along +y, clip start in radii or None for the camera's own).
VIEWS = (
    ("ordinary", "the scene camera", None, 0.0, None),
    ("clip start inside", "5 % of a radius from the surface, clip start 0.1 radius (inside the ball)",
     (0.0, -1.05, 0.0), 0.0, 0.1),
    ("eye on the surface", "0.2 % of a radius from the surface, the camera's clip start (0.1 m)",
     (0.0, -1.002, 0.0), 0.0, None),
    ("along the surface", "1 % of a radius from the surface, looking 80 degrees aside, clip start 0.001 radius",
     (0.0, -1.01, 0.0), 80.0, 0.001),
    ("grazing", "3 radii away, the ball's rim in the middle of the view", (1.05, -3.0, 0.0), 0.0, None),
)
#: Last, the scene camera again with the ball subdivided this many times (Subdivision
#: Surface): about a million triangles.
BIG_LEVELS = 4


def _place(scene, centre: np.ndarray, offset, yaw: float, clip) -> None:
    camera = scene.camera
    camera.constraints.clear()
    camera.location = centre + np.asarray(offset, dtype=np.float64)
    camera.rotation_euler = (np.pi / 2, 0.0, np.radians(yaw))
    if clip is not None:
        camera.data.clip_start = float(clip)


def _stage(width: int, height: int):
    """sbc_fig3 with its ball in Runtime mode and max order 2: (scene, ball)."""
    import bpy

    from curved_reflections.blender import demo_scenes
    from curved_reflections.blender.gpu_init import ensure_gpu

    ensure_gpu()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, width, height)
    ball = bpy.data.objects["MirrorSphere"]
    ball.curved_reflections.mode = 'RUNTIME'
    scene.curved_reflections.max_order = 2
    return scene, ball


def _timed_row(scene, name: str, what: str, repeats: int) -> dict:
    """One row: Render Image's frame of ``scene``, the median of ``repeats`` after a first one."""
    import bpy

    from curved_reflections.blender.render_image import render_scene

    depsgraph = bpy.context.evaluated_depsgraph_get()
    result = render_scene(scene, depsgraph)  # caches filled (shaders, capture, plan)
    seconds = []
    for _ in range(repeats):
        del result  # one frame's camera and ray-tracing set at a time, as Render Image holds them
        start = time.perf_counter()
        result = render_scene(scene, depsgraph)
        seconds.append(time.perf_counter() - start)
    return {"name": name, "what": what, "seconds": statistics.median(seconds),
            "sbc": result.seconds.get("sbc", 0.0), "draw": result.seconds.get("draw", 0.0),
            "rays": int(result.stats.get("n_rays", 0)), "sheets": int(result.stats.get("n_sheets", 0)),
            "traced": int(result.stats.get("traced_pixels") or 0), "peak_mb": _peak_mb()}


def _peak_mb() -> float:
    """The process's peak resident memory since the start or the last :func:`_reset_peak`."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:")) / 1024.0
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _reset_peak() -> bool:
    """Reset the peak resident memory to the current one (Linux); False where it cannot."""
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as clear:
            clear.write("5")
        return True
    except OSError:
        return False


def measure(width: int, height: int, repeats: int) -> list:
    """The views' rows, in one process."""
    scene, ball = _stage(width, height)
    centre, radius = np.array(ball.matrix_world.translation), 0.5 * max(ball.dimensions)
    rows = []
    for name, what, offset, yaw, clip in VIEWS:
        if offset is not None:
            _place(scene, centre, radius * np.asarray(offset), yaw, None if clip is None else clip * radius)
        rows.append(_timed_row(scene, name, what, repeats))
    return rows


def measure_big(width: int, height: int, repeats: int, levels: int) -> dict:
    """The subdivided ball's row, in this (fresh) process: Blender's own peak over a
    Workbench frame of the scene first (``blender_peak_mb``), then ours with the peak reset."""
    import bpy

    scene, ball = _stage(width, height)
    modifier = ball.modifiers.new("Subdivision", 'SUBSURF')
    modifier.levels = modifier.render_levels = levels
    scene.render.engine = 'BLENDER_WORKBENCH'
    scene.render.filepath = str(Path(bpy.app.tempdir or "/tmp") / "cliffs_workbench.png")
    bpy.ops.render.render(write_still=False)
    blender_peak = _peak_mb()
    reset = _reset_peak()
    triangles = bench_draw.evaluated_triangles(ball, bpy.context.evaluated_depsgraph_get())
    row = _timed_row(scene, "subdivided ball", f"the scene camera; the ball with Subdivision Surface level {levels}: "
                     f"{triangles:,} triangles", repeats)
    return {**row, "blender_peak_mb": blender_peak, "peak_reset": reset}


def measure_all(width: int, height: int, repeats: int, big_levels: int = BIG_LEVELS) -> dict:
    """Every row: the views here, the subdivided ball in a child process (its memory alone)."""
    rows = measure(width, height, repeats)
    if big_levels:
        child = subprocess.run([sys.executable, __file__, "--big-only", "--width", str(width), "--height", str(height),
                                "--repeats", str(repeats), "--big-levels", str(big_levels)],
                               capture_output=True, text=True, check=True)
        rows.append(json.loads(child.stdout.strip().splitlines()[-1]))
    return {"width": width, "height": height, "repeats": repeats, "rows": rows, "big_levels": big_levels}


def report(result: dict, command: str) -> str:
    rows = result["rows"]
    ordinary = rows[0]["seconds"]
    lines = [
        "# Views without cliffs",
        "",
        f"Generated {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC by `{command}` on "
        f"{bench_draw._machine()}.",
        "",
        f"sbc_fig3 at {result['width']}x{result['height']}, the mirror ball in Runtime mode, max order 2; Render "
        f"Image's frame (`render_image.render_scene`), median of {result['repeats']} after a first one. Peak: the "
        "process's resident memory after the view (it only grows); for the subdivided ball, in a process of its "
        "own, over our frames alone, after Blender's own Workbench frame of the scene (its peak in the last "
        "column: the mesh evaluated and drawn).",
        "",
        "| view | where the camera is | s per frame | / ordinary | camera s | drawing s | rays | sheets | "
        "traced px | peak MB | Workbench's peak MB |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        blender = f"{r['blender_peak_mb']:.0f}" if "blender_peak_mb" in r else ""
        lines.append(f"| {r['name']} | {r['what']} | {r['seconds']:.2f} | {r['seconds'] / ordinary:.2f}x | "
                     f"{r['sbc']:.2f} | {r['draw']:.2f} | {r['rays']:,} | {r['sheets']:,} | {r['traced']:,} | "
                     f"{r['peak_mb']:.0f} | {blender} |")
    worst = max(r["seconds"] for r in rows if r["name"] != "subdivided ball") / ordinary
    lines += ["", f"Slowest view: **{worst:.2f}x** the ordinary frame (target <= {TARGET_RATIO:g}x: "
              f"{'met' if worst <= TARGET_RATIO else 'not met'}); the subdivided ball is another scene, "
              "not a view, and not in this ratio.", ""]
    big = [r for r in rows if "blender_peak_mb" in r]
    if big:
        added = big[0]["peak_mb"] - big[0]["blender_peak_mb"]
        lines += [f"Subdivided ball: peak **{big[0]['peak_mb']:.0f} MB** in all, **{added:.0f} MB** over Blender's "
                  f"own frame of the scene ({big[0]['blender_peak_mb']:.0f} MB).", ""]
    return "\n".join(lines)


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="markdown file to write")
    parser.add_argument("--width", type=int, default=320)
    parser.add_argument("--height", type=int, default=240)
    parser.add_argument("--repeats", type=int, default=3, help="timed frames per view")
    parser.add_argument("--big-levels", type=int, default=BIG_LEVELS,
                        help="subdivisions of the ball for the last row (0: no such row)")
    parser.add_argument("--quick", action="store_true", help="small: 96x72, 1 frame per view, ball level 1")
    parser.add_argument("--big-only", action="store_true", help=argparse.SUPPRESS)  # the child process
    args = parser.parse_args(argv)
    if args.quick:
        args.width, args.height, args.repeats, args.big_levels = 96, 72, 1, 1
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    bench_sbc.import_package()
    if args.big_only:
        print(json.dumps(measure_big(args.width, args.height, args.repeats, args.big_levels)))
        return 0
    command = bench_draw.command_line("bench_cliffs.py", argv)
    return bench_draw.write_report(args.out, report(measure_all(args.width, args.height, args.repeats,
                                                                args.big_levels), command))


if __name__ == "__main__":
    sys.exit(main())
