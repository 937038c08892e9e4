# SPDX-License-Identifier: GPL-3.0-or-later
"""The live view's re-bake of a big reflector (issue 18, part 4: "re-bakes of big
reflectors run off the main thread with progress"): how long the main thread is held.

    .venv/bin/python tests/benchmarks/bench_live_rebake.py      # docs/benchmarks/live_rebake.md
    .venv/bin/python tests/benchmarks/bench_live_rebake.py --quick --out /tmp/live_rebake.md

The sbc_fig3 demo, its mirror ball in Runtime mode with Subdivision Surface (level 4:
about a million triangles), baked live for the scene camera's view. Then the ball is
moved, a re-bake, twice:

- *waiting* (what background mode does, and every re-bake did before): one
  ``live.process(wait=True)`` call captures, builds the ball's BVH and seal and the
  view's camera on the main thread;
- *not waiting* (the viewport's timer): ``live.process`` every POLL_SECONDS, as the
  timer calls it, until the new camera has landed; each call's time on the main thread
  is measured (the capture, then short polls while the worker prepares the reflector
  and builds the camera; the status line meanwhile), and the time until the capture
  landed and until the camera did.

Last, a diffuse object (the cube) is moved: no re-bake, the main thread captures,
re-seals the ball against the meshes and makes a new renderer.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_draw  # noqa: E402  (same folder: machine facts with the GPU)
import bench_sbc  # noqa: E402  (same folder: package import)

DEFAULT_OUT = bench_sbc.REPO_ROOT / "docs" / "benchmarks" / "live_rebake.md"
#: Subdivision Surface levels of the ball: about a million triangles.
LEVELS = 4


def _triangles(obj, depsgraph) -> int:
    import numpy as np

    polygons = obj.evaluated_get(depsgraph).data.polygons
    corners = np.zeros(len(polygons), dtype=np.int64)
    polygons.foreach_get("loop_total", corners)
    return int((corners - 2).sum())


def measure(width: int, height: int, levels: int, repeats: int) -> dict:
    import bpy

    from curved_reflections.operators import demo_scenes, live
    from curved_reflections.operators.capture import view_from_camera
    from curved_reflections.operators.gpu_init import ensure_gpu

    ensure_gpu()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, width, height)
    ball = bpy.data.objects["MirrorSphere"]
    ball.curved_reflections.mode = 'RUNTIME'
    ball.modifiers.new("Subdivision", 'SUBSURF').levels = levels
    scene.curved_reflections.auto_refresh = False  # the re-bakes below are driven by hand
    depsgraph = bpy.context.evaluated_depsgraph_get()
    triangles = _triangles(ball, depsgraph)
    view = view_from_camera(scene.camera, scene, depsgraph)
    start = time.perf_counter()
    state = live.bake(scene, depsgraph, {live.CAMERA_KEY: view}, wait=True)
    first_bake = time.perf_counter() - start

    def moved():
        ball.location.x += 0.01
        bpy.context.view_layer.update()
        state.dirty_reflectors = True
        return bpy.context.evaluated_depsgraph_get()

    waiting, runs = [], []
    for _ in range(repeats):
        depsgraph = moved()
        start = time.perf_counter()
        live.process(scene, depsgraph, wait=True)
        waiting.append(time.perf_counter() - start)

        depsgraph = moved()
        camera = state.cameras[live.CAMERA_KEY]
        calls, statuses, landed = [], [], None
        start = time.perf_counter()
        while True:
            before = time.perf_counter()
            live.process(scene, depsgraph)
            calls.append(time.perf_counter() - before)
            statuses.append(state.status)
            if landed is None and state.preparing is None:
                landed = time.perf_counter() - start
            if state.cameras.get(live.CAMERA_KEY) is not camera:
                break
            time.sleep(live.POLL_SECONDS)
        runs.append({"first": calls[0], "longest_poll": max(calls[1:], default=0.0), "polls": len(calls),
                     "main": sum(calls), "landed": landed, "camera": time.perf_counter() - start,
                     "status": next((s for s in statuses if s.startswith("Preparing")), "")})
    remeshes = []
    cube = bpy.data.objects["Cube"]
    for _ in range(repeats):
        cube.location.x += 0.01
        bpy.context.view_layer.update()
        state.dirty_meshes = True
        start = time.perf_counter()
        live.process(scene, bpy.context.evaluated_depsgraph_get())
        remeshes.append(time.perf_counter() - start)
    return {"width": width, "height": height, "levels": levels, "triangles": triangles, "repeats": repeats,
            "first_bake": first_bake, "waiting": waiting, "runs": runs, "remeshes": remeshes}


def report(result: dict, command: str) -> str:
    def median(key):
        return statistics.median(run[key] for run in result["runs"])

    waiting = statistics.median(result["waiting"])
    lines = [
        "# Live re-bake of a big reflector",
        "",
        f"Generated by `{command}` on {bench_draw._machine()}.",
        "",
        f"sbc_fig3 at {result['width']}x{result['height']}, the ball in Runtime mode with Subdivision Surface level "
        f"{result['levels']}: {result['triangles']:,} triangles, baked live for the scene camera "
        f"({result['first_bake']:.1f} s). The ball is then moved and re-baked, medians of {result['repeats']} "
        "(see the module docstring).",
        "",
        "| re-bake | main thread, s | longest call, s | capture landed after, s | camera landed after, s |",
        "|---|---:|---:|---:|---:|",
        f"| waiting (one `process(wait=True)`: background mode, and every re-bake before) | {waiting:.2f} | "
        f"{waiting:.2f} | {waiting:.2f} | {waiting:.2f} |",
        f"| not waiting (the viewport's timer, {median('polls'):.0f} calls) | {median('main'):.2f} | "
        f"{max(median('first'), median('longest_poll')):.2f} | {median('landed'):.2f} | {median('camera'):.2f} |",
        f"| a diffuse object moved (the cube: capture, seal, renderer; no re-bake) | "
        f"{statistics.median(result['remeshes']):.2f} | {statistics.median(result['remeshes']):.2f} | | |",
        "",
        f"The first call of a re-bake that does not wait (the capture: the evaluated mesh read from Blender) "
        f"held the main thread {median('first'):.2f} s, every later poll at most {median('longest_poll'):.3f} s; "
        f"meanwhile the last reflection drew and the status line said: \"{result['runs'][0]['status']}\".",
        "",
    ]
    return "\n".join(lines)


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="markdown file to write")
    parser.add_argument("--width", type=int, default=320)
    parser.add_argument("--height", type=int, default=240)
    parser.add_argument("--levels", type=int, default=LEVELS, help="Subdivision Surface levels of the ball")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="96x72, level 3 (above the worker's threshold), once")
    args = parser.parse_args(argv)
    if args.quick:
        args.width, args.height, args.levels, args.repeats = 96, 72, 3, 1
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    bench_sbc.import_package()
    command = bench_draw.command_line("bench_live_rebake.py", argv)
    return bench_draw.write_report(args.out, report(measure(args.width, args.height, args.levels, args.repeats),
                                                    command))


if __name__ == "__main__":
    sys.exit(main())
