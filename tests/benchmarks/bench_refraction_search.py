# SPDX-License-Identifier: GPL-3.0-or-later
"""The refraction search (issue 47, ``drawing/methods/refraction_draw.py``): where it
places points seen through convex glass, against the exact solver, and what it costs.

    .venv/bin/python tests/benchmarks/bench_refraction_search.py   # docs/benchmarks/refraction_search.md
    .venv/bin/python tests/benchmarks/bench_refraction_search.py --quick --out /tmp/refraction_search.md

Accuracy: points scattered behind each glass solid (IOR 1.5) are searched on the GPU and
solved exactly (``tools/exact_refraction.py``, a grid half a pixel apart); coverage is the
share of exact images within a pixel of an answer, *points* the share of points with an
image that got one, p99 the error of the answers that have an exact image. The ball is
the scene the search was tuned on; the thick lens, the flat ellipsoid and the box are
held out (the viewport searches where the scene has more image textures than its trace
samples; otherwise it traces each glass pixel, ``drawing/methods/glass_trace.py``). Cost: the
glass demo (``demo_scenes.build_glass``) drawn as the viewport draws it, the view
orbiting a degree a frame, against a Workbench frame of the same scene.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import animation_runs  # noqa: E402  (same folder: Workbench's time per frame)
import bench_draw  # noqa: E402  (same folder: machine facts, command line, report)
import bench_sbc  # noqa: E402  (same folder: package import)

DEFAULT_OUT = bench_sbc.REPO_ROOT / "docs" / "benchmarks" / "refraction_search.md"
IOR = 1.5
#: Issue 47's bars against the exact solver.
TARGET_P99_PX, TARGET_COVERAGE = 0.5, 0.99
#: The exact solver's grid, pixels: at one pixel it misses some of a flat lens's second
#: images, which the search finds.
REFERENCE_STRIDE = 0.5
#: An answer is a true path when the eye ray through its pixel, traced on the mesh, leaves
#: the glass within this distance of its point (a thousandth of the solids' radius).
TRUE_PATH_MISS = 1e-3


def _glasses():
    """(name, tuned or held out, surface, eye) of the glass measured."""
    from curved_reflections.engine.geometry.sphere import icosphere
    from curved_reflections.tools.surfaces import ellipsoid, flat_box

    return [("ball", "tuned", icosphere((0.0, 0.0, 0.0), 1.0, 5, "Ball"), (0.3, -0.2, 5.0)),
            ("thick lens", "held out", ellipsoid((0.0, 0.0, 0.0), (0.9, 0.9, 0.36), 5), (0.2, 0.3, 5.0)),
            ("flat ellipsoid", "held out", ellipsoid((0.0, 0.0, 0.0), (1.2, 0.8, 0.5), 5), (1.5, -2.0, 4.0)),
            ("box", "held out", flat_box("Box", (-1.0, -1.0, -0.4), (1.0, 1.0, 0.4)), (0.2, 0.1, 4.0))]


def measure_accuracy(name, kind, surface, eye, width: int, height: int, n_points: int) -> dict:
    """One glass's row: the search against the exact solver, and its GPU time per frame."""
    import gpu  # noqa: F401  (the drawing modules need it loaded)

    from curved_reflections.blender.glass_layer import glass_renderer
    from curved_reflections.engine.glass import Glass, GlassSet
    from curved_reflections.blender import star_maps
    from curved_reflections.engine.glass.refraction_search import refracted_glass
    from curved_reflections.engine.scene import DiffuseMesh
    from curved_reflections.engine.view import look_at_view
    from curved_reflections.tools.exact_refraction import solve_refractions

    glass = Glass(surface, IOR)
    start = time.perf_counter()
    method, reason = refracted_glass(glass, 0, *star_maps.star_map(surface), accuracy_px=0.5)
    bake = time.perf_counter() - start
    assert method is not None, reason
    rng = np.random.default_rng(len(name))
    points = np.c_[rng.uniform(-1.8, 1.8, (n_points, 2)), rng.uniform(-4.0, -1.0, n_points)]
    triangles = np.arange(n_points - n_points % 3).reshape(-1, 3)
    # The glass layer's renderer (blender/glass_layer.py): its frame traces the pixels'
    # paths, which the search starts from too; the search runs as where a mesh has an
    # image texture (without it the pixels' rays are met with the scene instead).
    renderer = glass_renderer([glass], [DiffuseMesh("points", points, triangles, np.ones((n_points, 4)))], [method],
                              edge_fraction=None, traced=False)
    search = renderer.pass_named("refraction")
    points = renderer.geometry.vertices
    view = look_at_view(eye, (0.0, 0.0, 0.0), fov_y_deg=30.0, width=width, height=height)
    cold, warm = [], []
    for k in range(5):
        turned = look_at_view(np.asarray(eye) + (0.02 * k, 0.0, 0.0), (0.0, 0.0, 0.0), fov_y_deg=30.0, width=width,
                              height=height)
        for times, is_warm in ((cold, False), (warm, True)):
            started = time.perf_counter()
            renderer.draw_passes(turned, None, warm=is_warm)
            search.read(0, slot=None)
            times.append(time.perf_counter() - started)
    renderer.draw_passes(view, None)
    entry, _, status = search.read(0, slot=None)
    every = solve_refractions(GlassSet([glass]), view, points, stride=REFERENCE_STRIDE)
    exact, inside = every.crossing(2), every.crossing(3, more=True)
    found = status == 1
    answered_point = np.nonzero(found)[1]
    paths = GlassSet([glass]).trace(*view.pixel_rays(view.to_pixels(entry[found])[0]))
    offset = points[answered_point] - paths.origin
    across = offset - np.einsum("ij,ij->i", offset, paths.direction)[:, None] * paths.direction
    true_paths = np.linalg.norm(across, axis=1) < TRUE_PATH_MISS
    pixels = np.full(entry.shape[:-1] + (2,), np.nan)
    pixels[found] = view.to_pixels(entry[found])[0]
    error = exact.matched(pixels)[0]
    nearest = every.matched(pixels)[1]
    per_point = np.full(len(points), np.inf)
    np.minimum.at(per_point, exact.point, error)
    seen = exact.count_per_point(len(points)) > 0
    answered = np.isfinite(nearest)
    return {"name": name, "kind": kind, "points": int(len(points)), "images": int(len(exact.point)),
            "inside": int(len(inside.point)),
            "inside_coverage": float((inside.matched(pixels)[0] < 1.0).mean()) if len(inside.point) else float("nan"),
            "several": int((exact.count_per_point(len(points)) > 1).sum()),
            "coverage": float((error < 1.0).mean()), "point_coverage": float((per_point[seen] < 1.0).mean()),
            "p99": float(np.percentile(nearest[answered], 99)) if answered.any() else float("nan"),
            "unmatched": int((found & ~(nearest < 1.0)).sum()), "bake": bake,
            "true_paths": float(true_paths.mean()) if len(true_paths) else float("nan"),
            "cold_ms": 1000.0 * float(np.median(cold)), "warm_ms": 1000.0 * float(np.median(warm))}


def measure_frames(width: int, height: int, frames: int, folder: Path) -> dict:
    """The glass demo drawn as the viewport draws it, a degree of orbit a frame: median
    seconds of a draw, against Workbench's seconds a frame of the same scene."""
    import bpy
    import gpu

    from curved_reflections.blender import demo_scenes, live
    from curved_reflections.blender.capture import view_from_camera
    from curved_reflections.blender.gpu_init import ensure_gpu
    from curved_reflections.engine.view import look_at_view

    ensure_gpu()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = demo_scenes.build("glass", bpy.context.scene, width, height)
    scene.frame_start = scene.frame_end = 1
    workbench = animation_runs.workbench_seconds(scene, folder, 1)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    base = view_from_camera(scene.camera, scene, depsgraph)
    live.start(scene, depsgraph, wait=True)
    state = live.state_of(scene)
    eye, target = base.eye, np.array([0.1, 0.0, 1.0])
    offscreen = gpu.types.GPUOffScreen(width, height, format='RGBA32F')
    seconds = []
    try:
        with offscreen.bind():
            framebuffer = gpu.state.active_framebuffer_get()
            for k in range(frames + 2):
                angle = np.radians(k)
                offset = eye - target
                turned = target + np.array([np.cos(angle) * offset[0] - np.sin(angle) * offset[1],
                                            np.sin(angle) * offset[0] + np.cos(angle) * offset[1], offset[2]])
                view = look_at_view(turned, target, fov_y_deg=40.0, width=width, height=height)
                framebuffer.clear(color=(0.0, 0.0, 0.0, 1.0), depth=1.0)
                seconds.append(bench_draw.timed(lambda: live.draw(scene, live.CAMERA_KEY, view), framebuffer))
    finally:
        offscreen.free()
    vertices = len(state.glass.renderer.geometry.vertices)
    live.clear(scene)
    draw = float(np.median(seconds[2:]))
    return {"workbench": workbench, "draw": draw, "vertices": vertices}


def search_images() -> int:
    """The answer slots per point of the refraction search."""
    from curved_reflections.engine.glass.refraction_search import IMAGES

    return IMAGES


def report(rows: list, frames: dict, command: str, machine: str, size: tuple) -> str:
    lines = ["# The refraction search: accuracy and cost", "",
             f"Command: `{command}`", "", f"Machine: {machine}", "",
             f"Points behind each glass solid (IOR {IOR:g}) against the exact solver, a {size[0]}x{size[1]} view; "
             f"targets: p99 <= {TARGET_P99_PX:g} px, coverage >= {100 * TARGET_COVERAGE:g} % of the exact images. "
             "The search runs in the glass layer's frame, as the viewport runs it where the scene has more image "
             "textures than its per-pixel trace samples (the pixels' paths through the glass first: its starts "
             "come from them too; otherwise each glass pixel is traced instead, below). *Exact images*: the "
             "exact solver's images in and straight out of the glass (two interfaces); *inside*: those "
             "reflected inside first (a Glass "
             "BSDF's, three interfaces or more; the search follows one reflection), and the share of them "
             "answered; *coverage*: exact images (two "
             f"interfaces) within a pixel of an answer (the search keeps up to {search_images()} images per "
             "point); *points*: points with an image that got one; *several*: points with more than one exact "
             "image; *unmatched*: answers more than a pixel from every exact image of their point; *true paths*: "
             f"answers whose pixel's eye ray, traced on the mesh, passes within {TRUE_PATH_MISS:g} of their point; "
             f"the exact solver's grid is {REFERENCE_STRIDE:g} px; *map*: the star-shape check and the cube map's "
             "bake (on the GPU, as the add-on makes it). Frame times: the glass layer's passes (pre-pass, the "
             "pixels' paths, the search, the refracted meshes), median of 5, cold (from the guesses) and warm "
             "(from the last frame's answers), read back included.", "",
             "| glass | set | points | exact images | inside | several | coverage | points | p99 px | unmatched | "
             "true paths | map s | cold ms | warm ms |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        inside = f"{r['inside']:,} ({100 * r['inside_coverage']:.0f} %)" if r["inside"] else "0"
        lines.append(f"| {r['name']} | {r['kind']} | {r['points']:,} | {r['images']:,} | {inside} | "
                     f"{r['several']:,} | "
                     f"**{100 * r['coverage']:.1f} %** | {100 * r['point_coverage']:.1f} % | **{r['p99']:.3f}** | "
                     f"{r['unmatched']} | {100 * r['true_paths']:.1f} % | {r['bake']:.1f} | {r['cold_ms']:.0f} | "
                     f"{r['warm_ms']:.0f} |")
    lines += ["", "## The viewport", "",
              f"The glass demo (the ball and the thick lens, {frames['vertices']:,} diffuse vertices after "
              "subdivision, no image texture) drawn as the viewport draws it, the view orbiting a degree a frame: "
              "each glass pixel's ray followed through the glass's own triangles and met with the scene on the "
              "GPU, with the rays the glass reflects, no search: "
              f"**{frames['draw']:.3f} s** a draw, **{frames['draw'] / frames['workbench']:.1f}x** a Workbench "
              f"frame of the same scene ({frames['workbench']:.3f} s).", ""]
    return "\n".join(lines)


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="markdown file to write")
    parser.add_argument("--images", type=Path, default=Path("/tmp/refraction_search"),
                        help="folder for Workbench's frames")
    parser.add_argument("--width", type=int, default=480)
    parser.add_argument("--height", type=int, default=320)
    parser.add_argument("--points", type=int, default=1000)
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--quick", action="store_true", help="small: 160x120, 600 points, 4 frames")
    args = parser.parse_args(argv)
    if args.quick:
        args.width, args.height, args.points, args.frames = 160, 120, 600, 4
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    bench_sbc.import_package_on_gpu()
    args.images.mkdir(parents=True, exist_ok=True)
    rows = [measure_accuracy(*glass, args.width, args.height, args.points) for glass in _glasses()]
    frames = measure_frames(args.width, args.height, args.frames, args.images)
    text = report(rows, frames, bench_draw.command_line("bench_refraction_search.py", argv), bench_draw._machine(),
                  (args.width, args.height))
    return bench_draw.write_report(args.out, text)


if __name__ == "__main__":
    sys.exit(main())
