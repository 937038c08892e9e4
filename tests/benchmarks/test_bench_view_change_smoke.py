# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the view-change benchmark: its smallest configuration (``--quick``) runs end to end.

Run by ``make bench`` (``make test`` ignores tests/benchmarks), in a child process as from
the command line. Only the shape of the output is checked: the figures themselves are what
the full run reports (docs/benchmarks/view_change.md).
"""

import re


def test_quick_benchmark_times_both_modes_on_every_view(run_quick, tmp_path):
    out = tmp_path / "view_change.md"
    run_quick("bench_view_change.py", out)
    report = out.read_text()
    assert "bench_view_change.py --quick --out" in report
    rows = re.findall(r"^\| (\d+) \| (\d+) \| (yes|) \|(( [\d.]+ \|){4})$", report, flags=re.MULTILINE)
    assert len(rows) == 6 and rows[0][2] == "yes"
    assert all(float(value) > 0 for row in rows for value in row[3].strip(" |").split(" | "))
    # The Iterative rows: per frame against the plain draw, and the animation against Workbench.
    iterative = re.findall(r"^\| (sbc_fig3|two_spheres) \| 160x120 \| [\d,]+ \| [\d,]+ \| [\d,]+ \|(( [\d.]+ \|){4})",
                           report, flags=re.MULTILINE)
    assert [row[0] for row in iterative] == ["sbc_fig3", "two_spheres"]
    assert all(float(value) > 0 for row in iterative for value in row[1].strip(" |").split(" | "))
    # The Morphing rows on the GPU: the frame, the pass and the blend against the plain draw.
    morph = re.search(r"^\| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \| \*\*([\d.]+)x\*\* \| [\d.]+x \| [\d.]+x \| "
                      r"([\d,]+) \|$", report, flags=re.MULTILINE)
    assert morph is not None and all(float(value) > 0 for value in morph.groups()[:5])
    assert int(morph.group(6).replace(",", "")) > 100
    animations = re.findall(r"^\| (sbc_fig3|two_spheres) \| 4 \| ([\d.]+) \| ([\d.]+) \|", report, flags=re.MULTILINE)
    assert len(animations) == 2 and all(float(ours) > 0 and float(workbench) > 0 for _, ours, workbench in animations)
