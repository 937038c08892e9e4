# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the drawing benchmark: its smallest configuration (``--quick``) runs end to end.

Run by ``make bench`` (``make test`` ignores tests/benchmarks). The script runs in a child
process, as from the command line, so its Blender state stays out of this one. Only the
shape of the output is checked: the figures themselves are what the full run reports.
"""

import re


def test_quick_benchmark_writes_the_table(run_quick, tmp_path):
    out = tmp_path / "draw.md"
    run_quick("bench_draw.py", out, timeout=600)

    report = out.read_text()
    for heading in ("# Drawing cost: reflected pass against a plain draw", "## Where the reflected pass spends",
                    "## What the numbers show", "**Per frame**", "**Per rebuild**"):
        assert heading in report
    assert "bench_draw.py --quick --out" in report
    row = re.search(r"\| sbc_fig3 \| 160x120, d=2 \| ([\d,]+) \([\d,]+\) \| ([\d,]+) \| (\d+) \| ([\d.]+) \| ([\d.]+) "
                    r"\| \*\*([\d.]+)x\*\* \|", report)
    assert row, report
    vertices, triangles, sheets = (int(row.group(k).replace(",", "")) for k in (1, 2, 3))
    reflected, plain, ratio = (float(row.group(k)) for k in (4, 5, 6))
    assert vertices >= 5_000 and triangles > vertices and sheets >= 1
    assert reflected > 0 and plain > 0 and abs(ratio - reflected / plain) < 0.1 + 0.05 * ratio
    # The projection, once per camera: its time and vertex projections with culling and without.
    row = re.search(r"\| sbc_fig3 \| 1 \| ([\d.]+) \| ([\d.]+) \| ([\d,]+) \| ([\d.]+) \| ([\d,]+) \| ([\d,]+) \|",
                    report)
    assert row, report
    culled_ms, gpu_ms, unculled_ms = (float(row.group(k)) for k in (1, 2, 4))
    culled, unculled = (int(row.group(k).replace(",", "")) for k in (3, 5))
    assert 0 < gpu_ms <= culled_ms and unculled_ms > 0
    assert 0 < culled <= unculled == vertices  # one sheet: each vertex at most once
