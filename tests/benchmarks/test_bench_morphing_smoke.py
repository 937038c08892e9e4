# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the morphing benchmark: its smallest configuration (``--quick``) runs end to end.

Run by ``make bench`` (``make test`` ignores tests/benchmarks), in a child process as from
the command line. Only the shape of the output is checked: the figures themselves are what
the full run reports (docs/benchmarks/morphing.md).
"""

import json
import os
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parent / "bench_morphing.py"


def test_quick_benchmark_writes_tables_and_raw_results(tmp_path):
    environment = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender_user"))
    run = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--out", str(tmp_path / "out")],
                         capture_output=True, text=True, timeout=900, env=environment)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]

    results = json.loads((tmp_path / "out" / "morphing.json").read_text())
    assert [cell["grid"] for cell in results["sweep"]] == [[3, 3, 2], [5, 5, 3]]
    for cell in results["sweep"]:
        assert set(cell["blends"]) == {"linear", "surface", "polished"}
        for blend in cell["blends"].values():
            if blend["n_views"]:
                assert blend["n_compared"] > 0
                assert 0 <= blend["error_p50"] <= blend["error_p95"] <= blend["error_p99"] <= blend["error_max"]
                assert 0 < blend["coverage"] <= 1 and 0 <= blend["false_rate"] <= 1
    bake = results["bake"]
    assert bake["n_nodes"] == 18 and bake["processes"] == 2
    assert bake["seconds"] > 0 and bake["cpu_seconds"] > 0 and bake["peak_rss_mb"] > 0 and bake["disk_mb"] > 0

    report = (tmp_path / "out" / "morphing.md").read_text()
    for heading in ("## Machine and command", "## Error against grid spacing", "## Bake of a 3x3x2 grid",
                    "## What the numbers show"):
        assert heading in report
    assert "bench_morphing.py --quick --out" in report


def test_bake_only_writes_the_bake_figures_alone(tmp_path):
    environment = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender_user"))
    run = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--bake-only", "--out", str(tmp_path / "out")],
                         capture_output=True, text=True, timeout=900, env=environment)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    result = json.loads((tmp_path / "out" / "morphing_bake.json").read_text())
    assert result["grid"] == [3, 3, 2] and result["n_nodes"] == 18 and result["seconds"] > 0
    assert result["worker_cpu_seconds"] >= 0.5 * result["cpu_seconds"] > 0
    assert not (tmp_path / "out" / "morphing.md").exists()
