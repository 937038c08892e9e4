# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the methods comparison: its smallest configuration (sbc_fig3 at
160x120, 3x3x2 grids, 3 frames, one against Cycles) runs every mode end to end and
plots them.

Run by ``make bench``. Only the shape of the output is checked: the figures are the full
run's (docs/benchmarks/methods.md).
"""

import re


def test_quick_benchmark_runs_every_mode_and_plots_them(run_quick, tmp_path):
    out = tmp_path / "methods.md"
    run_quick("bench_methods.py", out)
    report = out.read_text()
    assert "bench_methods.py --quick --out" in report
    rows = re.findall(r"^\| sbc_fig3 \| (\w+) \| (\w+) \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \| "
                      r"([\d.]+) / ([\d.]+) / ([\d.]+) \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \|$", report,
                      flags=re.MULTILINE)
    assert [(mode, drew) for mode, drew, *_ in rows] == [
        ("Runtime", "Runtime"), ("Morphing", "Morphing"), ("Octree", "Octree"), ("Iterative", "Iterative"),
        ("Perturbation", "Perturbation")]
    for mode, _, prepare, baked, seconds, *rest in rows:
        assert float(seconds) > 0
        assert (float(baked) > 0) == (mode in ("Morphing", "Octree"))  # only the grids are baked
    plot = tmp_path / "methods_accuracy_time.png"
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and plot.stat().st_size > 10_000
    assert (tmp_path / "methods.json").is_file()
