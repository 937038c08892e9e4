# SPDX-License-Identifier: GPL-3.0-or-later
"""The shader cache (drawing/shader_cache.py): built once per arguments, released on
demand and before the interpreter exits, so that a headless process ends cleanly."""

import subprocess
import sys

from curved_reflections.drawing import shader_cache

#: A headless render in Iterative mode, then the interpreter's exit: before the shaders
#: were released at exit, the process died there with a segmentation fault (exit 139).
_HEADLESS_RENDER = """
import sys
sys.path.insert(0, {scripts!r})
import package_link
package_link.isolate_blender_user_folder()
package = package_link.import_as_package({root!r})
import bpy
package.register()
from curved_reflections.blender import demo_scenes
from curved_reflections.blender.render_image import render_scene
scene = demo_scenes.build("sbc_fig3", bpy.context.scene, 48, 32)
bpy.data.objects["MirrorSphere"].curved_reflections.mode = 'ITERATIVE'
print("methods", render_scene(scene, bpy.context.evaluated_depsgraph_get()).stats["methods"])
"""


def test_a_shader_is_built_once_per_arguments_and_released_on_demand():
    built = []

    @shader_cache.cached_shader
    def build(kind: str):
        built.append(kind)
        return object()

    first = build("a")
    assert build("a") is first and build("b") is not first and built == ["a", "b"]
    shader_cache.release_shaders()
    assert build("a") is not first and built == ["a", "b", "a"]


def test_a_headless_render_exits_cleanly(repo_root, tmp_path):
    script = _HEADLESS_RENDER.format(scripts=str(repo_root / "scripts"), root=str(repo_root))
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert "methods {'MirrorSphere': 'ITERATIVE'}" in run.stdout, run.stdout[-2000:] + run.stderr[-2000:]
    assert run.returncode == 0, run.stderr[-2000:]
