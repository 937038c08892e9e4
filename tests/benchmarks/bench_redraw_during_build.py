# SPDX-License-Identifier: GPL-3.0-or-later
"""The live view's main thread while a Runtime camera builds (issue 17: "a viewport that
never waits"), measured in one run.

    .venv/bin/python tests/benchmarks/bench_redraw_during_build.py       # docs/benchmarks/redraw_during_build.md
    .venv/bin/python tests/benchmarks/bench_redraw_during_build.py --quick --out /tmp/redraw.md

The sbc_fig3 demo with its mirror in Runtime mode, baked in the live view
(``blender/live.py``) for the scene camera's view. The view then turns by
``--degrees``: the live view asks for that view's camera, which builds off the main
thread (``live_workers.build_camera``, with its reflected triangles) while the main
thread goes on redrawing the moved view with the old camera's. Timed on the main thread, into one offscreen
of the view's size that holds the scene's depth (``bench_draw.scene_depth``: what
Blender's drawing leaves for a draw handler, which the overlay is depth-tested
against), each ending with a one-pixel read-back:

- **redraw, idle**: ``live.draw`` of the moved view with no build running;
- **redraw during a build**: the same, as often as it fits while the build runs;
- **plain**: the renderer's diffuse triangles drawn once with one colour (bench_draw);
- **the redraw when the camera lands**: the first draw with the new camera, which puts
  the reflected triangles the worker made on the GPU (``CameraPass.adopt``);

and the build's wall time (the camera and its triangles). Medians and maxima over ``--builds`` view turns.
"""

from __future__ import annotations

import argparse
import datetime
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import animation_runs  # noqa: E402  (same folder: a view turned without a camera)
import bench_draw  # noqa: E402  (same folder: machine facts with the GPU, the plain draw)
import bench_sbc  # noqa: E402  (same folder: package import)

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_OUT = REPO_ROOT / "docs" / "benchmarks" / "redraw_during_build.md"
#: Target of a redraw during a build over the plain draw (issue 17).
TARGET_RATIO = 2.0


def measure(width: int, height: int, builds: int, degrees: float, idle_repeats: int) -> dict:
    import bpy
    import gpu

    from curved_reflections.blender import demo_scenes, live
    from curved_reflections.blender.capture import view_from_camera
    from curved_reflections.blender.gpu_init import ensure_gpu

    ensure_gpu()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    try:
        scene = demo_scenes.build("sbc_fig3", bpy.context.scene, width, height)
        bpy.data.objects["MirrorSphere"].curved_reflections.mode = 'RUNTIME'
        depsgraph = bpy.context.evaluated_depsgraph_get()
        base = view_from_camera(scene.camera, scene, depsgraph)
        key = "bench"
        state = live.start(scene, depsgraph, views={key: base}, wait=True)
        plain = bench_draw.PlainDraw(state.renderer.geometry)
        times = {"idle": [], "during": [], "plain": [], "landing": [], "build": []}
        offscreen = gpu.types.GPUOffScreen(width, height, format='RGBA16F')
        try:
            with offscreen.bind():
                framebuffer = gpu.state.active_framebuffer_get()
                framebuffer.clear(color=(0.0, 0.0, 0.0, 1.0))
                view = base
                live.draw(scene, key, view)  # the first camera's projection, shaders built
                for turn in range(1, builds + 1):
                    view = animation_runs.turned_view(base, degrees * turn)
                    bench_draw.scene_depth(framebuffer, plain, view)  # as Blender drew it (the plain draws keep it)
                    state.requests.pop(key, None)
                    live._start_camera(state, key, view, wait=False)  # what the debounced timer starts
                    future = state.jobs[key].future
                    start = time.perf_counter()
                    while not future.done():
                        times["during"].append(bench_draw.timed(lambda: live.draw(scene, key, view), framebuffer))
                    times["build"].append(time.perf_counter() - start)
                    live.process(scene, depsgraph)  # collects the camera
                    times["landing"].append(bench_draw.timed(lambda: live.draw(scene, key, view), framebuffer))
                    for _ in range(idle_repeats):
                        times["idle"].append(bench_draw.timed(lambda: live.draw(scene, key, view), framebuffer))
                        times["plain"].append(bench_draw.timed(lambda: plain.draw(view), framebuffer))
        finally:
            offscreen.free()
        vertices = int(len(state.renderer.geometry.vertices))
    finally:
        live.clear_all()
    summary = {name: {"median": 1000.0 * statistics.median(values), "max": 1000.0 * max(values), "n": len(values)}
               for name, values in times.items() if values}
    return {"width": width, "height": height, "builds": builds, "degrees": degrees, "vertices": vertices,
            "ms": summary}


def report(result: dict, command: str) -> str:
    ms = result["ms"]
    plain = ms["plain"]["median"]
    rows = [("redraw, idle", "idle"), ("**redraw during a build**", "during"), ("plain draw", "plain"),
            ("redraw when the camera lands (upload)", "landing"),
            ("camera build and projection (worker)", "build")]
    lines = [
        "# The live view's main thread while a Runtime camera builds",
        "",
        f"Generated {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC by `{command}` on "
        f"{bench_draw._machine()}.",
        "",
        f"sbc_fig3 in Runtime mode at {result['width']}x{result['height']}, {result['vertices']:,} drawn vertices; "
        f"the view turned by {result['degrees']:g} degrees {result['builds']} times, a camera built off the main "
        "thread each time while the main thread redraws the turned view with the old camera. Each redraw is an "
        "overlay over the scene's depth (drawn by the plain draw, untimed, as Blender's drawing leaves it for a "
        "draw handler): its pre-pass draws the mirror alone. Milliseconds on the main thread (each draw ends "
        "with a one-pixel read-back):",
        "",
        "| what | median ms | max ms | count | median / plain |",
        "|---|---:|---:|---:|---:|",
    ]
    for label, name in rows:
        r = ms[name]
        lines.append(f"| {label} | {r['median']:.1f} | {r['max']:.1f} | {r['n']} | {r['median'] / plain:.2f}x |")
    during = ms["during"]["median"] / plain
    lines += ["", f"A redraw during a build: **{during:.2f}x** the plain draw (target <= {TARGET_RATIO:g}x: "
              f"{'met' if during <= TARGET_RATIO else 'not met'}).", ""]
    return "\n".join(lines)


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="markdown file to write")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--builds", type=int, default=5, help="view turns, a camera built for each")
    parser.add_argument("--degrees", type=float, default=4.0, help="turn per build")
    parser.add_argument("--idle-repeats", type=int, default=5, help="idle redraws and plain draws per turn")
    parser.add_argument("--quick", action="store_true", help="small: 160x120, 2 builds")
    args = parser.parse_args(argv)
    if args.quick:
        args.width, args.height, args.builds, args.idle_repeats = 160, 120, 2, 2
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    bench_sbc.import_package()
    command = bench_draw.command_line("bench_redraw_during_build.py", argv)
    text = report(measure(args.width, args.height, args.builds, args.degrees, args.idle_repeats), command)
    return bench_draw.write_report(args.out, text)


if __name__ == "__main__":
    sys.exit(main())
