# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the soak benchmark: one cycle of the scripted session runs end to end.

Run by ``make bench`` (``make test`` ignores tests/benchmarks). The figures are the
hour-long run's (docs/benchmarks/soak.md); here one cycle must leave nothing behind.
"""

import re


def test_one_cycle_leaves_no_texture_handler_or_timer_behind(run_quick, tmp_path):
    out = tmp_path / "soak.md"
    run_quick("bench_soak.py", out)
    report = out.read_text()
    assert "bench_soak.py --quick --out" in report
    assert re.search(r"\| GPU textures a deleted mirror left alive \(worst cycle\) \| 0 \|", report)
    assert re.search(r"\| GPU textures alive after unregister \| 0 \|", report)
    assert "| 0, 0, 0, 0, 0, 0 | all 0 (met) |" in report
    assert re.search(r"\| 1 \| [\d.]+ \| \d+ \| [1-9]\d* \|", report)  # the live view held textures
