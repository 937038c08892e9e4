# SPDX-License-Identifier: GPL-3.0-or-later
"""Measured figures of second-order reflections (issue #5): the sample-based camera's
order-2 groups against the exact second-order solver, and rendered labels against Cycles.

    .venv/bin/python tests/benchmarks/bench_higher_order.py --out docs/benchmarks
    .venv/bin/python tests/benchmarks/bench_higher_order.py --out /tmp/bench --quick   # ~1-2 minutes

Scene: the two_spheres demo (two mirror spheres 0.18 apart), built with bpy and
captured from the evaluated depsgraph exactly as ``bench_sbc.py`` does (480x320 camera
view, scene box = bounds + 0.1, the same shuffled points: in the box, on the diffuse
meshes, within 0.5 of the mirrors). The exact solver (``tools/exact_paths.py``) finds
every visible path eye -> x1 -> x2 -> p once.

Per down-sampling d (accuracy 1 px, ``max_order=2``), for the histories (A, B) and
(B, A), in all their sheets:

- error: desired-view pixel distance from each projected image to the exact image of
  the same history (nearest, where a point has several);
- coverage: share of exact images whose pixel lies in a ray-map cell at least 3 cells
  inside the group's footprint (eroded by a 3-cell cross) that some sheet projects;
- false rate: share of projected images with no exact visible path of that history.

``--render`` adds the picture-level check at the demo's 320x240: our render
(``blender/render_image.render_scene``) with ``max_order`` 1 and 2 and Cycles with 1
and 8 glossy bounces, against Cycles with 8 bounces, label disagreement
(``tools/metrics.py``) on all reflector pixels and on the second-order footprint (pixels
whose reflected view ray hits the other mirror, from a full-resolution ray map).
Writes OUT/higher_order.md and OUT/higher_order.json.
"""

from __future__ import annotations

import argparse
import datetime
import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_sbc  # noqa: E402  (same folder: scene building, points, machine facts)

HISTORIES = ((0, 1), (1, 0))
FOOTPRINT_EROSION = 3
RENDER_WIDTH, RENDER_HEIGHT = 320, 240


def prepare(n_points: int) -> dict:
    from curved_reflections.tools.exact_paths import solve_second_order
    from curved_reflections.engine.geometry.raytrace import ReflectorSet

    _, _, reflectors, view, bounds, points, counts = bench_sbc.demo_scene("two_spheres", n_points)
    reflector_set = ReflectorSet(reflectors)
    start = time.perf_counter()
    exact = solve_second_order(reflector_set, view, points)
    seconds = time.perf_counter() - start
    exact = exact.select(exact.visible)
    return {"reflectors": reflectors, "reflector_set": reflector_set, "view": view, "bounds": bounds,
            "points": points, "counts": counts, "exact": exact, "exact_seconds": seconds}


def measure_cell(scene: dict, downsample: int, accuracy_px: float = 1.0) -> dict:
    from curved_reflections.engine.methods.sbc import build_sample_based_camera

    sbc = build_sample_based_camera(scene["reflector_set"], scene["view"], scene["bounds"], max_order=2,
                                    downsample=downsample, accuracy_px=accuracy_px)
    start = time.perf_counter()
    projection = sbc.project(scene["points"])
    project_seconds = time.perf_counter() - start
    exact, ray_map, n = scene["exact"], sbc.ray_map, len(scene["points"])
    cell = {"downsample": downsample, "accuracy_px": accuracy_px, "n_rays": sbc.stats["n_rays"],
            "n_leaves": sbc.stats["n_leaves"], "n_sheets": sbc.stats["n_sheets"],
            "build_seconds": sbc.stats["build_seconds"], "trace_seconds": sbc.stats["trace_seconds"],
            "project_seconds": project_seconds, "histories": {}}
    all_errors, totals = [], np.zeros(4, dtype=np.int64)  # well inside, covered, projected, false
    for history in HISTORIES:
        mine = (exact.history[:, 0] == history[0]) & (exact.history[:, 1] == history[1])
        point, pixel = exact.point[mine], exact.pixel[mine]
        has_exact = np.zeros(n, dtype=bool)
        has_exact[point] = True
        sheets = [g for g, h in enumerate(projection.groups) if tuple(h) == history]
        errors, projected, false = [], 0, 0
        projected_any = np.zeros(n, dtype=bool)
        rays = int((ray_map.group == ray_map.histories.index(history)).sum()) if history in ray_map.histories else 0
        for g in sheets:
            valid = projection.valid[g]
            projected_any |= valid
            both = valid[point]
            distance = np.linalg.norm(projection.pixels[g, point[both]] - pixel[both], axis=1)
            nearest = np.full(n, np.inf)
            np.minimum.at(nearest, point[both], distance)
            errors.append(nearest[np.isfinite(nearest)])
            projected += int(valid.sum())
            false += int((valid & ~has_exact).sum())
        if history in ray_map.histories:
            inner = bench_sbc._eroded(ray_map.group_grid(ray_map.histories.index(history)) >= 0, FOOTPRINT_EROSION)
            cells = np.floor(pixel / ray_map.downsample).astype(np.int64)
            cells[:, 0] = np.clip(cells[:, 0], 0, ray_map.columns - 1)
            cells[:, 1] = np.clip(cells[:, 1], 0, ray_map.rows - 1)
            well = inner[cells[:, 1], cells[:, 0]]
        else:
            well = np.zeros(len(point), dtype=bool)
        covered = int(projected_any[point[well]].sum())
        error = np.concatenate(errors) if errors else np.zeros(0)
        cell["histories"]["".join("AB"[r] for r in history)] = {
            "rays": rays, "sheets": len(sheets), "exact_images": int(len(point)), **_stats(error),
            "well_inside": int(well.sum()), "covered": covered, "projected": projected, "false": false}
        all_errors.append(error)
        totals += [int(well.sum()), covered, projected, false]
    error = np.concatenate(all_errors)
    cell.update(_stats(error))
    cell["coverage"] = totals[1] / totals[0] if totals[0] else float("nan")
    cell["false_rate"] = totals[3] / totals[2] if totals[2] else float("nan")
    return cell


def _stats(error: np.ndarray) -> dict:
    if len(error) == 0:
        return {"n_compared": 0, "error_p50": float("nan"), "error_p95": float("nan"),
                "error_p99": float("nan"), "error_max": float("nan")}
    p50, p95, p99 = np.percentile(error, [50, 95, 99])
    return {"n_compared": int(len(error)), "error_p50": float(p50), "error_p95": float(p95),
            "error_p99": float(p99), "error_max": float(error.max())}


# --- rendered labels against Cycles ---------------------------------------------------------


def render_check(images: Path, cycles_samples: int, bounces: int) -> dict:
    """Label disagreement with Cycles (``bounces`` glossy bounces) on the two_spheres demo."""
    import bpy

    from curved_reflections.tools import metrics
    from curved_reflections.engine.methods.sbc.raymap import trace_ray_map
    from curved_reflections.engine.geometry.raytrace import ReflectorSet
    from curved_reflections.engine.scene import scene_bounds
    from curved_reflections.blender import capture, demo_scenes, render_image
    from curved_reflections.blender.png import write_png
    from curved_reflections.tools import reference_render as rr

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.scene.name = "two_spheres"
    scene = demo_scenes.build("two_spheres", bpy.context.scene, RENDER_WIDTH, RENDER_HEIGHT)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    reflector_objects = demo_scenes.reflectors(scene)
    palette = demo_scenes.palette(scene)
    images.mkdir(parents=True, exist_ok=True)
    mask, _ = rr.render_mask(scene, images / "mask.png", reflector_objects)
    reference = rr.render_cycles(scene, images / f"cycles_{bounces}.png", cycles_samples, bounces)
    single = rr.render_cycles(scene, images / "cycles_1.png", cycles_samples, 1)

    # Second-order footprint: pixels whose reflected view ray meets the other mirror.
    captured = capture.capture_scene(depsgraph)
    view = capture.view_from_camera(scene.camera, scene, depsgraph)
    ray_map = trace_ray_map(ReflectorSet(captured.reflectors), view,
                            scene_bounds(captured.reflectors, captured.meshes, 0.1), downsample=1, max_order=2)
    second = np.zeros(mask.shape, dtype=bool)
    cells = ray_map.cell[ray_map.order == 2]
    second[cells[:, 1], cells[:, 0]] = True
    second &= mask

    rows = {"cycles, 1 glossy bounce": single.image}
    seconds = {}
    for order in (1, 2):
        start = time.perf_counter()
        result = render_image.render_scene(scene, depsgraph, max_order=order)
        path = write_png(images / f"ours_order{order}.png", result.display)
        seconds[order] = time.perf_counter() - start
        rows[f"ours, max_order {order}"] = rr.read_png(path)
    table = []
    for name, image in rows.items():
        table.append({"renderer": name,
                      "all_reflector_px": metrics.label_disagreement(image, reference.image, mask, palette),
                      "second_order_px": metrics.label_disagreement(image, reference.image, second, palette)})
    # Where ours (max_order 2) disagrees on the second-order footprint, and why.
    world = metrics.palette_names(palette).index(demo_scenes.WORLD_KEY)
    ours = metrics.label_image(rows["ours, max_order 2"], palette)
    truth = metrics.label_image(reference.image, palette)
    differ = (ours != truth) & second
    edge = np.zeros_like(second)
    for axis in (0, 1):
        change = np.diff(truth, axis=axis) != 0
        lead = [slice(None)] * 2
        lead[axis] = slice(1, None)
        edge[tuple(lead)] |= change
        lead[axis] = slice(None, -1)
        edge[tuple(lead)] |= change
    causes = {"ours world, reference an object": int((differ & (ours == world) & (truth != world)).sum()),
              "ours an object, reference world": int((differ & (ours != world) & (truth == world)).sum()),
              "another object": int((differ & (ours != world) & (truth != world)).sum()),
              "within 1 px of a reference label edge": int((differ & edge).sum())}
    return {"width": RENDER_WIDTH, "height": RENDER_HEIGHT, "cycles_samples": cycles_samples, "bounces": bounces,
            "reflector_px": int(mask.sum()), "second_order_px": int(second.sum()), "rows": table,
            "ours_seconds": seconds, "second_order_differing_px": int(differ.sum()), "second_order_causes": causes}


# --- report ----------------------------------------------------------------------------------


def _f(value, digits=3):
    return "n/a" if value is None or value != value else f"{value:.{digits}f}"


def report(results: dict) -> str:
    machine, scene = results["machine"], results["scene"]
    code = results["code"]
    blocks = [
        "# Second-order reflections: measured figures (issue #5)",
        "Written by `tests/benchmarks/bench_higher_order.py`; every number below comes from the run it describes.",
        "## Machine and command",
        "\n".join([
            f"- Machine: {machine['cpu']}, {machine['cores']} cores, shared with other work and noisy; Python "
            f"{machine['python']}, numpy {machine['numpy']}, bpy {machine['bpy']}.",
            f"- Command: `{results['command']}`",
            f"- Code: commit `{code['commit'][:12]}`" + (
                ", with uncommitted changes in " + ", ".join(f"`{f}`" for f in code["uncommitted"])
                if code["uncommitted"] else ", no uncommitted changes in the extension's code") + ".",
            f"- Started {results['started']}, total {results['total_seconds'] / 60:.1f} min."]),
        "## Scene and reference",
        f"two_spheres demo, 480x320 camera view, {scene['n_points']} points ({scene['point_counts']}). "
        f"The exact second-order solver (`tools/exact_paths.py`) found {scene['exact_visible']} visible paths "
        f"({scene['exact_by_history']}) in {scene['exact_seconds']:.1f} s.",
        "## Sample-based camera, order-2 groups (accuracy 1 px, max_order 2)",
    ]
    rows = ["| d | rays (AB / BA) | sheets (all groups) | leaves (all groups) | compared | p50 px | p95 px | p99 px "
            "| max px | coverage | false | build s |",
            "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for cell in results["cells"]:
        h = cell["histories"]
        rows.append(
            f"| {cell['downsample']} | {h['AB']['rays']} / {h['BA']['rays']} | {cell['n_sheets']} | {cell['n_leaves']} "
            f"| {cell['n_compared']} | {_f(cell['error_p50'])} | {_f(cell['error_p95'])} | {_f(cell['error_p99'])} "
            f"| {_f(cell['error_max'])} | {_f(100 * cell['coverage'], 1)} % | {_f(100 * cell['false_rate'], 2)} % "
            f"| {cell['build_seconds']:.2f} |")
    blocks += ["\n".join(rows), "Per history:"]
    rows = ["| d | history | exact images | compared | p50 | p95 | p99 | well inside | covered | projected | false |",
            "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for cell in results["cells"]:
        for name, h in cell["histories"].items():
            rows.append(f"| {cell['downsample']} | {name} | {h['exact_images']} | {h['n_compared']} | "
                        f"{_f(h['error_p50'])} | {_f(h['error_p95'])} | {_f(h['error_p99'])} | {h['well_inside']} | "
                        f"{h['covered']} | {h['projected']} | {h['false']} |")
    blocks.append("\n".join(rows))
    render = results.get("render")
    if render:
        blocks += [
            "## Rendered labels against Cycles",
            f"{render['width']}x{render['height']}, Cycles {render['cycles_samples']} samples with "
            f"{render['bounces']} glossy bounces as the reference; {render['reflector_px']} reflector pixels, "
            f"{render['second_order_px']} of them in the second-order footprint (their reflected view ray meets "
            "the other mirror). Label disagreement: share of those pixels showing another object than the "
            "reference."]
        rows = ["| renderer | all reflector px | second-order px |", "|---|---:|---:|"]
        for row in render["rows"]:
            rows.append(f"| {row['renderer']} | {_f(100 * row['all_reflector_px'], 2)} % | "
                        f"{_f(100 * row['second_order_px'], 2)} % |")
        causes = render["second_order_causes"]
        blocks += ["\n".join(rows),
                   f"Of the {render['second_order_differing_px']} second-order pixels where ours (max_order 2) "
                   "disagrees: " + ", ".join(f"{name} {count}" for name, count in causes.items()) + ".",
                   "Our render times (capture, sample-based camera, drawing, PNG; the first includes shader "
                   "builds): " + ", ".join(f"max_order {k}: {v:.1f} s" for k, v in render["ours_seconds"].items())
                   + "."]
    if results.get("render_error"):
        blocks += ["## Rendered labels against Cycles", "Rendering failed:\n\n```\n" + results["render_error"] + "```"]
    blocks += ["## Targets (issue #5)", "\n".join(_targets(results))]
    return "\n\n".join(blocks) + "\n"


def _targets(results: dict) -> list:
    """One line per done-means target, computed from the numbers above."""
    lines = []
    for cell in results["cells"]:
        p95 = cell["error_p95"]
        lines.append(f"- p95 <= 1 px against the exact second-order solver at d = {cell['downsample']}: "
                     f"{_f(p95)} px, {'met' if p95 <= 1.0 else 'NOT met'}.")
    render = results.get("render")
    if render:
        ours = next(r for r in render["rows"] if r["renderer"] == "ours, max_order 2")
        share = 100 * ours["all_reflector_px"]
        lines.append(f"- Label disagreement with Cycles ({render['bounces']} glossy bounces) <= 3 % on reflector "
                     f"pixels, max_order 2: {_f(share, 2)} %, {'met' if share <= 3.0 else 'NOT met'} "
                     f"({_f(100 * ours['second_order_px'], 2)} % on the second-order footprint).")
    return lines


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=bench_sbc.REPO_ROOT / "docs" / "benchmarks")
    parser.add_argument("--points", type=int, default=4000)
    parser.add_argument("--downsamples", nargs="+", type=int, default=[1, 2, 4])
    parser.add_argument("--render", action="store_true", help="also render and compare with Cycles")
    parser.add_argument("--cycles-samples", type=int, default=16)
    parser.add_argument("--bounces", type=int, default=8)
    parser.add_argument("--images", type=Path, default=None, help="folder for the rendered PNGs (default: a "
                        "temporary folder)")
    parser.add_argument("--quick", action="store_true", help="600 points, d = 4 only, no rendering")
    args = parser.parse_args(argv)
    if args.quick:
        args.points, args.downsamples, args.render = 600, [4], False
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(argv)
    started = time.perf_counter()
    args.out.mkdir(parents=True, exist_ok=True)
    bench_sbc.import_package()
    results = {
        "command": " ".join([".venv/bin/python", "tests/benchmarks/bench_higher_order.py"]
                            + [shlex.quote(a) for a in argv]),
        "started": datetime.datetime.now().isoformat(timespec="seconds"),
        "machine": bench_sbc._machine(), "code": bench_sbc._code_version(bench_sbc.REPO_ROOT),
    }
    bench_sbc._log("two_spheres: scene, points and exact second-order paths")
    scene = prepare(args.points)
    exact = scene["exact"]
    by_history = {"".join("AB"[r] for r in h): int(np.all(exact.history == h, axis=1).sum()) for h in HISTORIES}
    results["scene"] = {"n_points": int(len(scene["points"])), "point_counts": scene["counts"],
                        "exact_visible": int(len(exact.point)), "exact_by_history": by_history,
                        "exact_seconds": scene["exact_seconds"]}
    bench_sbc._log(f"{len(exact.point)} visible paths in {scene['exact_seconds']:.1f} s")
    results["cells"] = []
    for d in args.downsamples:
        results["cells"].append(measure_cell(scene, d))
        bench_sbc._log(f"d={d}: p95 {results['cells'][-1]['error_p95']:.3f} px")
    _write(args.out, results, started)  # the projection figures stand even if rendering fails below
    status = 0
    if args.render:
        import tempfile
        import traceback

        images = args.images or Path(tempfile.mkdtemp(prefix="higher_order_images_"))
        try:
            results["render"] = render_check(images, args.cycles_samples, args.bounces)
            bench_sbc._log(f"render images in {images}")
        except Exception:  # recorded in the report: the projection figures are still worth keeping
            results["render_error"] = traceback.format_exc(limit=3)
            bench_sbc._log(f"rendering failed:\n{results['render_error']}")
            status = 1
        _write(args.out, results, started)
    bench_sbc._log(f"wrote {args.out / 'higher_order.md'}")
    return status


def _write(out: Path, results: dict, started: float) -> None:
    results["total_seconds"] = time.perf_counter() - started
    (out / "higher_order.json").write_text(json.dumps(bench_sbc._jsonable(results), indent=1) + "\n")
    (out / "higher_order.md").write_text(report(results))


if __name__ == "__main__":
    sys.exit(main())
