# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the real-mirrors benchmark: its ``--quick`` run renders a torus and a
bevelled curve mirror against Cycles and reports their label disagreement (``make bench``)."""

import re


def test_quick_run_reports_each_mirror_against_cycles(run_quick, tmp_path):
    out = tmp_path / "real_mirrors.md"
    run_quick("bench_real_mirrors.py", out)
    report = out.read_text()
    rows = re.findall(r"^\| (torus|curve) \| ([0-9,]+) \| [^|]+ \| \*\*([0-9.]+) %\*\* \|", report, re.M)
    assert [r[0] for r in rows] == ["torus", "curve"], report
    for _, pixels, disagreement in rows:
        assert int(pixels.replace(",", "")) > 100 and 0.0 <= float(disagreement) < 50.0
