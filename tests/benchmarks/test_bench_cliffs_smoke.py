# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the cliffs benchmark: its smallest configuration runs end to end.

Run by ``make bench`` (``make test`` ignores tests/benchmarks). Only the shape of the
output is checked: the figures are the full run's (docs/benchmarks/cliffs.md).
"""

import re


def test_quick_benchmark_times_every_view_against_the_ordinary_one(run_quick, tmp_path):
    out = tmp_path / "cliffs.md"
    run_quick("bench_cliffs.py", out)
    report = out.read_text()
    assert "bench_cliffs.py --quick --out" in report
    rows = re.findall(r"^\| ([a-z0-9 ]+) \| .+? \| ([\d.]+) \| ([\d.]+)x \|", report, flags=re.MULTILINE)
    assert [name for name, _, _ in rows] == ["ordinary", "clip start inside", "eye on the surface",
                                             "along the surface", "grazing", "subdivided ball"]
    assert float(rows[0][2]) == 1.0 and all(float(seconds) > 0 for _, seconds, _ in rows)
    assert re.search(r"Slowest view: \*\*[\d.]+x\*\* the ordinary frame", report)
