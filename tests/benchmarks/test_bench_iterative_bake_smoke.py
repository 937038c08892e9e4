# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the reflector-map bake benchmark: its smallest configuration (``--quick``)
runs end to end and its row is sane.

Run by ``make bench`` (``make test`` ignores tests/benchmarks), in a child process as from
the command line; the timings themselves are the full run's (docs/benchmarks/iterative_bake.md).
"""

import re


def test_quick_benchmark_times_both_bakes(run_quick, tmp_path):
    out = tmp_path / "bake.md"
    run_quick("bench_iterative_bake.py", out)
    report = out.read_text()
    assert "bench_iterative_bake.py --quick --out" in report
    row = re.search(r"^\| 1,280 \| 32 \| ([\d.]+) \| ([\d.]+) \| \d+x \| ([\d.]+) \| ([\d.]+) \| (\d+) \|$", report,
                    flags=re.MULTILINE)
    assert row is not None, report
    assert float(row.group(1)) > 0 and float(row.group(2)) > 0
    assert 0.5 < float(row.group(3)) <= 1 and abs(float(row.group(3)) - float(row.group(4))) <= 0.01
    assert int(row.group(5)) <= 4  # silhouette texels only
