# SPDX-License-Identifier: GPL-3.0-or-later
"""Smoke test of the view-change benchmark: its smallest configuration (``--quick``) runs end to end.

Run by ``make bench`` (``make test`` ignores tests/benchmarks), in a child process as from
the command line. Only the shape of the output is checked: the figures themselves are what
the full run reports (docs/benchmarks/view_change.md).
"""

import os
import re
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parent / "bench_view_change.py"


def test_quick_benchmark_times_both_modes_on_every_view(tmp_path):
    environment = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender_user"))
    out = tmp_path / "view_change.md"
    run = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--out", str(out)],
                         capture_output=True, text=True, timeout=900, env=environment)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    report = out.read_text()
    assert "bench_view_change.py --quick --out" in report
    rows = re.findall(r"^\| (\d+) \| (\d+) \| (yes|) \|(( [\d.]+ \|){4})$", report, flags=re.MULTILINE)
    assert len(rows) == 6 and rows[0][2] == "yes"
    assert all(float(value) > 0 for row in rows for value in row[3].strip(" |").split(" | "))
