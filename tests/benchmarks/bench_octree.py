# SPDX-License-Identifier: GPL-3.0-or-later
"""Ray-octree morphing (Martin & Popescu 2004; issue 20) beside the tetrahedral grid
(SBC paper VI), in one run: projection error against the exact solver at views between
the nodes, and the bake's time and memory per node.

    .venv/bin/python tests/benchmarks/bench_octree.py      # docs/benchmarks/octree.md
    .venv/bin/python tests/benchmarks/bench_octree.py --quick --out /tmp/octree.md

Scenes: the ``sbc_fig3`` demo's mirror sphere (with its scene's points, as
``bench_morphing.py``), a held-out ellipsoid (``bench_sbc.ellipsoid_reflector``: radii
1.5 / 0.75 / 0.95, turned; no constant of the octree was chosen on it), a second one
(``bench_sbc.second_ellipsoid``, coarser), and two held-out mirrors that are not
quadrics: a rounded box (``bench_sbc.rounded_box``, a superellipsoid of exponent 4) and
a rippled ellipsoid (``bench_sbc.rippled_ellipsoid``). The blend's local surface is a
quadric, exact on the first three mirrors' shapes. Per scene,
``--views`` eyes drawn at random inside the default grid (9x9x5, margin 1: so between
nodes), away from the mirror, 480x320, 45 degrees, fresh points per view; both kinds of
grid answer the same views and points. Error: desired-view px from each projected image
to the exact visible reflection; coverage as in ``bench_morphing.py`` (in parentheses:
reflections seen at most 72.5 degrees off the normal). Blends: the paper's (*linear*:
barycentric over a tetrahedron, trilinear over a cube) and ours (*surface*: refined on
the quadric fitted to the nodes' images). ``--finer`` grids (default 17x17x9) answer the
same views, to show how the error falls with the cell size.

Bake: each kind's whole default grid, ``--processes`` worker processes, into a temporary
folder: wall and CPU time, per node, and the nodes' arrays in memory and on disk.
"""

from __future__ import annotations

import argparse
import datetime
import functools
import json
import shlex
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import bench_morphing as BM  # noqa: E402  (same folder: views, error and bake measurements)

B = BM.B
REPO_ROOT = HERE.parents[1]
SEED = 20040415
KINDS = ("tetrahedral", "octree")
LABEL = {"tetrahedral": "tetrahedral (SBC VI)", "octree": "ray octree (Martin & Popescu)"}


def _log(text: str) -> None:
    print(f"[bench_octree {time.strftime('%H:%M:%S')}] {text}", flush=True)


def grid_maker(kind: str):
    """``grid_on_demand(local, settings, blend=, nodes=)`` of one kind, as a new scene
    draws it: *Polish Node Images* on, its default."""
    from curved_reflections.engine.methods.morphing import morphing
    from curved_reflections.engine.methods.octree import octree_grid_on_demand

    return functools.partial(octree_grid_on_demand if kind == "octree" else morphing.grid_on_demand, polish=True)


def scenes(n_points: int, quick: bool):
    """(name, mirror (world), object matrix, point sampler) of each scene."""
    mirror, matrix, bounds, meshes = BM.sphere_scene(n_points)
    found = [("sbc_fig3", mirror, matrix, lambda rng: B.make_points("sbc_fig3", [mirror], meshes, bounds,
                                                                     n_points, rng)[0])]
    if not quick:
        found.append(_held_out("ellipsoid (held out)", B.ellipsoid_reflector(np.random.default_rng(SEED)),
                               n_points))
        found.append(_held_out("second ellipsoid (held out)", B.second_ellipsoid(), n_points))
        found.append(_held_out("rounded box (held out, not a quadric)", B.rounded_box(), n_points))
        found.append(_held_out("rippled ellipsoid (held out, not a quadric)",
                               B.rippled_ellipsoid((0.0, 0.0, 1.0), (1.2, 0.8, 0.9), 5, 0.04, lobes=(4, 3),
                                                   name="HeldOutRippled"), n_points))
    return found


def _held_out(name: str, mirror, n_points: int):
    """A scene of ``scenes`` for a mirror alone, its object matrix the identity: points in its
    bounds widened by ``bench_sbc.HELD_OUT_MARGIN``."""
    lo, hi = mirror.bounds
    box = (lo - B.HELD_OUT_MARGIN, hi + B.HELD_OUT_MARGIN)
    return name, mirror, np.eye(4), lambda rng: B.make_points(mirror.name, [mirror], [], box, n_points, rng)[0]


def measure_scene(name, mirror, matrix, sample, settings, args) -> dict:
    from curved_reflections.engine.reference.exact import solve_reflections
    from curved_reflections.engine.geometry.raytrace import ReflectorSet

    rng = np.random.default_rng(SEED)
    views = BM.draw_views(None, mirror, matrix, settings, args.views, args.min_eye_distance, rng)
    reference = ReflectorSet([mirror])
    view_points, exact = [], []
    for view in views:
        points = sample(rng)
        found = solve_reflections(reference, view, points)
        view_points.append(points)
        exact.append(found.select(found.visible))
    _log(f"{name}: {len(views)} views, exact reflections solved")
    out = {"scene": name, "kinds": {}}
    for kind in KINDS:
        out["kinds"][kind] = BM.measure_grid(grid_maker(kind), mirror, matrix, replace(settings, kind=kind), views,
                                             view_points, exact, args)
        s = BM.headline(out["kinds"][kind]["blends"])
        _log(f"{name} {kind}: p50/p95/p99 {s['error_p50']:.2f}/{s['error_p95']:.2f}/{s['error_p99']:.2f} px, "
             f"coverage {100 * s['coverage']:.1f} %")
    out["finer"] = []
    for grid in args.finer:  # the same views: the finer grid spans the same box
        finer = replace(settings, grid=grid)
        out["finer"].append({"grid": list(grid), "kinds": {
            kind: BM.headline(BM.measure_grid(grid_maker(kind), mirror, matrix, replace(finer, kind=kind), views,
                                              view_points, exact, args)["blends"]) for kind in KINDS}})
        _log(f"{name} grid {grid}: octree p99 {out['finer'][-1]['kinds']['octree']['error_p99']:.2f} px")
    return out


def measure_bakes(mirror, matrix, settings, processes) -> dict:
    from curved_reflections.engine.baking import bake
    from curved_reflections.engine.methods.morphing import morphing

    bakes = {}
    for kind in KINDS:
        bakes[kind] = BM.measure_bake(morphing, bake, mirror, matrix, replace(settings, kind=kind), processes)
        _log(f"bake {kind}: {bakes[kind]['seconds']:.1f} s wall, {bakes[kind]['memory_mb']:.1f} MB")
    return bakes


def _f(value, digits=2):
    return BM._f(value, digits)


def report(results: dict) -> str:
    args = results["settings"]
    lines = [
        "# Ray-octree morphing beside the tetrahedral grid (issue 20)", "",
        f"Written by `{results['command']}` ({results['started']}, {results['total_seconds'] / 60:.1f} min) on "
        f"{results['machine']['cpu']}, {results['machine']['cores']} cores; code `{results['code']['commit'][:12]}`"
        + (" with uncommitted changes" if results["code"]["uncommitted"] else "") + ". Every number comes from "
        "this one run.", "",
        f"Grid {'x'.join(map(str, args['grid']))} (margin 1 mirror size), cube faces {args['face_resolution']} px; "
        f"octree depth {args['octree_depth']}. {args['views']} views per scene with eyes drawn at random inside "
        f"the grid (between nodes), {BM.WIDTH}x{BM.HEIGHT} px, {args['points']} points per view. Both kinds answer "
        "the same views and points. *linear*: the papers' blends (barycentric over the eye's tetrahedron, "
        "trilinear over its cube); *surface*: ours, refined on the quadric fitted to the nodes' images; "
        "*polished*: the surface blend's images each polished on the mirror (*Polish Every Frame*, the default, "
        "whose figures the summary gives). "
        "Coverage in parentheses: reflections seen at most 72.5 degrees off the mirror's normal.", "",
        "## Error against the exact solver", "",
        "| scene | grid | blend | views | compared | p50 / p95 / p99 / max px | coverage % (facing) | false % "
        "| k pts/s | static k pts/s |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for scene in results["scenes"]:
        for kind, cell in scene["kinds"].items():
            for blend, b in cell["blends"].items():
                lines.append(
                    f"| {scene['scene']} | {LABEL[kind]} | {blend} | {b['n_views']} | {b['n_compared']} "
                    f"| {_f(b['error_p50'])} / {_f(b['error_p95'])} / {_f(b['error_p99'])} / {_f(b['error_max'])} "
                    f"| {_f(100 * b['coverage'], 1)} ({_f(100 * b['coverage_facing'], 1)}) "
                    f"| {_f(100 * b['false_rate'], 2)} | {_f(b['points_per_second'] / 1e3, 0)} "
                    f"| {_f(b['static_points_per_second'] / 1e3, 0)} |")
    finer = [(scene["scene"], row) for scene in results["scenes"] for row in scene.get("finer", [])]
    if finer:
        lines += ["", "## Finer grids, the same views (polished blend)", "",
                  "| scene | grid | kind | p50 / p95 / p99 / max px | coverage % (facing) |", "|---|---|---|---:|---:|"]
        for name, row in finer:
            for kind, b in row["kinds"].items():
                lines.append(f"| {name} | {'x'.join(map(str, row['grid']))} | {LABEL[kind]} "
                             f"| {_f(b['error_p50'])} / {_f(b['error_p95'])} / {_f(b['error_p99'])} / "
                             f"{_f(b['error_max'])} | {_f(100 * b['coverage'], 1)} ({_f(100 * b['coverage_facing'], 1)}) |")
    lines += ["", "## Bake of the whole grid, per kind", "",
              "| grid | nodes | processes | wall s | CPU s | node CPU s p50 / max | arrays MB (per node) "
              "| disk MB (per node) | peak RSS MB |",
              "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for kind, bake in results["bakes"].items():
        n = bake["n_nodes"]
        lines.append(f"| {LABEL[kind]} | {n} | {bake['processes']} | {_f(bake['seconds'], 1)} "
                     f"| {_f(bake['cpu_seconds'], 1)} | {_f(bake['node_cpu_p50'])} / {_f(bake['node_cpu_max'])} "
                     f"| {_f(bake['memory_mb'], 1)} ({_f(bake['memory_mb'] / n, 3)}) "
                     f"| {_f(bake['disk_mb'], 1)} ({_f(bake['disk_mb'] / n, 3)}) | {_f(bake['peak_rss_mb'], 0)} |")
    lines += ["", "## What the numbers show", ""] + summary(results) + [""]
    return "\n".join(lines)


def _met(p99: float) -> str:
    return "met" if p99 <= 1 else "**not met**"


def summary(results: dict) -> list:
    out = []
    for scene in results["scenes"]:
        octree = BM.headline(scene["kinds"]["octree"]["blends"])
        tetra = BM.headline(scene["kinds"]["tetrahedral"]["blends"])
        out.append(f"- {scene['scene']}: p99 at views between nodes (target <= 1 px), the tetrahedral grid's "
                   f"{_f(tetra['error_p99'])} px ({_met(tetra['error_p99'])}), the octree grid's "
                   f"{_f(octree['error_p99'])} px ({_met(octree['error_p99'])}); coverage "
                   f"{_f(100 * tetra['coverage'], 1)} % against {_f(100 * octree['coverage'], 1)} %."
                   + "".join(f" With a {'x'.join(map(str, row['grid']))} grid: p99 "
                             f"{_f(row['kinds']['tetrahedral']['error_p99'])} px (octree "
                             f"{_f(row['kinds']['octree']['error_p99'])} px)." for row in scene.get("finer", [])))
    bakes = results["bakes"]
    o, t = bakes["octree"], bakes["tetrahedral"]
    out.append(f"- Bake: the octree grid in {_f(o['seconds'], 1)} s ({_f(o['cpu_seconds'] / o['n_nodes'], 3)} CPU s "
               f"and {_f(o['memory_mb'] / o['n_nodes'], 3)} MB per node), the tetrahedral grid in "
               f"{_f(t['seconds'], 1)} s ({_f(t['cpu_seconds'] / t['n_nodes'], 3)} CPU s and "
               f"{_f(t['memory_mb'] / t['n_nodes'], 3)} MB per node).")
    return out


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "benchmarks" / "octree.md")
    parser.add_argument("--views", type=int, default=8)
    parser.add_argument("--points", type=int, default=6000)
    parser.add_argument("--min-eye-distance", type=float, default=1.5)
    parser.add_argument("--processes", type=int, default=2)
    parser.add_argument("--finer", nargs="*", default=["17,17,9"], help="finer grids measured on the same views "
                        "(nodes along x,y,z; none with an empty list)")
    parser.add_argument("--quick", action="store_true", help="smallest run: sbc_fig3 only, 2 views, 1500 points, "
                        "a 3x3x2 grid of 32-px faces (and a 4x4x3 one)")
    args = parser.parse_args(argv)
    args.finer = [tuple(int(n) for n in grid.split(",")) for grid in args.finer]
    if args.quick:
        args.views, args.points, args.finer = 2, 1500, [(4, 4, 3)]
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(argv)
    started = time.perf_counter()
    B.import_package()
    from curved_reflections.engine.methods.morphing import morph_grid

    settings = morph_grid.MorphSettings(grid=(3, 3, 2), face_resolution=32) if args.quick \
        else morph_grid.MorphSettings()
    results = {"command": " ".join([".venv/bin/python", "tests/benchmarks/bench_octree.py"]
                                   + [shlex.quote(a) for a in argv]),
               "started": datetime.datetime.now().isoformat(timespec="seconds"), "machine": B._machine(),
               "code": B._code_version(REPO_ROOT),
               "settings": {"views": args.views, "points": args.points, "grid": list(settings.grid),
                            "face_resolution": settings.face_resolution, "octree_depth": settings.octree_depth},
               "scenes": []}
    found = scenes(args.points, args.quick)
    for name, mirror, matrix, sample in found:
        results["scenes"].append(measure_scene(name, mirror, matrix, sample, settings, args))
    _, mirror, matrix, _ = found[0]
    results["bakes"] = measure_bakes(mirror, matrix, settings, args.processes)
    results["total_seconds"] = time.perf_counter() - started
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(B._jsonable(results), indent=1) + "\n")
    args.out.write_text(report(results))
    _log(f"wrote {args.out} in {results['total_seconds'] / 60:.1f} min")
    return 0


if __name__ == "__main__":
    sys.exit(main())
