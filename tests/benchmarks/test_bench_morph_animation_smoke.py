# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the Morphing- and Octree-mode animation benchmark: its smallest
configuration (a 3x3x2 grid baked, 3 frames, one frame against Cycles) runs end to end.

Run by ``make bench``. Only the shape of the output is checked: the figures are the full
runs' (docs/benchmarks/morph_animation.md, octree_animation.md).
"""

import re

import pytest


@pytest.mark.parametrize("mode, label", [("MORPHING", "Morphing"), ("OCTREE", "Octree")])
def test_quick_benchmark_renders_an_animation_and_a_frame_against_cycles(run_quick, tmp_path, mode, label):
    out = tmp_path / "morph_animation.md"
    run_quick("bench_morph_animation.py", out, extra=("--mode", mode))
    report = out.read_text()
    assert "bench_morph_animation.py --quick --out" in report
    assert f"the mirror ball in {label} mode" in report
    assert re.search(r"its 3x3x2 grid baked first in [\d.]+ s", report)
    ours, workbench = map(float, re.search(r"^\| ([\d.]+) \| ([\d.]+) \| \*\*[\d.]+x\*\* \|$", report,
                                           flags=re.MULTILINE).groups())
    assert ours > 0 and workbench > 0
    frames = re.findall(r"^\| (\d+) \| ([\d,]+) \| ([\d.]+) % \| [\d.]+ \| ([\d.]+) % \| [\d.]+ \| ([\d.]+) % \| "
                        r"[\d.]+ \|$", report, flags=re.MULTILINE)
    assert [int(f[0]) for f in frames] == [1] and int(frames[0][1].replace(",", "")) > 1000
    assert 0 <= float(frames[0][4]) < 10  # Runtime mode on the same frame: the reference's few per cent
