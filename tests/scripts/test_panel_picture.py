# SPDX-License-Identifier: GPL-3.0-or-later
"""scripts/panel_picture.py draws the Reflections tab from the panel's own draw code.

Run as from the command line (its own Blender state, in a child process); the rows it
records are checked through the picture's size (one line per row) and its log.
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
    run = subprocess.run([sys.executable, str(SCRIPT), "--out", str(out)], capture_output=True, text=True,
                         timeout=300, env=environment)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    size = re.search(r"wrote .*panel\.png \((\d+)x(\d+)\)", run.stdout)
    assert size and out.stat().st_size > 5000
    # The active object's settings, the lists, both boxes with their buttons and the stats: 25+ rows.
    assert int(size.group(1)) == 540 and int(size.group(2)) >= 2 * 10 + 22 * 25
