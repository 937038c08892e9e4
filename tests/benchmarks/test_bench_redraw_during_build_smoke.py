# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the redraw-during-build benchmark: its smallest configuration runs end to end.

Run by ``make bench`` (``make test`` ignores tests/benchmarks). Only the shape of the
output is checked: the figures are the full run's (docs/benchmarks/redraw_during_build.md).
"""

import re


def test_quick_benchmark_times_redraws_while_cameras_build(run_quick, tmp_path):
    out = tmp_path / "redraw.md"
    run_quick("bench_redraw_during_build.py", out)
    report = out.read_text()
    assert "bench_redraw_during_build.py --quick --out" in report
    rows = dict(re.findall(r"^\| (.+?) \| ([\d.]+) \| [\d.]+ \| \d+ \| [\d.]+x \|$", report, flags=re.MULTILINE))
    assert set(rows) == {"redraw, idle", "**redraw during a build**", "plain draw",
                         "redraw when the camera lands (upload)", "camera build and projection (worker)"}
    assert all(float(ms) > 0 for ms in rows.values())
    assert re.search(r"A redraw during a build: \*\*[\d.]+x\*\* the plain draw", report)
