# SPDX-License-Identifier: GPL-3.0-or-later
"""Import the repository as the package ``curved_reflections``, whatever its folder is called.

Blender installs the extension as ``bl_ext.<repo>.curved_reflections``; the code inside
uses relative imports only. Tests and scripts need it under one fixed name instead, so
this links the repository root into a temporary folder as ``<name>`` and imports it
from there. Importing does not import ``bpy``: only ``register()`` does.
"""

from __future__ import annotations

import atexit
import importlib.util
import os
import shutil
import sys
import tempfile
from pathlib import Path


def import_as_package(repo_root, name: str = "curved_reflections"):
    """The repository at ``repo_root`` imported as the package ``name`` (cached in sys.modules).

    A second call for the same repository returns the same module; a different
    repository already imported under ``name`` is an error.
    """
    root = Path(repo_root).resolve()
    if name in sys.modules:
        module = sys.modules[name]
        loaded_from = Path(module.__path__[0]).resolve()
        if loaded_from != root:
            raise ImportError(f"{name!r} is already imported from {loaded_from}, not {root}")
        return module

    folder = tempfile.mkdtemp(prefix=f"{name}_link_")
    # rmtree removes the link itself, never what it points to.
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    link = Path(folder) / name
    os.symlink(root, link, target_is_directory=True)

    spec = importlib.util.spec_from_file_location(
        name, link / "__init__.py", submodule_search_locations=[str(link)]
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


def isolate_blender_user_folder(prefix: str = "curved_reflections_blender_user_") -> None:
    """Point ``BLENDER_USER_RESOURCES`` at a temporary folder, removed at exit, unless set.

    Call before ``bpy`` is imported, so no script or test reads or writes the user's
    real Blender configuration.
    """
    if not os.environ.get("BLENDER_USER_RESOURCES"):
        folder = tempfile.mkdtemp(prefix=prefix)
        os.environ["BLENDER_USER_RESOURCES"] = folder
        atexit.register(shutil.rmtree, folder, ignore_errors=True)


def import_registered(repo_root, prefix: str = "curved_reflections_blender_user_"):
    """The repository imported as ``curved_reflections`` and registered with Blender,
    in an isolated Blender user folder (for scripts: the demo, the benchmarks)."""
    isolate_blender_user_folder(prefix)
    package = import_as_package(repo_root)
    package.register()
    return package
