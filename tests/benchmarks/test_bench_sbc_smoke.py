# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the SBC benchmark: its smallest configuration (``--quick``) runs end to end.

Run by ``make bench`` (``make test`` ignores tests/benchmarks). The script runs in a child
process, as from the command line, so its Blender state stays out of this one. Only the
shape of the output is checked: the figures themselves are what the full run reports.
"""

import json


def test_quick_benchmark_writes_tables_and_raw_results(run_quick, tmp_path):
    run_quick("bench_sbc.py", tmp_path / "out")

    results = json.loads((tmp_path / "out" / "sbc.json").read_text())
    assert [s["scene"] for s in results["scenes"]] == ["sbc_fig3", "superellipsoid"]
    assert {(c["scene"], c["model"]) for c in results["headline"]} == {
        (scene, model) for scene in ("sbc_fig3", "superellipsoid") for model in ("ray_patch", "pinhole")}
    assert len(results["sweep"]) == 8
    for cell in results["headline"] + results["sweep"]:
        assert cell["status"] == "ok", cell
        assert cell["n_rays"] > 0 and cell["n_leaves"] > 0 and cell["n_compared"] > 100
        assert 0 <= cell["error_p50"] <= cell["error_p95"] <= cell["error_p99"] <= cell["error_max"]
        assert 0 < cell["coverage"] <= 1 and 0 <= cell["false_rate"] <= 1
        assert cell["points_per_second"] > 0 and cell["build_seconds"] > 0

    report = (tmp_path / "out" / "sbc.md").read_text()
    for heading in ("## Machine and command", "## Headline: d = 4, accuracy 1 px", "### Targets for ours",
                    "## Sweep: superellipsoid", "## What the numbers show"):
        assert heading in report
    assert "bench_sbc.py --quick --out" in report
