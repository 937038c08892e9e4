# SPDX-License-Identifier: GPL-3.0-or-later
"""Every image of a folded mirror (issue 44, ``engine/methods/iterative/fold_patches.py``):
what the GPU search for every image finds against the exact solver, beside the search for
one image per point, and what each costs.

    .venv/bin/python tests/benchmarks/bench_fold_search.py   # docs/benchmarks/fold_search.md
    .venv/bin/python tests/benchmarks/bench_fold_search.py --quick --out /tmp/fold_search.md

Four star-shaped mirrors of ``tools/mirror_family.py`` that fold their reflections: the
star ball and the dented sphere of the tuning half, the 3 x 6 bumpy ball and the
hammered sphere of the held-out half. Each mirror's map is baked on the GPU as the
add-on bakes it (faces of 256); points scattered between 1.25 and 3 radii of its centre
are searched on the GPU in a view from each of three eyes and solved exactly
(``engine/reference/exact.py``). Only the answers the picture shows count
(``spot_check.shown_answers``, the fragment stage's tests). *Coverage*: the exact visible
images with a shown answer of their point within a pixel; *p99*: of the shown answers'
distances to their point's nearest exact image; *unmatched*: shown answers more than a
pixel from every exact image of their point. Search time: median of 3 cold searches of
the points on the GPU, read back included, per thousand points.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_draw  # noqa: E402  (same folder: machine facts, command line, report)
import bench_sbc  # noqa: E402  (same folder: package import)

DEFAULT_OUT = bench_sbc.REPO_ROOT / "docs" / "benchmarks" / "fold_search.md"
#: Issue 44's bars against the exact solver.
TARGET_P99_PX, TARGET_COVERAGE = 1.0, 0.99
MIRRORS = (("star_ball", "tuning"), ("dented_sphere", "tuning"), ("bumpy_ball_3_6", "held out"),
           ("hammered_sphere", "held out"))
EYES = ((3.2, -2.4, 1.5), (-1.5, 3.3, 2.2), (0.8, 1.0, -3.5))


def _mirror(name: str):
    from curved_reflections.engine.scene import Reflector
    from curved_reflections.tools import mirror_family

    shape = {"star_ball": lambda: mirror_family.bumpy_ball(0.12, (5, 4)),
             "bumpy_ball_3_6": lambda: mirror_family.bumpy_ball(0.18, (3, 6)),
             "dented_sphere": mirror_family.dented_sphere, "hammered_sphere": mirror_family.hammered_sphere}[name]()
    return Reflector(name, shape.vertices, shape.triangles, shape.normals)


def _points(count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return direction * rng.uniform(1.25, 3.0, (count, 1))


def _gpu_answers(reflector, rmap, view, points, repeats: int = 3) -> tuple[np.ndarray, np.ndarray, float]:
    """The points in the renderer's order (it sorts its vertices), the (K, P, 3) answers of
    the GPU search in ``view`` (NaN: none) and the median seconds of a cold search, read
    back included."""
    from curved_reflections.drawing.draw_geometry import prepare_geometry
    from curved_reflections.drawing.methods.iterative_draw import IterativePass
    from curved_reflections.engine.methods.iterative import IterativeReflector
    from curved_reflections.engine.scene import DiffuseMesh

    mesh = DiffuseMesh("points", points, np.arange(len(points) - len(points) % 3).reshape(-1, 3),
                       np.ones((len(points), 4)))
    geometry = prepare_geometry([reflector], [mesh], edge_fraction=None)
    search = IterativePass(geometry, [IterativeReflector(0, reflector.name, rmap)])
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        search.search(view)
        slots = [points for points, _ in search.meshes.read_slots(search.answers()[0].texture)]
        times.append(time.perf_counter() - start)
    return geometry.vertices, np.stack(slots), float(np.median(times))


def _compare(reflector_set, view, points, answers) -> dict:
    from curved_reflections.drawing.frame_pass import FramePass
    from curved_reflections.drawing.reflected_meshes import REFLECTION_COSINE
    from curved_reflections.engine.reference.exact import solve_reflections
    from curved_reflections.engine.spot_check import shown_answers

    shown = shown_answers(reflector_set, view, 0, points, answers, REFLECTION_COSINE, FramePass.hidden_fraction)
    exact = solve_reflections(reflector_set, view, points)
    pixels, owner = exact.pixel[exact.visible], exact.point[exact.visible]
    covered = np.zeros(len(pixels), dtype=bool)
    errors, unmatched = [], 0
    for slot, point in zip(*np.nonzero(np.isfinite(shown[..., 0]))):
        at, _ = view.to_pixels(shown[slot, point][None])
        distance = np.linalg.norm(pixels[owner == point] - at[0], axis=1)
        if len(distance) == 0 or distance.min() > 1.0:
            unmatched += 1
            continue
        errors.append(distance.min())
        covered[np.flatnonzero(owner == point)[np.argmin(distance)]] = True
    return {"images": len(pixels), "covered": int(covered.sum()), "errors": errors, "unmatched": unmatched,
            "answers": int(np.isfinite(shown[..., 0]).sum())}


def measure(name: str, kind: str, width: int, height: int, n_points: int) -> dict:
    from curved_reflections.drawing.methods.iterative_bake import bake_reflector_map_gpu
    from curved_reflections.engine.geometry.raytrace import ReflectorSet
    from curved_reflections.engine.methods.iterative import check_star_shaped
    from curved_reflections.engine.methods.iterative.fold_patches import folded
    from curved_reflections.engine.view import look_at_view

    reflector = _mirror(name)
    reflector_set = ReflectorSet([reflector])
    start = time.perf_counter()
    shape = check_star_shaped(reflector, reflector_set)
    plain = bake_reflector_map_gpu(reflector, shape.centre, 256).reflector_map
    every = folded(plain)
    prepare = time.perf_counter() - start
    one = dataclasses.replace(every, patches=None, images=1)
    row = {"name": name, "kind": kind, "patches": len(every.patches) if every.patches is not None else 0,
           "prepare": prepare}
    for label, rmap in (("every", every), ("one", one)):
        totals = {"images": 0, "covered": 0, "errors": [], "unmatched": 0, "answers": 0, "seconds": []}
        for k, eye in enumerate(EYES):
            view = look_at_view(eye, (0.0, 0.0, 0.0), width=width, height=height)
            points, answers, seconds = _gpu_answers(reflector, rmap, view, _points(n_points, 11 + k))
            found = _compare(reflector_set, view, points, answers)
            for key in ("images", "covered", "unmatched", "answers"):
                totals[key] += found[key]
            totals["errors"] += found["errors"]
            totals["seconds"].append(seconds)
        row[label] = {"coverage": totals["covered"] / max(totals["images"], 1), "images": totals["images"],
                      "p99": float(np.percentile(totals["errors"], 99)) if totals["errors"] else float("nan"),
                      "unmatched": totals["unmatched"], "answers": totals["answers"],
                      "ms_per_1000": 1000.0 * float(np.median(totals["seconds"])) * 1000.0 / n_points}
        print(f"[bench_fold_search] {name} {label}: {row[label]}", flush=True)
    return row


def report(rows: list, command: str, machine: str, size: tuple, n_points: int) -> str:
    lines = ["# Every image of a folded mirror: the search against the exact solver", "",
             f"Command: `{command}`", "", f"Machine: {machine}", "",
             f"{n_points:,} points around each mirror in a {size[0]}x{size[1]} view from each of {len(EYES)} eyes; "
             f"targets (issue 44): coverage >= {100 * TARGET_COVERAGE:g} % of the exact images, p99 <= "
             f"{TARGET_P99_PX:g} px. *Every image*: the search from each of the map's patches (Render Image, "
             "Iterative mode); *one image*: the search from one guess (the live view in Auto). *Patches*: the "
             "folded map's starts; *prepare*: star check, GPU bake and patches. ms: a cold GPU search per "
             "thousand points, read back included (llvmpipe).", "",
             "| mirror | set | patches | exact images | coverage: every / one | p99 px: every / one | "
             "unmatched: every / one | ms per 1,000 points: every / one | prepare s |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        every, one = r["every"], r["one"]
        lines.append(f"| {r['name']} | {r['kind']} | {r['patches']:,} | {every['images']:,} | "
                     f"**{100 * every['coverage']:.1f} %** / {100 * one['coverage']:.1f} % | "
                     f"**{every['p99']:.2f}** / {one['p99']:.2f} | {every['unmatched']} / {one['unmatched']} | "
                     f"{every['ms_per_1000']:.0f} / {one['ms_per_1000']:.0f} | {r['prepare']:.1f} |")
    lines.append("")
    return "\n".join(lines)


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="markdown file to write")
    parser.add_argument("--width", type=int, default=480)
    parser.add_argument("--height", type=int, default=320)
    parser.add_argument("--points", type=int, default=600, help="points per view")
    parser.add_argument("--quick", action="store_true", help="small: 160x120, 120 points")
    args = parser.parse_args(argv)
    if args.quick:
        args.width, args.height, args.points = 160, 120, 120
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    bench_sbc.import_package_on_gpu()
    rows = [measure(name, kind, args.width, args.height, args.points) for name, kind in MIRRORS]
    text = report(rows, bench_draw.command_line("bench_fold_search.py", argv), bench_draw._machine(),
                  (args.width, args.height), args.points)
    return bench_draw.write_report(args.out, text)


if __name__ == "__main__":
    sys.exit(main())
