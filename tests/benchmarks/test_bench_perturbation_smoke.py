# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the perturbation benchmark: its smallest configuration (150 points a
view, coarse meshes, a 3-frame animation at 160x120, one frame against Cycles) runs end
to end.

Run by ``make bench``. The shape of the output is checked, and that the method answers
(nearly every exact reflection, sub-pixel): the figures are the full run's
(docs/benchmarks/perturbation.md).
"""

import re


def test_quick_run_compares_the_methods_and_renders_an_animation(run_quick, tmp_path):
    out = tmp_path / "perturbation.md"
    run_quick("bench_perturbation.py", out)
    report = out.read_text()
    assert "bench_perturbation.py --quick --out" in report
    rows = re.findall(r"^\| ([a-z ,0-9]+) \| (\d) \| (Perturbation|Runtime|Iterative) \| ([\d.]+) % \| [\d.]+ % \| "
                      r"([\d.]+) \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \| ([\d,]+) \|$", report, flags=re.MULTILINE)
    ours = [r for r in rows if r[2] == "Perturbation"]
    runtime = [r for r in rows if r[2] == "Runtime"]
    # Every surface and view of the comparison, each with the Runtime row it is compared with.
    assert len(ours) == len(runtime) >= 14 and {r[:2] for r in ours} == {r[:2] for r in runtime}
    assert {r[0] for r in ours} >= {"exact sphere", "two sphere meshes, order 2"}
    assert all(float(r[3]) > 90 and float(r[6]) < 1.0 for r in ours)
    ratio = re.search(r"^\| ([\d.]+) \| ([\d.]+) \| \*\*([\d.]+)x\*\* \|$", report, flags=re.MULTILINE)
    assert ratio and float(ratio.group(1)) > 0
    frames = re.findall(r"^\| (\d+) \| ([\d,]+) \| ([\d.]+) % \| [\d.]+ \| ([\d.]+) % \| [\d.]+ \| ([\d.]+) % \| "
                        r"[\d.]+ \|$", report, flags=re.MULTILINE)
    assert [int(f[0]) for f in frames] == [1] and float(frames[0][2]) < 10
