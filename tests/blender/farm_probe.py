# SPDX-License-Identifier: GPL-3.0-or-later
"""Run in fresh Pythons by test_packaging: the render-farm bake of the user guide.

``python farm_probe.py install EXTENSION.zip SCENE.blend CACHE [NODES [MARGIN]]``: installs
the zip (the user folder is ``BLENDER_USER_RESOURCES``) and saves a scene with a mirror ball
in Morphing mode whose cache folder is CACHE (a grid of NODES nodes along x, default 2, by
2 by 2, reaching MARGIN ball sizes beyond it, default 2.5: the farther, the smaller the ball
in the nodes' cube faces and the quicker a node bakes); and ``python farm_probe.py kettle KETTLE.blend``: a scene the user guide's
examples open, a mirror ball and a box in Auto mode, two frames. ``python farm_probe.py bake SCENE.blend
RANGE [CACHE]``: what a farm task runs, as the user guide writes it for the ``bpy``
module (CACHE, when given, replaces the scene's cache folder for this run).
"""

import sys

import bpy

MODULE = "bl_ext.user_default.curved_reflections"


def _ball(mode):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0.5, 0.0, 1.0), segments=24, ring_count=12)
    ball = bpy.context.active_object
    ball.name = "Ball"
    ball.curved_reflections.is_reflector = True
    ball.curved_reflections.mode = mode
    return ball


def install(zip_path, blend_path, cache, nodes="2", margin="2.5"):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo='user_default', enable_on_install=True)
    scene = bpy.context.scene
    _ball('MORPHING')
    scene.curved_reflections.morph_grid = (int(nodes), 2, 2)
    scene.curved_reflections.morph_margin = float(margin)  # nodes far from the ball: small cube faces, a quick bake
    scene.curved_reflections.morph_cache_dir = cache
    bpy.ops.wm.save_as_mainfile(filepath=blend_path)


def kettle(blend_path):
    import addon_utils

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    addon_utils.enable(MODULE, default_set=True)
    scene = bpy.context.scene
    _ball('AUTO')
    bpy.ops.mesh.primitive_cube_add(size=0.8, location=(2.0, -0.8, 0.6))
    bpy.ops.object.camera_add(location=(0.5, -7.0, 2.0), rotation=(1.4, 0.0, 0.0))
    scene.camera = bpy.context.active_object
    scene.render.resolution_x, scene.render.resolution_y = 64, 48  # the cube's reflection in the ball: a few pixels
    scene.frame_start, scene.frame_end = 1, 2
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
    {"install": install, "bake": bake, "kettle": kettle}[sys.argv[1]](*sys.argv[2:])
