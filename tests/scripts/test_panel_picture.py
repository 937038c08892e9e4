# SPDX-License-Identifier: GPL-3.0-or-later
"""scripts/panel_picture.py draws the Reflections tab from the panels' own draw code.

Run as from the command line (its own Blender state, in a child process); its log names
each panel drawn, open or closed as by default, with its rows, and each mirror's accuracy
checked in the scene camera's view; the picture's size follows from the rows.
"""

import os
import re
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "panel_picture.py"


def test_panel_picture_is_written(tmp_path, gpu_ready):
    out = tmp_path / "panel.png"
    environment = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender_user"))
    command = [sys.executable, str(SCRIPT), "--out", str(out), "--resolution", "96", "72",
               "--check-sample", "300"]
    run = subprocess.run(command, capture_output=True, text=True, timeout=600, env=environment)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    size = re.search(r"wrote .*panel\.png \((\d+)x(\d+)\)", run.stdout)
    assert size and out.stat().st_size > 5000
    panels = dict(re.findall(r"^panel (.+): ((?:open|closed), \d+ rows)$", run.stdout, re.MULTILINE))
    assert list(panels) == ["Curved Reflections", "Mirror", "Glass", "Reflectors", "Quality", "Morphing Grids",
                            "Statistics"]
    # Closed: the header alone.
    assert panels["Glass"] == panels["Morphing Grids"] == panels["Statistics"] == "closed, 0 rows"
    # The ball measured in the view by the method that drew it, answers confirmed (the
    # traced torus has no answers per vertex to check).
    checks = dict(re.findall(r"^checked (\w+): In this view \((\w+)\): p95 [\d.]+ px", run.stdout, re.MULTILINE))
    assert checks == {"MirrorSphere": "Iterative"}, run.stdout[-3000:]
    assert "Ring ray traced on the GPU every frame" in run.stdout
    rows = {name: int(state.split(", ")[1].split()[0]) for name, state in panels.items()}
    # The live buttons and status; the mirror's settings; both mirrors with their reasons; the quality settings.
    assert rows["Curved Reflections"] >= 5 and rows["Mirror"] >= 9 and rows["Reflectors"] >= 8 and rows["Quality"] >= 6
    assert int(size.group(1)) == 540 and int(size.group(2)) >= 2 * 10 + 22 * (sum(rows.values()) + len(rows))
