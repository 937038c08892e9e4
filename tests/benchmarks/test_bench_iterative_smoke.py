# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the iterative-search accuracy benchmark: its smallest configuration
(``--quick``) runs end to end and its table has a sane row per reflector.

Run by ``make bench`` (``make test`` ignores tests/benchmarks), in a child process as from
the command line; the figures themselves are the full run's (docs/benchmarks/iterative.md).
"""

import re

NAMES = ["sphere", "ellipsoid", "superellipsoid", "bumpy 0.03", "bumpy 0.06"]
ROW = re.compile(
    r"^\| (?P<name>[a-z0-9. ]+?) \| (?P<triangles>[\d,]+) \| (?P<face>\d+) \| (?P<convex>yes|no) \| "
    r"(?P<visible>[\d,]+) \| (?P<answers>[\d,]+) \| (?P<p50>[\d.]+) \| (?P<p95>[\d.]+) \| \*\*(?P<p99>[\d.]+)\*\* \| "
    r"(?P<max>[\d.]+) \| \*\*(?P<coverage>[\d.]+) %\*\* \| (?P<false>[\d.]+) % \| (?P<steps>[\d.]+) / "
    r"(?P<steps_max>\d+) \| (?P<bake>[\d.]+) \| (?P<search>[\d.]+) \| [\d.]+ \|$", flags=re.MULTILINE)


def test_quick_benchmark_measures_every_reflector(run_quick, tmp_path):
    run_quick("bench_iterative.py", tmp_path)
    report = (tmp_path / "iterative.md").read_text()
    assert "bench_iterative.py --quick --out" in report
    rows = [match.groupdict() for match in ROW.finditer(report)]
    assert [row["name"] for row in rows] == NAMES
    assert [row["convex"] for row in rows] == ["yes", "yes", "no", "no", "no"]
    for row in rows:
        assert row["triangles"] == "1,280" and row["face"] == "24"
        visible, answers = int(row["visible"].replace(",", "")), int(row["answers"].replace(",", ""))
        assert 40 <= visible <= 120 and 0.8 * visible <= answers <= 1.2 * visible  # of 2 x 60 points
        assert 0 <= float(row["p50"]) <= float(row["p95"]) <= float(row["p99"]) <= float(row["max"]) < 5
        assert 80 <= float(row["coverage"]) <= 100 and 0 <= float(row["false"]) <= 20
        assert 1 <= float(row["steps"]) <= int(row["steps_max"]) <= 80  # 16 steps x 5 starts at most
        assert float(row["bake"]) > 0 and float(row["search"]) >= 0
    assert re.search(r"^Largest p99: [\d.]+ px \(.+\); lowest coverage [\d.]+ %", report, flags=re.MULTILINE)
