# SPDX-License-Identifier: GPL-3.0-or-later
"""Run in fresh Pythons by test_packaging: the render-farm bake of the user guide.

``python farm_probe.py install EXTENSION.zip SCENE.blend CACHE``: installs the zip (the
user folder is ``BLENDER_USER_RESOURCES``) and saves a scene with a mirror ball in
Morphing mode whose cache folder is CACHE. ``python farm_probe.py bake SCENE.blend
RANGE [CACHE]``: what a farm task runs, as the user guide writes it for the ``bpy``
module (CACHE, when given, replaces the scene's cache folder for this run).
"""

import sys

import bpy

MODULE = "bl_ext.user_default.curved_reflections"


def install(zip_path, blend_path, cache):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo='user_default', enable_on_install=True)
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0.5, 0.0, 1.0), segments=24, ring_count=12)
    ball = bpy.context.active_object
    ball.name = "Ball"
    ball.curved_reflections.is_reflector = True
    ball.curved_reflections.mode = 'MORPHING'
    scene.curved_reflections.morph_grid = (2, 2, 2)
    scene.curved_reflections.morph_margin = 2.5  # nodes far from the ball: small cube faces, a quick bake
    scene.curved_reflections.morph_cache_dir = cache
    bpy.ops.wm.save_as_mainfile(filepath=blend_path)


def bake(blend_path, nodes, cache=None):
    # The user guide's farm task, bpy module form:
    import addon_utils

    bpy.ops.wm.open_mainfile(filepath=blend_path)
    addon_utils.enable(MODULE, default_set=True)
    if cache is not None:
        bpy.context.scene.curved_reflections.morph_cache_dir = cache
    result = bpy.ops.curved_reflections.bake_morphing(object_name="Ball", nodes=nodes, processes=1)
    print("RESULT", sorted(result))


if __name__ == "__main__":
    {"install": install, "bake": bake}[sys.argv[1]](*sys.argv[2:])
