# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the refraction search's benchmark: its smallest configuration (``--quick``)
runs end to end, and its table holds a sane row per glass and the viewport's figure.

Run by ``make bench`` (``make test`` ignores tests/benchmarks), in a child process as from
the command line; the figures themselves are the full run's
(docs/benchmarks/refraction_search.md)."""

import re

ROW = re.compile(r"^\| (?P<name>[a-z ]+) \| (?P<set>tuned|held out) \| (?P<points>[\d,]+) \| [\d,]+ \| [\d,]+(?: \([\d]+ %\))? \| [\d,]+ \| "
                 r"\*\*(?P<coverage>[\d.]+) %\*\* \| (?P<points_share>[\d.]+) % \| \*\*(?P<p99>[\d.]+)\*\* \|",
                 flags=re.MULTILINE)


def test_quick_benchmark_measures_every_glass_and_the_viewport(run_quick, tmp_path):
    run_quick("bench_refraction_search.py", tmp_path / "refraction_search.md")
    report = (tmp_path / "refraction_search.md").read_text()
    rows = [match.groupdict() for match in ROW.finditer(report)]
    assert [(row["name"], row["set"]) for row in rows] == [
        ("ball", "tuned"), ("thick lens", "held out"), ("flat ellipsoid", "held out"), ("box", "held out")]
    ball = rows[0]
    assert float(ball["coverage"]) > 99.0 and float(ball["p99"]) < 0.5
    assert all(0.0 < float(row["coverage"]) <= 100.0 for row in rows)
    assert re.search(r"\*\*[\d.]+ s\*\* a draw, \*\*[\d.]+x\*\* a Workbench frame", report)
