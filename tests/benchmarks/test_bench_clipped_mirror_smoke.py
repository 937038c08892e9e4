# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the clipped-mirror benchmark: its smallest configuration runs end to end.

Run by ``make bench`` (``make test`` ignores tests/benchmarks). The shape of the output
is checked, and that the view starting inside the ball matches Cycles (all black): the
other figures are the full run's (docs/benchmarks/clipped_mirror.md).
"""

import re


def test_quick_benchmark_measures_every_view_and_renderer_against_cycles(run_quick, tmp_path):
    out = tmp_path / "clipped_mirror.md"
    run_quick("bench_clipped_mirror.py", out, extra=("--images", str(tmp_path / "images")))
    report = out.read_text()
    assert "bench_clipped_mirror.py --quick --out" in report
    rows = re.findall(r"^\| ([a-z ]+) \| (ours, [^|]+?) \| \*\*([\d.]+) %\*\* \|", report, flags=re.MULTILINE)
    assert sorted({view for view, _, _ in rows}) == ["clip start inside", "near plane through the ball", "ordinary"]
    renderers = {renderer for _, renderer, _ in rows}
    assert {"ours, Auto: Render Image", "ours, Auto: live view", "ours, Runtime: Render Image",
            "ours, Runtime: live view", "ours, Runtime: live view at rest"} <= renderers
    assert all(float(share) == 0.0 for view, _, share in rows if view == "clip start inside")
    assert "Worst clipped view of each of ours:" in report
