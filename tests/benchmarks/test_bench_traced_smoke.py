# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of Ray Traced mode's benchmark: its smallest configuration (``--quick``) runs
end to end, and its tables hold a row per mirror, the trace off the exact one on under
2 % of the mirror's pixels.

Run by ``make bench`` (``make test`` ignores tests/benchmarks), in a child process as from
the command line; the figures themselves are the full run's (docs/benchmarks/traced.md)."""

import re

ROW = re.compile(r"^\| (?P<name>[a-z_0-9]+) \| (?:yes|no) \| [A-Za-z, ]+ \| \*\*[\d.]+x\*\* \| [\d.]+x \| "
                 r"[\d.]+ %(?: / [\d.]+ %)? \| \*\*[\d.]+x\*\* \| (?P<pixels>[\d,]+) \| (?P<off>[\d.]+) % \|",
                 flags=re.MULTILINE)


def test_quick_benchmark_measures_each_mirror(run_quick, tmp_path):
    run_quick("bench_traced.py", tmp_path / "traced.md")
    rows = [m.groupdict() for m in ROW.finditer((tmp_path / "traced.md").read_text())]
    assert [row["name"] for row in rows] == ["torus", "bumpy_ball_3_6"]
    assert all(int(row["pixels"].replace(",", "")) > 500 and float(row["off"]) < 2.0 for row in rows)
