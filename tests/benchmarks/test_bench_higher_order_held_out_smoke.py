# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the held-out second-order benchmark: its ``--quick`` run writes a table
per scene with real coverage and error figures (``make bench``)."""

import re


def test_quick_run_reports_coverage_and_errors_per_scene(run_quick, tmp_path):
    out = tmp_path / "held_out.md"
    run_quick("bench_higher_order_held_out.py", out)
    report = out.read_text()
    for heading in ("## facing spheres", "## sphere and wall"):
        assert heading in report
    coverage = [float(v) for v in re.findall(r"\| \*\*([0-9.]+) %\*\* \|", report)]
    scenes = re.findall(r"^## ", report, flags=re.MULTILINE)
    # Two reflectors a scene: one row per history (A -> B, B -> A).
    assert len(coverage) == 2 * len(scenes) and all(50.0 < c <= 100.0 for c in coverage), coverage
    assert "bench_higher_order_held_out.py --quick --out" in report
