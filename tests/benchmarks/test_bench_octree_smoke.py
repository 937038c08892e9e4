# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the ray-octree benchmark: its smallest configuration (the sbc_fig3
sphere, 2 views, a 3x3x2 grid of both kinds, both bakes) runs end to end.

Run by ``make bench``. Only the shape of the output is checked: the figures are the full
run's (docs/benchmarks/octree.md).
"""

import re


def test_quick_benchmark_compares_both_grids_and_their_bakes(run_quick, tmp_path):
    out = tmp_path / "octree.md"
    run_quick("bench_octree.py", out)
    report = out.read_text()
    assert "bench_octree.py --quick --out" in report
    rows = re.findall(r"^\| sbc_fig3 \| (.+?) \| (linear|surface) \| 2 \| (\d+) \|", report, flags=re.MULTILINE)
    assert {(grid, blend) for grid, blend, _ in rows} == {
        (grid, blend) for grid in ("tetrahedral (SBC VI)", "ray octree (Martin & Popescu)")
        for blend in ("linear", "surface")}
    bakes = re.findall(r"^\| (tetrahedral \(SBC VI\)|ray octree \(Martin & Popescu\)) \| 18 \| 2 \| ([\d.]+) \|",
                       report, flags=re.MULTILINE)
    assert len(bakes) == 2 and all(float(seconds) > 0 for _, seconds in bakes)
    assert (tmp_path / "octree.json").is_file()
