# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the live re-bake benchmark: its smallest configuration runs end to end.

Run by ``make bench`` (``make test`` ignores tests/benchmarks). The figures are the full
run's (docs/benchmarks/live_rebake.md); here only that the re-bake that does not wait
held the main thread less than the one that waits, and said so in the status line.
"""

import re


def test_quick_benchmark_times_the_main_thread_of_both_rebakes(run_quick, tmp_path):
    out = tmp_path / "live_rebake.md"
    run_quick("bench_live_rebake.py", out)
    report = out.read_text()
    assert "bench_live_rebake.py --quick --out" in report
    waiting = re.search(r"^\| waiting .+? \| ([\d.]+) \|", report, flags=re.MULTILINE)
    not_waiting = re.search(r"^\| not waiting .+? \| ([\d.]+) \|", report, flags=re.MULTILINE)
    assert float(not_waiting.group(1)) < float(waiting.group(1))
    assert "Preparing 'MirrorSphere' for ray tracing" in report
