# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the held-out family benchmark: its ``--quick`` run, on one mirror of
each half at a tiny size, reports both halves' tables with figures (``make bench``)."""

import re

ROW = (r"^\| {name} \| [^|]+ \| ([0-9.]+) \| \*\*([0-9.]+)\*\* \| \*\*([0-9.]+) / ([0-9.]+)\*\* \| "
       r"([^|]+) \| ([^|]+) \|$")


def test_quick_run_reports_both_halves(run_quick, tmp_path):
    out = tmp_path / "held_out_family.md"
    run_quick("bench_held_out_family.py", out, extra=("--mirrors", "star_ball", "bumpy_ball_3_6",
                                                      "--width", "96", "--height", "64"))
    report = out.read_text()
    tuning, held_out = report.split("## Tuning half")[1].split("## Held-out half")
    for name, section in (("star_ball", tuning), ("bumpy_ball_3_6", held_out)):
        row = re.search(ROW.format(name=name), section, re.M)
        assert row is not None, report
        seconds, ratio, first, last, modes, _check = row.groups()
        assert float(seconds) > 0.0 and float(ratio) > 0.0, report
        assert 0.0 <= float(first) < 50.0 and 0.0 <= float(last) < 50.0, report
        cells = modes.split("<br>")  # Iterative, Perturbation, Runtime: what drew and its labels
        assert [c.split()[0].rstrip(":") for c in cells] == ["Iterative", "Perturbation", "Runtime"], report
        assert all(re.search(r": [0-9.]+ %", c) for c in cells), report
        assert "What the numbers show" in section
