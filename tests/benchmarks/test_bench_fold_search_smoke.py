# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the folded-mirror search's benchmark: its smallest configuration
(``--quick``) runs end to end, and its table holds a sane row per mirror.

Run by ``make bench`` (``make test`` ignores tests/benchmarks), in a child process as from
the command line; the figures themselves are the full run's (docs/benchmarks/fold_search.md)."""

import re

ROW = re.compile(r"^\| (?P<name>[a-z_0-9]+) \| (?P<set>tuning|held out) \| [\d,]+ \| [\d,]+ \| "
                 r"\*\*(?P<every>[\d.]+) %\*\* / (?P<one>[\d.]+) % \|", flags=re.MULTILINE)


def test_quick_benchmark_measures_every_mirror(run_quick, tmp_path):
    run_quick("bench_fold_search.py", tmp_path / "fold_search.md")
    rows = [match.groupdict() for match in ROW.finditer((tmp_path / "fold_search.md").read_text())]
    assert [(row["name"], row["set"]) for row in rows] == [
        ("star_ball", "tuning"), ("dented_sphere", "tuning"), ("bumpy_ball_3_6", "held out"),
        ("hammered_sphere", "held out")]
    # Every image covers more of the exact images than one per point, on the star ball by far.
    assert all(float(row["every"]) >= float(row["one"]) for row in rows)
    assert float(rows[0]["every"]) > 80.0 and float(rows[0]["one"]) < 70.0
