# SPDX-License-Identifier: GPL-3.0-or-later
"""The iterative search's reflector map (Roger & Holzschuch 2006) baked on the GPU
(``drawing/methods/iterative_bake.py``) against the CPU ray-cast bake
(``engine/methods/iterative/reflector_map.py``), timed in one run.

    .venv/bin/python tests/benchmarks/bench_iterative_bake.py      # docs/benchmarks/iterative_bake.md
    .venv/bin/python tests/benchmarks/bench_iterative_bake.py --quick --out /tmp/bake.md

A geodesic sphere (``--subdivisions``, default 5: 20,480 triangles) of radius 1 is baked
from a point off its centre at each face size (``--sizes``, default 256), once on the GPU
after a warm-up bake (shader built) and once on the CPU; the two maps are compared
texel by texel (hole flags that differ: rays exactly on a silhouette). The GPU on this
project's machines is Mesa llvmpipe, i.e. the same CPU cores. What the bakes must agree
on is tested (tests/drawing/methods/test_iterative_bake.py, at small sizes); this
measures what they cost.
"""

from __future__ import annotations

import argparse
import datetime
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_draw  # noqa: E402  (same folder: machine facts with the GPU)
import bench_sbc  # noqa: E402  (same folder: package import)

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_OUT = REPO_ROOT / "docs" / "benchmarks" / "iterative_bake.md"
SPHERE_CENTRE = (0.1, -0.2, 0.3)
BAKE_CENTRE = (0.3, -0.1, 0.2)


def measure(subdivisions: int, face_size: int) -> dict:
    from curved_reflections.drawing.methods.iterative_bake import bake_reflector_map_gpu
    from curved_reflections.engine.geometry.raytrace import ReflectorSet
    from curved_reflections.engine.geometry.sphere import icosphere
    from curved_reflections.engine.methods.iterative.reflector_map import bake_reflector_map

    reflector = icosphere(SPHERE_CENTRE, 1.0, subdivisions)
    bake_reflector_map_gpu(reflector, BAKE_CENTRE, 8)  # shader built, GPU warm
    start = time.perf_counter()
    gpu_bake = bake_reflector_map_gpu(reflector, BAKE_CENTRE, face_size)
    gpu_seconds = time.perf_counter() - start
    start = time.perf_counter()
    cpu_bake = bake_reflector_map(ReflectorSet([reflector]), BAKE_CENTRE, face_size)
    cpu_seconds = time.perf_counter() - start
    g, c = gpu_bake.reflector_map.texels[..., 0] > 0, cpu_bake.reflector_map.texels[..., 0] > 0
    return {"triangles": len(reflector.triangles), "face": face_size, "gpu": gpu_seconds, "cpu": cpu_seconds,
            "differ": int((g != c).sum()), "coverage_gpu": gpu_bake.coverage, "coverage_cpu": cpu_bake.coverage}


def report(results: list, command: str, machine: str) -> str:
    lines = [
        "# Reflector map bake: GPU against CPU",
        "",
        f"Generated {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC by `{command}` on {machine}.",
        "",
        "The iterative search's cube map of a geodesic sphere, baked from a point off its centre: "
        "rasterised on the GPU (`drawing/methods/iterative_bake.py`, after a warm-up bake) and ray-cast on the "
        "CPU (`engine/methods/iterative/reflector_map.py`). Hole flags differ only for rays exactly on a "
        "silhouette.",
        "",
        "| triangles | face size | GPU bake (s) | CPU bake (s) | CPU / GPU | coverage GPU | coverage CPU "
        "| hole flags differ |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        lines.append(f"| {r['triangles']:,} | {r['face']} | {r['gpu']:.3f} | {r['cpu']:.3f} | "
                     f"{r['cpu'] / r['gpu']:.0f}x | {r['coverage_gpu']:.4f} | {r['coverage_cpu']:.4f} | "
                     f"{r['differ']} |")
    lines += ["", "The GPU here is Mesa llvmpipe on the same two cores as the CPU bake.", ""]
    return "\n".join(lines)


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="markdown file to write")
    parser.add_argument("--subdivisions", type=int, default=5)
    parser.add_argument("--sizes", type=int, nargs="+", default=[256])
    parser.add_argument("--quick", action="store_true", help="small: 3 subdivisions, face size 32")
    args = parser.parse_args(argv)
    if args.quick:
        args.subdivisions, args.sizes = 3, [32]
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    bench_sbc.import_package_on_gpu()
    results = []
    for size in args.sizes:
        results.append(measure(args.subdivisions, size))
        r = results[-1]
        print(f"S={size}, {r['triangles']} triangles: GPU bake {r['gpu']:.3f} s, CPU bake {r['cpu']:.3f} s, "
              f"hole flags differ at {r['differ']} texels", flush=True)
    command = bench_draw.command_line("bench_iterative_bake.py", argv)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(report(results, command, bench_draw._machine()), encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
