# SPDX-License-Identifier: GPL-3.0-or-later
"""Run in a fresh Python by test_packaging: install the built zip as a user would, probe it.

Usage: python install_probe.py EXTENSION.zip RESULT.json  (BLENDER_USER_RESOURCES set
to an empty folder). Writes what it observed as JSON; the test asserts on it.
"""

import json
import sys
from pathlib import Path

import bpy

MODULE = "bl_ext.user_default.curved_reflections"


def registered_state():
    return {
        "addon_enabled": MODULE in bpy.context.preferences.addons,
        "panel": hasattr(bpy.types, "VIEW3D_PT_curved_reflections"),
        "check_scene_op": hasattr(bpy.types, "CURVED_REFLECTIONS_OT_check_scene"),
        "mark_reflector_op": hasattr(bpy.types, "CURVED_REFLECTIONS_OT_mark_reflector"),
        "object_settings": hasattr(bpy.types.Object, "curved_reflections"),
        "scene_settings": hasattr(bpy.types.Scene, "curved_reflections"),
    }


def main(zip_path, result_path):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    result = {"install": sorted(bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo='user_default', enable_on_install=True,
    ))}
    result["enabled"] = registered_state()
    module = sys.modules[MODULE]
    root = Path(module.__file__).parent
    result["installed_files"] = sorted(
        p.relative_to(root).as_posix() for p in root.rglob("*")
        if p.is_file() and "__pycache__" not in p.parts
    )

    # The installed add-on works end to end: its relative imports, capture and report.
    result["poll"] = bpy.ops.curved_reflections.check_scene.poll()
    bpy.ops.mesh.primitive_cube_add()
    bpy.context.active_object.curved_reflections.is_reflector = True
    result["check_scene"] = sorted(bpy.ops.curved_reflections.check_scene())

    bpy.ops.preferences.addon_disable(module=MODULE)
    result["disabled"] = registered_state()
    Path(result_path).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main(*sys.argv[1:3])
