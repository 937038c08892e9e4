# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the iterative-search accuracy benchmark: its smallest configuration
(``--quick``) runs end to end and its table has a sane row per reflector.

Run by ``make bench`` (``make test`` ignores tests/benchmarks), in a child process as from
the command line; the figures themselves are the full run's (docs/benchmarks/iterative.md).
"""

import re


def test_quick_benchmark_measures_every_reflector(run_quick, tmp_path):
    run_quick("bench_iterative.py", tmp_path)
    report = (tmp_path / "iterative.md").read_text()
    assert "bench_iterative.py --quick --out" in report
    rows = re.findall(r"^\| (sphere|ellipsoid|bumpy 0.03|bumpy 0.06) \| [\d,]+ \| 24 \| (yes|no) \| ([\d.]+) \| "
                      r"([\d.]+) \| \*\*([\d.]+)\*\* \| [\d.]+ \| \*\*([\d.]+) %\*\*", report, flags=re.MULTILINE)
    assert [row[0] for row in rows] == ["sphere", "ellipsoid", "bumpy 0.03", "bumpy 0.06"]
    assert [row[1] for row in rows] == ["yes", "yes", "no", "no"]
    for _, _, p50, p95, p99, coverage in rows:
        assert 0 <= float(p50) <= float(p95) <= float(p99) < 5
        assert 80 <= float(coverage) <= 100
