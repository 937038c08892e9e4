# SPDX-License-Identifier: GPL-3.0-or-later
"""A working session, scripted and repeated for an hour (issue 46, part 5: "soak").

    .venv/bin/python tests/benchmarks/bench_soak.py              # docs/benchmarks/soak.md
    .venv/bin/python tests/benchmarks/bench_soak.py --quick --out /tmp/soak.md

One process, the sbc_fig3 demo (a mirror ball in Auto mode, max order 2, columns, a
cube near the ball) with the live view running at 160x120 and drawn into an offscreen
as the viewport's draw handler draws, one cycle of what an artist does after another:

- **orbit**: 12 frames, the camera 5 degrees further round the ball each frame;
- **edit**: the cube moved and put back; one vertex of the ball moved and put back;
- **modifier**: a Subdivision Surface added to the ball, drawn, removed;
- **bake**: the ball set to Morphing mode, its 2x2x2 grid baked (worker processes) and
  drawn, set back to Auto, its cache cleared;
- **render**: Render Image's frame (``render_image.render_scene``);
- **undo**: the cube moved, undone and redone (``bpy.ops.ed.undo`` / ``redo``);
- **reflector**: a second mirror added, drawn, deleted, drawn.

After each cycle: the process's resident memory (``VmRSS``) and the GPU textures alive
(every ``gpu.types.GPUTexture`` made is counted; one is alive while anything but the
census holds it). Memory is *flat* when the median of the last three cycles is within
5 % of the median of the three after the warm-up (the first tenth of the session, two
minutes at least, and until Blender's undo stack is full). The textures a reflector
brought must be gone once it is deleted, and at the end, once the live view is cleared
and the extension unregistered, no handler, timer or GPU texture of it may be left.
"""

from __future__ import annotations

import argparse
import datetime
import gc
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_draw  # noqa: E402  (same folder: machine facts with the GPU)
import bench_sbc  # noqa: E402  (same folder: package import)

DEFAULT_OUT = bench_sbc.REPO_ROOT / "docs" / "benchmarks" / "soak.md"
#: Target: memory growth after the warm-up, a share of the warmed-up memory.
MAX_GROWTH = 0.05
#: The warm-up: this share of the session, at least WARM_UP_MIN_SECONDS, and at least
#: the cycles that fill Blender's undo stack (*Undo Steps*, UNDO_PUSHES a cycle): it
#: grows until then, by Blender's setting, not ours.
WARM_UP_SHARE = 0.1
WARM_UP_MIN_SECONDS = 120.0
UNDO_PUSHES = 2
ORBIT_FRAMES = 12
ORBIT_DEGREES = 5.0
KEY = "soak"


class TextureCensus:
    """Counts the GPU textures made while it is installed and still held by someone:
    ``gpu.types.GPUTexture`` is replaced by a maker that keeps each texture in a list;
    :meth:`alive` drops the ones only the list holds (``sys.getrefcount``)."""

    def __init__(self):
        import gpu

        self._gpu, self._real, self.made, self.total = gpu, gpu.types.GPUTexture, [], 0
        self.made.append(self._real((1, 1), format='RGBA32F'))
        self._unheld = sys.getrefcount(self.made[0])  # the list's reference and the argument's
        self.made.clear()

    def __enter__(self):
        def make(*args, **kwargs):
            texture = self._real(*args, **kwargs)
            self.made.append(texture)
            self.total += 1
            return texture

        self._gpu.types.GPUTexture = make
        return self

    def __exit__(self, *exc):
        self._gpu.types.GPUTexture = self._real

    def alive(self) -> int:
        gc.collect()
        self.made = [texture for texture in self.made if sys.getrefcount(texture) > self._unheld + 1]
        return len(self.made)


def _resident_mb() -> float:
    with open("/proc/self/status", encoding="ascii") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmRSS:")) / 1024.0


class Session:
    """The scene, its live view and the steps of one cycle."""

    def __init__(self, width: int, height: int):
        import bpy

        from curved_reflections.blender import demo_scenes

        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        self.scene = demo_scenes.build("sbc_fig3", bpy.context.scene, width, height)
        self.ball = bpy.data.objects["MirrorSphere"]
        self.cube_name = next(o.name for o in self.scene.objects if o.type == 'MESH' and "Cube" in o.name)
        self.cube = bpy.data.objects[self.cube_name]
        self.centre = np.array(self.ball.matrix_world.translation)
        camera = self.scene.camera
        offset = np.array(camera.location) - self.centre
        self.radius, self.height = float(np.hypot(offset[0], offset[1])), float(offset[2])
        self.angle = float(np.arctan2(offset[1], offset[0]))
        self.scene.curved_reflections.morph_grid = (2, 2, 2)
        self.frames, self.offscreen = 0, None

    def _depsgraph(self):
        import bpy

        return bpy.context.evaluated_depsgraph_get()

    def draw(self) -> None:
        """A frame of the live view from the scene camera, as its draw handler draws it,
        with the work that view asks for done."""
        import gpu

        from curved_reflections.blender import live
        from curved_reflections.blender.capture import view_from_camera

        view = view_from_camera(self.scene.camera, self.scene, self._depsgraph())
        if self.offscreen is None:  # the viewport's framebuffer: one for the session
            self.offscreen = gpu.types.GPUOffScreen(view.width, view.height, format='RGBA32F')
        with self.offscreen.bind():
            gpu.state.active_framebuffer_get().clear(color=(0.0, 0.0, 0.0, 1.0), depth=1.0)
            live.draw_safely(self.scene, KEY, view)
            live.process(self.scene, self._depsgraph(), wait=True)
            live.draw_safely(self.scene, KEY, view)
        self.frames += 1

    def start(self) -> None:
        from curved_reflections.blender import live

        live.start(self.scene, self._depsgraph(), wait=True)
        self.draw()

    def _updated(self) -> None:
        import bpy

        bpy.context.view_layer.update()
        self.draw()

    def orbit(self) -> None:
        camera = self.scene.camera
        for _ in range(ORBIT_FRAMES):
            self.angle += np.radians(ORBIT_DEGREES)
            camera.location = self.centre + (self.radius * np.cos(self.angle), self.radius * np.sin(self.angle),
                                             self.height)
            self._updated()

    def edit(self) -> None:
        self.cube.location.x += 0.1
        self._updated()
        self.cube.location.x -= 0.1
        vertex = self.ball.data.vertices[0]
        vertex.co.z += 0.02
        self.ball.data.update()
        self._updated()
        vertex.co.z -= 0.02
        self.ball.data.update()
        self._updated()

    def modifier(self) -> None:
        modifier = self.ball.modifiers.new("Soak Subdivision", 'SUBSURF')
        modifier.levels = 1
        self._updated()
        self.ball.modifiers.remove(modifier)
        self._updated()

    def bake(self) -> None:
        import bpy

        self.ball.curved_reflections.mode = 'MORPHING'
        assert bpy.ops.curved_reflections.bake_morphing(processes=2) == {'FINISHED'}
        self._updated()
        self.ball.curved_reflections.mode = 'AUTO'
        assert bpy.ops.curved_reflections.clear_morphing() == {'FINISHED'}
        self._updated()

    def render(self) -> None:
        from curved_reflections.blender.render_image import render_scene

        render_scene(self.scene, self._depsgraph())

    def undo(self) -> None:
        import bpy

        bpy.ops.ed.undo_push(message="soak: before the move")
        self.cube.location.y += 0.1
        bpy.ops.ed.undo_push(message="soak: the move")
        bpy.ops.ed.undo()
        bpy.ops.ed.redo()
        self._refind()
        self.cube.location.y -= 0.1
        self._updated()

    def _refind(self) -> None:
        """Undo gives new Python objects for the scene's data."""
        import bpy

        self.scene = bpy.context.scene
        self.ball = bpy.data.objects["MirrorSphere"]
        self.cube = bpy.data.objects[self.cube_name]

    def reflector(self, census: TextureCensus) -> int:
        """Add a mirror, draw, delete it, draw: the textures it left alive."""
        import bpy

        before = census.alive()
        bpy.ops.mesh.primitive_ico_sphere_add(radius=0.4, location=tuple(self.centre + (1.8, 1.2, 0.0)))
        extra = bpy.context.active_object
        extra.curved_reflections.is_reflector = True
        self._updated()
        bpy.data.objects.remove(extra)
        self._updated()
        return census.alive() - before

    def cycle(self, census: TextureCensus) -> dict:
        seconds = {}
        for name in ("orbit", "edit", "modifier", "bake", "render", "undo"):
            start = time.perf_counter()
            getattr(self, name)()
            seconds[name] = time.perf_counter() - start
        start = time.perf_counter()
        left = self.reflector(census)
        seconds["reflector"] = time.perf_counter() - start
        return {"seconds": seconds, "left_by_reflector": left}


def leftovers() -> dict:
    """Handlers, timers and live state of the extension still there."""
    import bpy

    from curved_reflections.blender import live, live_handlers, live_workers, scene_changes

    lists = [getattr(bpy.app.handlers, name) for name in dir(bpy.app.handlers) if not name.startswith("_")]
    handlers = sum(1 for handlers in lists if isinstance(handlers, list) for handler in handlers
                   if "curved_reflections" in getattr(handler, "__module__", ""))
    return {"handlers": handlers, "timers": int(bpy.app.timers.is_registered(live._tick)),
            "draw_handler": int(live_handlers._draw_handle is not None), "workers": int(live_workers.running()),
            "live_states": len(live._states), "listeners": len(scene_changes._listeners)}


def measure(minutes: float, width: int, height: int) -> dict:
    import bpy

    import curved_reflections
    from curved_reflections.blender import live
    from curved_reflections.blender.gpu_init import ensure_gpu

    ensure_gpu()
    census = TextureCensus()
    with census:  # the package is registered (bench_sbc.import_package)
        session = Session(width, height)
        session.start()
        start = time.perf_counter()
        rows = []
        while not rows or time.perf_counter() - start < 60.0 * minutes:
            row = session.cycle(census)
            row.update(elapsed=time.perf_counter() - start, rss_mb=_resident_mb(), textures=census.alive())
            rows.append(row)
            print(f"{row['elapsed']:7.0f} s  {row['rss_mb']:7.1f} MB  {row['textures']} textures", flush=True)
        live.clear(session.scene)
        session.offscreen.free()
        curved_reflections.unregister()
        textures_after = census.alive()
    undo_cycles = -(-bpy.context.preferences.edit.undo_steps // UNDO_PUSHES)
    return {"minutes": minutes, "width": width, "height": height, "rows": rows, "frames": session.frames,
            "undo_cycles": undo_cycles,
            "textures_made": census.total, "textures_after": textures_after, "leftovers": leftovers()}


def growth(result: dict) -> tuple:
    """(warmed-up MB, final MB, growth share, cycles in the warm-up)."""
    rows = result["rows"]
    warm_up = max(WARM_UP_MIN_SECONDS, WARM_UP_SHARE * 60.0 * result["minutes"])
    warm = [r for k, r in enumerate(rows) if r["elapsed"] >= warm_up and k >= result["undo_cycles"]] or rows[-1:]
    first = statistics.median(r["rss_mb"] for r in warm[:3])
    last = statistics.median(r["rss_mb"] for r in rows[-3:])
    return first, last, last / first - 1.0, len(rows) - len(warm)


def report(result: dict, command: str) -> str:
    rows = result["rows"]
    first, last, share, warm_up = growth(result)
    left = result["leftovers"]
    steps = rows[0]["seconds"].keys()
    median_steps = {name: statistics.median(r["seconds"][name] for r in rows) for name in steps}
    by_reflector = max(r["left_by_reflector"] for r in rows)
    lingering = sum(left.values())
    lines = [
        "# Soak: a working session, an hour long",
        "",
        f"Generated {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC by `{command}` on "
        f"{bench_draw._machine()}.",
        "",
        f"sbc_fig3 in Auto mode at {result['width']}x{result['height']}, the live view drawn offscreen as its draw "
        f"handler draws; {len(rows)} cycles in {rows[-1]['elapsed'] / 60.0:.1f} minutes, {result['frames']:,} live "
        f"frames, {result['textures_made']:,} GPU textures made. One cycle: an orbit of {ORBIT_FRAMES} frames "
        f"({ORBIT_DEGREES:g} degrees a frame), an object and a mirror vertex moved and put back, a Subdivision "
        "Surface added and removed, a 2x2x2 morphing grid baked and cleared, Render Image's frame, a move undone "
        "and redone, a second mirror added and deleted (the module's docstring says each step).",
        "",
        "| result | measured | target |",
        "|---|---:|---|",
        f"| resident memory after the warm-up ({warm_up} cycles: Blender's undo stack full) | {first:.0f} MB | |",
        f"| resident memory at the end (median of the last 3 cycles) | {last:.0f} MB | |",
        f"| growth after the warm-up | **{100.0 * share:+.1f} %** | <= {100.0 * MAX_GROWTH:.0f} % "
        f"({'met' if share <= MAX_GROWTH else 'not met'}) |",
        f"| GPU textures a deleted mirror left alive (worst cycle) | {by_reflector} | 0 |",
        f"| GPU textures alive after unregister | {result['textures_after']} | 0 |",
        f"| handlers, timers, draw handler, workers, live states, listeners left after unregister | "
        f"{left['handlers']}, {left['timers']}, {left['draw_handler']}, {left['workers']}, {left['live_states']}, "
        f"{left['listeners']} | all 0 ({'met' if lingering == 0 else 'not met'}) |",
        "",
        "Median seconds a step: " + ", ".join(f"{name} {s:.2f}" for name, s in median_steps.items()) + ".",
        "",
        "| cycle | minutes | resident MB | GPU textures alive |",
        "|---:|---:|---:|---:|",
    ]
    shown = sorted(set(np.linspace(0, len(rows) - 1, min(len(rows), 12)).round().astype(int)))
    lines += [f"| {k + 1} | {rows[k]['elapsed'] / 60.0:.1f} | {rows[k]['rss_mb']:.0f} | {rows[k]['textures']} |"
              for k in shown]
    return "\n".join(lines + [""])


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="markdown file to write")
    parser.add_argument("--minutes", type=float, default=60.0, help="how long the session runs")
    parser.add_argument("--width", type=int, default=160)
    parser.add_argument("--height", type=int, default=120)
    parser.add_argument("--quick", action="store_true", help="small: one cycle at 64x48")
    args = parser.parse_args(argv)
    if args.quick:
        args.minutes, args.width, args.height = 0.0, 64, 48
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    bench_sbc.import_package()
    command = bench_draw.command_line("bench_soak.py", argv)
    return bench_draw.write_report(args.out, report(measure(args.minutes, args.width, args.height), command))


if __name__ == "__main__":
    sys.exit(main())
