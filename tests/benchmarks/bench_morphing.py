# SPDX-License-Identifier: GPL-3.0-or-later
"""Measured figures of reflection morphing (SBC paper VI; issue #5): projection error
against the exact solver as a function of grid spacing, and the bake of a 9x9x5 grid.

    .venv/bin/python tests/benchmarks/bench_morphing.py --out docs/benchmarks
    .venv/bin/python tests/benchmarks/bench_morphing.py --out /tmp/bench --quick    # ~1 minute
    .venv/bin/python tests/benchmarks/bench_morphing.py --out /tmp/bench --bake-only    # the 9x9x5 bake alone
    .venv/bin/python tests/benchmarks/bench_morphing.py --out /tmp/bench --grids 9,9,5    # one grid's error

Scene: the ``sbc_fig3`` demo (mirror sphere of radius 1 on a tiled floor among columns),
built with bpy and captured from the evaluated depsgraph, as ``bench_sbc.py`` does; its
scene box and point sampler (box, diffuse meshes, near the mirror) are reused from there.

Error sweep: grids of several node counts over the same box (the mirror's box grown by
``morph_margin`` = 1 mirror size, the default), so the spacing varies. Views: eyes drawn
at random (fixed seed) inside the grid, above the floor and at least ``--min-eye-distance``
from the sphere's centre, looking at the centre (jittered), 480x320, 45 degrees; the same
views for every grid. Per view, fresh points; the exact solver (``engine/reference/exact.py``) gives
the visible reflections. Only the nodes of the views' tetrahedra are built (lazily; the
error does not depend on the others). Both blends: the paper's barycentric blend of the
four first reflector points (``linear``) and ours (``surface``: the blend refined on a
quadric fitted to the images and normals of the eight nodes of the tetrahedron's cube).
Error: desired-view pixel
distance from each projected image to the exact visible reflection; coverage: share of
exact visible reflections that are projected; false: projected images with no exact
visible reflection. Projection rate: a second ``project`` call (nodes already in memory),
and a third with ``static_key`` (the paper's reuse of static vertices' four projections).

Bake: the whole default grid (9x9x5 nodes, default face resolution) baked with
``--processes`` worker processes into a temporary folder: wall time, the CPU time summed
over nodes, the largest resident set (parent or any worker), bytes in memory and on disk.
The machine is shared with other work; its load average is recorded with the bake.
"""

from __future__ import annotations

import argparse
import datetime
import functools
import importlib.util
import json
import math
import os
import resource
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO_ROOT = HERE.parents[1]
WIDTH, HEIGHT, FOV = 480, 320, 45.0
#: The blends measured: the paper's (linear), ours (surface: refined on the fitted
#: quadric), and ours with each frame's images polished on the mirror (polished,
#: ``MorphingGrid.polish_frames``: *Polish Every Frame*, the default).
BLENDS = ("linear", "surface", "polished")
SEED = 20061101
#: Coverage is also reported for exact reflections seen at most acos(0.3) = 72.5 degrees
#: off the mirror's normal: the sphere's rim, where grazing reflections crowd, is a band a
#: cell or two wide in every node's ray map, where no four rays surround a point.
FACING_COS = 0.3


def _bench_sbc():
    spec = importlib.util.spec_from_file_location("bench_sbc", HERE / "bench_sbc.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["bench_sbc"] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


B = _bench_sbc()


def _log(text: str) -> None:
    print(f"[bench_morphing {time.strftime('%H:%M:%S')}] {text}", flush=True)


def sphere_scene(n_points: int):
    """The sbc_fig3 demo: its mirror (world), the mirror's object matrix, box and a point sampler."""
    import bpy

    name, _, reflectors, view, bounds, _, _ = B.demo_scene("sbc_fig3", 100)
    mirror = reflectors[0]
    matrix = np.array(bpy.data.objects[mirror.name].matrix_world, dtype=np.float64)
    from curved_reflections.blender import capture

    meshes = capture.capture_scene(bpy.context.evaluated_depsgraph_get()).meshes
    return mirror, matrix, bounds, meshes


def draw_views(morphing, mirror, matrix, settings, count, min_distance, rng):
    """Eyes inside the default grid (in world space), above the floor, away from the mirror."""
    from curved_reflections.engine import look_at_view
    from curved_reflections.engine.methods.morphing import morph_grid

    frame = morph_grid.rigid_frame(matrix)
    local = morph_grid.reflector_in_frame(mirror, frame)
    grid = morph_grid.grid_for(local, settings)
    centre = mirror.vertices.mean(axis=0)
    views = []
    while len(views) < count:
        eye = morph_grid.from_frame(frame, rng.uniform(grid.lo, grid.hi)[None])[0]
        if eye[2] < 0.3 or np.linalg.norm(eye - centre) < min_distance:
            continue
        target = centre + rng.normal(scale=0.2, size=3)
        views.append(look_at_view(eye, target, width=WIDTH, height=HEIGHT, fov_y_deg=FOV, name=f"view{len(views)}"))
    return views


def measure_grid(grid_on_demand, mirror, matrix, settings, views, view_points, exact, args) -> dict:
    """Error, coverage and rates of one grid shape over all views, for both blends;
    ``grid_on_demand(local reflector, settings, blend=, nodes=)`` makes the grid
    (``morphing.grid_on_demand``, or the octree grid's of ``bench_octree.py``)."""
    from curved_reflections.engine.methods.morphing import morph_grid, morphing
    from curved_reflections.engine.geometry.raytrace import ReflectorSet

    frame = morph_grid.rigid_frame(matrix)
    local = morph_grid.reflector_in_frame(mirror, frame)
    reflector_set_world = ReflectorSet([mirror])
    nodes = None
    grid = morph_grid.grid_for(local, settings)
    cell = {"grid": list(settings.grid), "spacing": [float(x) for x in grid.spacing], "blends": {}}
    fallbacks = 0
    for blend in BLENDS:
        morph = grid_on_demand(local, settings, blend="linear" if blend == "linear" else "surface", nodes=nodes)
        nodes = morph.nodes
        morph.polish_frames = blend == "polished"
        if blend == "polished" and morph.mirror is None:
            continue  # nothing to polish on: the nodes' images are not polished either
        errors, covered, n_exact, projected, false, remedies, rates, static_rates = [], 0, 0, 0, 0, {}, [], []
        covered_facing, n_facing, false_on_mirror, off_image = 0, 0, 0, 0
        facing_errors = []
        for view, points, found in zip(views, view_points, exact):
            try:
                result = morph.project(points, view, matrix=matrix)
            except morphing.ViewOutsideGrid:
                fallbacks += blend == "linear"
                continue
            start = time.perf_counter()
            result = morph.project(points, view, matrix=matrix)
            rates.append(len(points) / (time.perf_counter() - start))
            morph.project(points, view, matrix=matrix, static_key="bench")
            start = time.perf_counter()
            morph.project(points, view, matrix=matrix, static_key="bench")
            static_rates.append(len(points) / (time.perf_counter() - start))
            pixel = np.full((len(points), 2), np.nan)
            pixel[found.point] = found.pixel
            has = np.isfinite(pixel[:, 0])
            n_exact += int(has.sum())
            to_eye = view.eye - found.position
            incidence = np.einsum("pd,pd->p", found.normal, to_eye) / np.linalg.norm(to_eye, axis=1)
            facing = np.zeros(len(points), dtype=bool)
            facing[found.point[incidence >= FACING_COS]] = True
            n_facing += int(facing.sum())
            any_image = np.zeros(len(points), dtype=bool)
            for k in range(result.valid.shape[0]):
                valid = result.valid[k]
                both = valid & has
                # Morphing also places points beyond the image's edges (their triangles may
                # still reach into it); the exact solver calls those not in view.
                with np.errstate(invalid="ignore"):
                    on_image = np.all((result.pixels[k] >= 0) & (result.pixels[k] <= [view.width, view.height]),
                                      axis=1)
                off_image += int((valid & ~on_image).sum())
                valid = valid & on_image
                errors.append(nearest_exact_error(found, np.flatnonzero(both), result.pixels[k][both]))
                facing_errors.append(errors[-1][facing[both]])
                projected += int(valid.sum())
                wrong = np.flatnonzero(valid & ~has)
                false += len(wrong)
                if len(wrong):  # a false image off the mirror's footprint is masked away when drawing
                    origins, directions = view.pixel_rays(result.pixels[k][wrong])
                    false_on_mirror += int(reflector_set_world.intersect(origins, directions).hit.sum())
                any_image |= valid
                for code, label in ((1, "all_nodes"), (2, "extended_frustum"), (3, "partial")):
                    remedies[label] = remedies.get(label, 0) + int((result.remedy[k][valid] == code).sum())
            covered += int((any_image & has).sum())
            covered_facing += int((any_image & facing).sum())
        error = np.concatenate(errors) if errors else np.zeros(0)
        p = np.percentile(error, [50, 95, 99]) if len(error) else [math.nan] * 3
        cell["blends"][blend] = {
            "n_views": len(rates), "n_compared": int(len(error)), "error_p50": float(p[0]), "error_p95": float(p[1]),
            "error_p99": float(p[2]), "error_max": float(error.max()) if len(error) else math.nan,
            "error_p99_facing": float(np.percentile(np.concatenate(facing_errors), 99)) if errors else math.nan,
            "coverage": covered / max(n_exact, 1), "false_rate": false / max(projected, 1),
            "coverage_facing": covered_facing / max(n_facing, 1),
            "false_on_mirror_rate": false_on_mirror / max(projected, 1),
            "off_image": off_image,
            "remedies": {k: v / max(projected, 1) for k, v in remedies.items()},
            "points_per_second": float(np.median(rates)) if rates else math.nan,
            "static_points_per_second": float(np.median(static_rates)) if static_rates else math.nan,
        }
    cell["views_outside"] = fallbacks
    cell["nodes_built"] = len(nodes)
    cell["node_cpu_seconds_mean"] = nodes.cpu_seconds / max(len(nodes), 1)
    return cell


def headline(blends: dict) -> dict:
    """The figures of what the product draws by default: the polished blend (*Polish
    Every Frame*) where measured, else the surface blend."""
    return blends.get("polished", blends["surface"])


def nearest_exact_error(found, points: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """(R,) px from each of ``pixels`` (R, 2), an image of the point ``points`` (R,), to
    the nearest exact visible reflection of that point in ``found``. A point a mirror
    shows two or three times (a rippled mirror) has as many exact images, and an image
    is measured against its own, not against whichever the solver listed last."""
    order = np.argsort(found.point, kind="stable")
    listed, listed_pixels = found.point[order], found.pixel[order]
    first, last = np.searchsorted(listed, points, "left"), np.searchsorted(listed, points, "right")
    error = np.full(len(points), np.inf)
    for k in range(int((last - first).max()) if len(points) else 0):  # images per point: a few at most
        has = first + k < last
        distance = np.linalg.norm(pixels[has] - listed_pixels[first[has] + k], axis=1)
        error[has] = np.minimum(error[has], distance)
    return error


def measure_bake(morphing, bake, mirror, matrix, settings, processes) -> dict:
    folder = Path(tempfile.mkdtemp(prefix="bench_morphing_"))
    load_before = os.getloadavg()
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    try:
        result = bake.bake_grid(mirror, matrix, settings, folder, processes=processes)
        own_after, children_after = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
        disk = sum(p.stat().st_size for p in result.directory.iterdir())
    finally:
        subprocess.run(["rm", "-rf", str(folder)], check=False)
    built = result.node_cpu_seconds > 0
    return {"grid": list(settings.grid), "face_resolution": settings.face_resolution, "processes": result.processes,
            "seconds": result.seconds, "cpu_seconds": float(result.node_cpu_seconds.sum()),
            "node_cpu_p50": float(np.median(result.node_cpu_seconds[built])),
            "node_cpu_max": float(result.node_cpu_seconds.max()), "n_nodes": result.n_nodes,
            # Whole processes: the workers' CPU includes writing the node files, the parent's the rest.
            "worker_cpu_seconds": _cpu(children_after) - _cpu(children), "parent_cpu_seconds": _cpu(own_after) - _cpu(own),
            "peak_rss_mb": result.peak_rss_mb, "memory_mb": result.nbytes / 2**20, "disk_mb": disk / 2**20,
            "load_before": list(load_before), "load_after": list(os.getloadavg())}


def _cpu(usage) -> float:
    return usage.ru_utime + usage.ru_stime


def _f(value, digits=2):
    return "n/a" if value is None or (isinstance(value, float) and not math.isfinite(value)) else f"{value:.{digits}f}"


def report(results: dict) -> str:
    m, args = results["machine"], results["settings"]
    lines = [
        "# Reflection morphing: measured figures (issue #5)", "",
        "Written by `tests/benchmarks/bench_morphing.py`; every number below comes from the run it describes.", "",
        "## Machine and command", "",
        f"- Machine: {m['cpu']}, {m['cores']} cores, {m['memory_gb']:.0f} GB, {m['platform']}; shared with "
        "other work (load averages below), so times vary between runs.",
        f"- Python {m['python']}, numpy {m['numpy']}, bpy {m['bpy']}.",
        f"- Command: `{results['command']}`",
        f"- Code: commit `{results['code']['commit'][:12]}`"
        + (f", uncommitted changes in {len(results['code']['uncommitted'])} engine files"
           if results["code"]["uncommitted"] else ", no uncommitted changes in the extension's code") + ".",
        f"- Started {results['started']}, total run time {results['total_seconds'] / 60:.1f} min.", "",
        "## What is measured", "",
        f"Scene `sbc_fig3` (mirror sphere, radius 1). {args['views']} views drawn at random inside the grid box "
        f"(above the floor, eye at least {args['min_eye_distance']} from the sphere's centre), {WIDTH}x{HEIGHT} px, "
        f"{FOV:.0f} degrees, {args['points']} points each (box, diffuse meshes, near the mirror). Cube faces "
        f"{args['face_resolution']} px, accuracy {args['accuracy_px']} face px. *linear*: the paper's barycentric "
        "blend of the four "
        "first reflector points; *surface*: ours, the blend refined on a quadric fitted to the images and normals "
        "of the eight nodes of the tetrahedron's cube (`refine_on_local_surface`)"
        + ("; the nodes' images polished on the mirror (*Polish Node Images*, the "
           "default; `image_polish.py`)" if args.get("polish", True) else "; the nodes' images as their cameras "
           "give them (*Polish Node Images* off)")
        + ("; *polished*: the surface blend's images each polished on the mirror from where the blend put them "
           "(*Polish Every Frame*, the default; `MorphingGrid.polish_frames`)" if args.get("polish", True) else "")
        + ". Error: desired-view px from each projected image to the exact "
        "visible reflection (`engine/reference/exact.py`). Coverage: exact visible reflections that are projected; "
        "in parentheses, those seen less than 72.5 degrees off the mirror's normal (the rim of the sphere, a cell or "
        "two wide in every node's ray map, reflects much of the scene at grazing angles and is not projected). "
        "False: projected images inside the image with no exact visible reflection; in parentheses those whose "
        "pixel lies on the mirror (the draw masks the others away). Images placed beyond the image's edges are "
        "not counted as projected (morphing places them; a runtime SBC cannot). "
        "Remedies: share of projected images blended from all four nodes, with an extended leaf frustum at some "
        "node, or from fewer nodes (partial). Rates: points/s of `project` with the nodes in memory; static: "
        "with the four projections reused (same tetrahedron).", "",
        "## Error against grid spacing", "",
        "| grid | spacing x/y/z | blend | views | compared | p50 / p95 / p99 / max px | coverage % (facing) "
        "| false % (on the mirror) "
        "| all / extended / partial % | k pts/s | static k pts/s |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for cell in results["sweep"]:
        for blend, b in cell["blends"].items():
            r = b["remedies"]
            lines.append(
                f"| {'x'.join(map(str, cell['grid']))} | {' / '.join(_f(s) for s in cell['spacing'])} | {blend} "
                f"| {b['n_views']} | {b['n_compared']} | {_f(b['error_p50'])} / {_f(b['error_p95'])} / "
                f"{_f(b['error_p99'])} / {_f(b['error_max'])} | {_f(100 * b['coverage'], 1)} "
                f"({_f(100 * b['coverage_facing'], 1)}) "
                f"| {_f(100 * b['false_rate'], 2)} ({_f(100 * b['false_on_mirror_rate'], 2)}) "
                f"| {_f(100 * r.get('all_nodes', 0), 1)} / "
                f"{_f(100 * r.get('extended_frustum', 0), 1)} / {_f(100 * r.get('partial', 0), 1)} "
                f"| {_f(b['points_per_second'] / 1e3, 0)} | {_f(b['static_points_per_second'] / 1e3, 0)} |")
    lines += ["", "Views outside a grid's usable tetrahedra (runtime fallback): "
              + ", ".join(f"{'x'.join(map(str, c['grid']))}: {c['views_outside']}" for c in results["sweep"]) + ".",
              "Mean CPU time per node built in the sweep: "
              + ", ".join(f"{'x'.join(map(str, c['grid']))}: {_f(c['node_cpu_seconds_mean'])} s"
                          for c in results["sweep"]) + ".", ""]
    bake = results["bake"]
    lines += [
        f"## Bake of a {'x'.join(map(str, bake['grid']))} grid", "",
        "| nodes | face px | processes | wall s | CPU s (sum over nodes) | node CPU s p50 / max | peak RSS MB "
        "| arrays MB | disk MB | load avg before / after |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        f"| {bake['n_nodes']} | {bake['face_resolution']} | {bake['processes']} | {_f(bake['seconds'], 1)} "
        f"| {_f(bake['cpu_seconds'], 1)} | {_f(bake['node_cpu_p50'])} / {_f(bake['node_cpu_max'])} "
        f"| {_f(bake['peak_rss_mb'], 0)} | {_f(bake['memory_mb'], 1)} | {_f(bake['disk_mb'], 1)} "
        f"| {_f(bake['load_before'][0])} / {_f(bake['load_after'][0])} |", "",
        "## What the numbers show", "", summary(results), ""]
    return "\n".join(lines)


def summary(results: dict) -> str:
    default = next((c for c in results["sweep"] if c["grid"] == results["settings"]["default_grid"]), None)
    bake = results["bake"]
    out = []
    if default is not None:
        s, lin = headline(default["blends"]), default["blends"]["linear"]
        out.append(f"- At the default grid ({'x'.join(map(str, default['grid']))}, spacing "
                   f"{' / '.join(_f(x) for x in default['spacing'])}): p95 {_f(s['error_p95'])} px with the "
                   f"{'polished ' if 'polished' in default['blends'] else ''}surface refinement (target p95 <= 1 px: {'met' if s['error_p95'] <= 1 else '**not met**'}), "
                   f"{_f(lin['error_p95'])} px with the paper's linear blend; coverage {_f(100 * s['coverage'], 1)} %.")
        out.append(f"- p99 {_f(s['error_p99'])} px (issue 17's target p99 <= 1 px: "
                   f"{'met' if s['error_p99'] <= 1 else '**not met**'}); over the reflections seen less than 72.5 "
                   f"degrees off the mirror's normal (the coverage's *facing*; the others are the sphere's rim, where a "
                   f"reflection point moves fastest with the normal), p99 {_f(s['error_p99_facing'])} px.")
    ideal = bake["cpu_seconds"] / max(bake["processes"], 1)
    out.append(f"- Bake: {_f(bake['seconds'], 1)} s wall on {bake['processes']} processes (goal < 60 s: "
               f"{'met' if bake['seconds'] < 60 else '**not met**'}); the nodes' CPU time, "
               f"{_f(bake['cpu_seconds'], 1)} s, divided by the processes is {_f(ideal, 1)} s, what an otherwise idle "
               f"machine would take; the load average was {_f(bake['load_before'][0])} when it started.")
    return "\n".join(out)


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "benchmarks")
    parser.add_argument("--grids", nargs="+", default=["5,5,3", "9,9,5", "13,13,7"])
    parser.add_argument("--views", type=int, default=8)
    parser.add_argument("--points", type=int, default=6000)
    parser.add_argument("--min-eye-distance", type=float, default=1.5)
    parser.add_argument("--face-resolution", type=int, default=None, help="default: MorphSettings' default")
    parser.add_argument("--accuracy", type=float, default=None, help="leaf accuracy in cube-face pixels "
                        "(default: MorphSettings' default)")
    parser.add_argument("--bake-grid", default="9,9,5")
    parser.add_argument("--processes", type=int, default=2)
    parser.add_argument("--no-polish", dest="polish", action="store_false", help="leave the nodes' regular and "
                        "extended images as their cameras give them (the scene's Polish Node Images off; on by "
                        "default)")
    parser.add_argument("--bake-only", action="store_true", help="measure the bake alone (no error sweep, no "
                        "exact solve); writes morphing_bake.json and leaves morphing.md as it is")
    parser.add_argument("--quick", action="store_true", help="smallest run: grids 3x3x2 and 5x5x3, 2 views, "
                        "1500 points, face 32 px, a 3x3x2 bake")
    args = parser.parse_args(argv)
    if args.quick:
        args.grids, args.views, args.points, args.bake_grid = ["3,3,2", "5,5,3"], 2, 1500, "3,3,2"
        args.face_resolution = args.face_resolution or 32
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(argv)
    started = time.perf_counter()
    args.out.mkdir(parents=True, exist_ok=True)
    B.import_package()
    from curved_reflections.engine.baking import bake
    from curved_reflections.engine.methods.morphing import morph_grid, morphing
    from curved_reflections.engine.reference.exact import solve_reflections
    from curved_reflections.engine.geometry.raytrace import ReflectorSet

    face = args.face_resolution or morph_grid.MorphSettings.face_resolution
    accuracy = args.accuracy or morph_grid.MorphSettings.accuracy_px
    settings_for = {g: morph_grid.MorphSettings(grid=tuple(int(n) for n in g.split(",")), face_resolution=face,
                                              accuracy_px=accuracy)
                    for g in args.grids + [args.bake_grid]}
    mirror, matrix, bounds, meshes = sphere_scene(args.points)
    if args.bake_only:
        bake_result = measure_bake(morphing, bake, mirror, matrix, settings_for[args.bake_grid], args.processes)
        bake_result.update(command=" ".join([".venv/bin/python", "tests/benchmarks/bench_morphing.py"]
                                            + [shlex.quote(a) for a in argv]), machine=B._machine(),
                           code=B._code_version(REPO_ROOT), total_seconds=time.perf_counter() - started)
        (args.out / "morphing_bake.json").write_text(json.dumps(B._jsonable(bake_result), indent=1) + "\n")
        _log(f"bake {args.bake_grid}: {bake_result['seconds']:.1f} s wall, {bake_result['cpu_seconds']:.1f} s CPU, "
             f"peak RSS {bake_result['peak_rss_mb']:.0f} MB; wrote {args.out / 'morphing_bake.json'}")
        return 0
    rng = np.random.default_rng(SEED)
    default = morph_grid.MorphSettings()
    views = draw_views(morphing, mirror, matrix, default, args.views, args.min_eye_distance, rng)
    reference = ReflectorSet([mirror])
    view_points, exact = [], []
    for view in views:
        points, _ = B.make_points("sbc_fig3", [mirror], meshes, bounds, args.points, rng)
        found = solve_reflections(reference, view, points)
        view_points.append(points)
        exact.append(found.select(found.visible))
    _log(f"{len(views)} views, exact reflections solved")
    results = {
        "command": " ".join([".venv/bin/python", "tests/benchmarks/bench_morphing.py"]
                            + [shlex.quote(a) for a in argv]),
        "started": datetime.datetime.now().isoformat(timespec="seconds"),
        "machine": B._machine(), "code": B._code_version(REPO_ROOT),
        "settings": {**{k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
                     "face_resolution": face, "accuracy_px": accuracy, "default_grid": list(default.grid)},
        "sweep": [],
    }
    for g in args.grids:
        cell = measure_grid(functools.partial(morphing.grid_on_demand, polish=args.polish), mirror, matrix,
                            settings_for[g], views, view_points, exact, args)
        results["sweep"].append(cell)
        s = headline(cell["blends"])
        _log(f"grid {g}: default blend p50/p95/p99 {s['error_p50']:.2f}/{s['error_p95']:.2f}/{s['error_p99']:.2f} px, "
             f"linear p95 {cell['blends']['linear']['error_p95']:.2f} px")
    results["bake"] = measure_bake(morphing, bake, mirror, matrix, settings_for[args.bake_grid], args.processes)
    _log(f"bake {args.bake_grid}: {results['bake']['seconds']:.1f} s wall, {results['bake']['cpu_seconds']:.1f} s CPU")
    results["total_seconds"] = time.perf_counter() - started
    (args.out / "morphing.json").write_text(json.dumps(B._jsonable(results), indent=1) + "\n")
    (args.out / "morphing.md").write_text(report(results))
    _log(f"wrote {args.out / 'morphing.md'} in {results['total_seconds'] / 60:.1f} min")
    return 0


if __name__ == "__main__":
    sys.exit(main())
