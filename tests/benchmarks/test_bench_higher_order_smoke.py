# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the second-order benchmark: its smallest configuration (``--quick``) runs end to end.

Run by ``make bench`` (``make test`` ignores tests/benchmarks), in a child process so its
Blender state stays out of this one. Shapes and sanity of the output are checked; the
figures themselves are what the full run reports.
"""

import json


def test_quick_benchmark_writes_tables_and_raw_results(run_quick, tmp_path):
    run_quick("bench_higher_order.py", tmp_path / "out")

    results = json.loads((tmp_path / "out" / "higher_order.json").read_text())
    assert results["scene"]["exact_visible"] > 100
    assert set(results["scene"]["exact_by_history"]) == {"AB", "BA"}
    (cell,) = results["cells"]
    assert cell["downsample"] == 4 and cell["n_compared"] > 100
    assert 0 <= cell["error_p50"] <= cell["error_p95"] <= cell["error_p99"] <= cell["error_max"]
    assert 0 < cell["coverage"] <= 1 and 0 <= cell["false_rate"] <= 1
    for history in cell["histories"].values():
        assert history["rays"] > 0 and history["exact_images"] > 0

    report = (tmp_path / "out" / "higher_order.md").read_text()
    for heading in ("## Machine and command", "## Scene and reference", "## Sample-based camera, order-2 groups"):
        assert heading in report
    assert "bench_higher_order.py --quick --out" in report
