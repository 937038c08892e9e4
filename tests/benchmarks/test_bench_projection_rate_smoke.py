# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the projection-rate benchmark: its smallest configuration (``--quick``) runs end to end.

Run by ``make bench`` (``make test`` ignores tests/benchmarks), in a child process as from
the command line. Only the shape of the output is checked (and that numpy and the GPU
agree, and that the cone holds every projected pair): the rates themselves are what the
full run reports (docs/benchmarks/projection_rate.md).
"""

import re


def test_quick_benchmark_measures_both_rates(run_quick, tmp_path):
    out = tmp_path / "rate.md"
    run_quick("bench_projection_rate.py", out)
    report = out.read_text()
    assert "bench_projection_rate.py --quick --out" in report
    row = re.search(r"^\| sbc_fig3 \| 1 \| 20,000 \| ([\d.]+) \| ([\d.]+) \| [\d.]+x \| ([\d.]+)% "
                    r"\| ([\d.]+)% \| ([\d.]+)% \| ([\d.]+) \|$", report, flags=re.MULTILINE)
    assert row is not None, report
    assert float(row.group(1)) > 0 and float(row.group(2)) > 0
    assert float(row.group(3)) >= 99.9
    # One sheet: every point lies in its cone, and the ball reflects most of them.
    assert float(row.group(4)) >= float(row.group(5)) > 50.0
    assert float(row.group(6)) > 0
