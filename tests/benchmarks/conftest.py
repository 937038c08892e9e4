# SPDX-License-Identifier: GPL-3.0-or-later
"""What the benchmarks' smoke tests share: running a benchmark's ``--quick`` configuration."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


@pytest.fixture
def run_quick(tmp_path):
    """``run_quick(script, out)`` runs ``tests/benchmarks/<script> --quick --out <out>`` (then
    ``extra`` arguments) in a
    child process, as from the command line, with a throw-away Blender user folder; a
    failing run fails the test with the tail of its output."""

    def run(script: str, out: Path, timeout: int = 900, extra=()):
        environment = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender_user"))
        done = subprocess.run([sys.executable, str(HERE / script), "--quick", "--out", str(out), *extra],
                              capture_output=True, text=True, timeout=timeout, env=environment)
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
        return done

    return run
