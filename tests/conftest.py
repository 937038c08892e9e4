# SPDX-License-Identifier: GPL-3.0-or-later
"""Test harness: an isolated Blender user folder, the package import, the GPU fixture.

Engine tests (tests/engine) never import ``bpy``; this file imports it only inside
fixtures. ``BLENDER_USER_RESOURCES`` is set before any test can import ``bpy`` so that
no test reads or writes the user's real Blender configuration.
"""

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


def _load_package_link():
    spec = importlib.util.spec_from_file_location(
        "curved_reflections_package_link", REPO_ROOT / "scripts" / "package_link.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_package_link = _load_package_link()
_package_link.isolate_blender_user_folder()
_package_link.import_as_package(REPO_ROOT)


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO_ROOT


#: Initialises the GPU the way gpu_ready does (blender/gpu_init.py, loaded by file path:
#: it imports only bpy and gpu); run first in a child process, because without OpenGL
#: Blender aborts the whole process instead of raising.
_GPU_INIT = f"""
import importlib.util
spec = importlib.util.spec_from_file_location("gpu_init", {str(REPO_ROOT / "blender" / "gpu_init.py")!r})
gpu_init = importlib.util.module_from_spec(spec)
spec.loader.exec_module(gpu_init)
gpu_init.ensure_gpu()
"""


@pytest.fixture(scope="session")
def gpu_ready():
    """Blender's ``gpu`` module, initialised headless by one tiny Workbench render.

    Before anything has rendered, every ``gpu`` call fails in background mode. If the
    GPU cannot be initialised the test fails (never skips): GPU code must be tested.
    """
    probe = subprocess.run(
        [sys.executable, "-c", _GPU_INIT], capture_output=True, text=True, timeout=120
    )
    if probe.returncode != 0:
        output = "\n".join((probe.stdout + probe.stderr).splitlines()[-8:])
        pytest.fail(
            "Could not initialise Blender's GPU module with a Workbench render "
            f"(exit status {probe.returncode}). GPU tests need OpenGL 4.3+, e.g. Mesa "
            "llvmpipe (Debian: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri).\n"
            + output,
            pytrace=False,
        )
    from curved_reflections.blender.gpu_init import ensure_gpu

    ensure_gpu()
    import gpu

    return gpu


@pytest.fixture(scope="session")
def sphere_reflections():
    """A sphere mesh (centre (0, 0, 1), radius 1), points around it and their exact
    reflection points seen from ``eye`` (one per point: the sphere is convex), NaN
    where none is seen: what a polish of node images is checked against, in numpy
    (``test_image_polish.py``) and on the GPU (``test_polish_gpu.py``)."""
    from types import SimpleNamespace

    import numpy as np

    from curved_reflections.engine import look_at_view
    from curved_reflections.engine.geometry.raytrace import ReflectorSet
    from curved_reflections.engine.geometry.sphere import icosphere
    from curved_reflections.engine.reference.exact import solve_reflections

    centre, eye = np.array([0.0, 0.0, 1.0]), np.array([0.3, -3.0, 1.6])
    mirror = ReflectorSet([icosphere(centre, 1.0, 4, "Sphere")])
    points = np.random.default_rng(11).uniform([-2.5, -2.5, -0.5], [2.5, 2.5, 2.8], (600, 3))
    points = points[np.linalg.norm(points - centre, axis=1) > 1.2]
    exact = solve_reflections(mirror, look_at_view(eye, centre), points)
    exact = exact.select(exact.seen_by_eye & exact.sees_point)
    truth = np.full((len(points), 3), np.nan)
    truth[exact.point] = exact.position
    return SimpleNamespace(mirror=mirror, points=points, truth=truth, centre=centre, eye=eye)
