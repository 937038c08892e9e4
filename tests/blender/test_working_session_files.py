# SPDX-License-Identifier: GPL-3.0-or-later
"""The working-session corpus, files and bakes (issue 46): saving, undoing and reloading
around a morphing bake, moving the .blend, a mirror from a library file, a cache folder
that cannot be written, a farm worker killed mid-node. Each case ends in the right
picture (the picture of the same state rendered afresh) or a clear message, with no
traceback and the user's data unchanged. The live-view cases are in
test_working_session.py; docs/benchmarks/reliability.md lists every case.

A UI bake runs on a thread while Blender's main thread goes on (``invoke``); here the
operator's own bake body (``_run``) runs on a thread the same way, held after a few nodes
while the main thread saves or undoes.
"""

import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import bpy
import numpy as np
import pytest

from curved_reflections.blender import morph_bake
from curved_reflections.blender.scene_status import status_of
from curved_reflections.engine.baking import bake

from session_scene import build, differing, render

REPO_ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def files(empty_scene, registered, gpu_ready, monkeypatch, tmp_path, capfd):
    """The corpus scene in Morphing mode (a 2x2x2 grid, quick nodes); grids go under
    tmp_path unless the scene names a Cache Folder. No case may print a traceback."""
    monkeypatch.setattr(morph_bake, "FACE_RESOLUTION", 16)
    root = morph_bake.cache_root
    monkeypatch.setattr(morph_bake, "cache_root", lambda scene: root(scene) if
                        scene.curved_reflections.morph_cache_dir.strip() else tmp_path / "cache")
    scene = build(mode='MORPHING')
    scene.curved_reflections.morph_grid = (2, 2, 2)
    yield scene
    captured = capfd.readouterr()
    assert "Traceback" not in captured.out + captured.err


def _held_bake(scene, at_node: int = 3):
    """The Bake operator's body on a thread, held once ``at_node`` nodes are done:
    (thread, release, the scene's status)."""
    reached, release = threading.Event(), threading.Event()
    real = bake.bake_grid

    def held(*args, progress=None, **kwargs):
        def step(done, total):
            progress(done, total)
            if done == at_node:
                reached.set()
                release.wait(60)
        return real(*args, progress=step, **kwargs)

    jobs = [(reflector, matrix, morph_bake.reflector_settings(scene, reflector))
            for reflector, matrix in morph_bake.morphing_reflectors(bpy.context)]
    status = status_of(scene)
    status.bake = {"running": True, "done": 0, "total": 0, "reflector": "Ball", "message": ""}
    operator = SimpleNamespace(processes=1, nodes="")
    bake.bake_grid = held
    thread = threading.Thread(target=morph_bake.CURVED_REFLECTIONS_OT_bake_morphing._run,
                              args=(operator, status, jobs, morph_bake.cache_directory(scene), threading.Event()))
    thread.start()
    assert reached.wait(60)
    bake.bake_grid = real
    return thread, release, status


def _loaded(scene=None):
    scene = scene or bpy.context.scene
    (reflector, matrix), = morph_bake.morphing_reflectors(bpy.context)
    return morph_bake.load_morphing(reflector, matrix, scene)


def test_save_as_during_a_bake_of_an_unsaved_file(files, tmp_path):
    """The grid goes with the file: the bake finishes in the folder it started in, and
    the grids are carried to the saved file's folder when it ends."""
    thread, release, status = _held_bake(files)
    assert morph_bake.cache_directory(files).name == "unsaved"
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "shot.blend"))
    release.set()
    thread.join(60)
    assert "failed" not in status.bake["message"] and "Ball: baked 8 nodes" in status.bake["message"]
    assert not status.bake["running"] and "carry" not in status.bake
    folder = morph_bake.cache_directory(bpy.context.scene)
    assert folder.name.startswith("shot-") and len(list(folder.glob("Ball-*/node_*"))) == 8
    assert not (tmp_path / "cache" / "unsaved").exists()
    assert _loaded() is not None


def test_undo_during_a_bake(files):
    """The bake goes on with the mirror it started with; undone, the mirror no longer
    matches it, and its line says so (runtime mode until baked again). Nothing the bake
    did changed the user's data."""
    bpy.ops.ed.undo_push(message="before")
    bpy.data.objects["Ball"].scale = (1.2, 1.0, 1.0)
    bpy.context.view_layer.update()
    bpy.ops.ed.undo_push(message="scaled")
    thread, release, status = _held_bake(bpy.context.scene)
    assert bpy.ops.ed.undo() == {'FINISHED'}
    release.set()
    thread.join(60)
    assert "Ball: baked 8 nodes" in status.bake["message"]
    assert tuple(bpy.data.objects["Ball"].scale) == pytest.approx((1.0, 1.0, 1.0))
    assert _loaded() is None
    assert "baked for other geometry or settings" in morph_bake.morph_status(bpy.context.scene)
    assert bpy.ops.ed.redo() == {'FINISHED'}  # the scaled mirror again: its grid is whole
    assert _loaded() is not None


def test_reload_and_move_the_file_with_a_relative_cache_folder(files, tmp_path, capfd):
    """Bake, reload the file, move its folder elsewhere: the "//" cache folder goes with
    it, the grid is found without baking again, and the picture is the same."""
    first = tmp_path / "project"
    first.mkdir()
    files.curved_reflections.morph_cache_dir = "//cache"
    bpy.ops.wm.save_as_mainfile(filepath=str(first / "shot.blend"))
    picture = render()
    assert "baking the morphing grid of 'Ball' first" in capfd.readouterr().out
    bpy.ops.wm.revert_mainfile()
    assert differing(render(), picture) == 0.0
    moved = tmp_path / "elsewhere" / "project"
    shutil.move(str(first), str(moved))
    bpy.ops.wm.open_mainfile(filepath=str(moved / "shot.blend"))
    scene = bpy.context.scene
    assert morph_bake.cache_directory(scene).parent == moved / "cache"
    assert differing(render(scene), picture) == 0.0
    out = capfd.readouterr().out
    assert "baking the morphing grid" not in out
    assert "morphing (baked grid loaded)" in morph_bake.morph_status(scene)


def test_a_mirror_linked_from_a_library_file(empty_scene, registered, gpu_ready, tmp_path, capfd):
    build()
    library = tmp_path / "props.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(library))
    picture = render()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    with bpy.data.libraries.load(str(library), link=True) as (source, target):
        target.objects = ["Ball", "Box", "Camera"]
    scene = bpy.context.scene
    for obj in target.objects:
        scene.collection.objects.link(obj)
    scene.camera = bpy.data.objects["Camera"]
    scene.render.resolution_x, scene.render.resolution_y = picture.shape[1], picture.shape[0]
    scene.curved_reflections.max_order = 1
    ball = bpy.data.objects["Ball"]
    assert ball.library is not None and ball.curved_reflections.is_reflector  # its settings come with it
    assert differing(render(scene), picture) == 0.0
    assert bpy.ops.curved_reflections.start_live() == {'FINISHED'}
    assert "Traceback" not in capfd.readouterr().err


@pytest.mark.parametrize("case", ["read_only", "full"])
def test_a_cache_folder_that_cannot_be_written(files, tmp_path, monkeypatch, capfd, case):
    """Bake says why it failed; Render Image draws the mirror in runtime mode, as a
    Runtime render does, and warns naming it and the folder; the next render with a
    writable folder bakes."""
    savez_compressed = np.savez_compressed
    if case == "read_only":  # a folder below a file: no one, root neither, can write there
        (tmp_path / "locked").write_text("a file")
        files.curved_reflections.morph_cache_dir = str(tmp_path / "locked" / "cache")
        problem = "Not a directory"
    else:
        def full(*args, **kwargs):
            raise OSError(28, "No space left on device")
        monkeypatch.setattr(np, "savez_compressed", full)
        problem = "No space left on device"
    with pytest.raises(RuntimeError, match=f"bake failed: .*{problem}"):
        bpy.ops.curved_reflections.bake_morphing(processes=1)
    assert not status_of(files).bake["running"]
    assert bpy.ops.curved_reflections.render_image(filepath=str(tmp_path / "image.png")) == {'FINISHED'}
    out = capfd.readouterr().out
    assert f"Warning: 'Ball': its morphing grid could not be baked into" in out and problem in out
    line = dict(morph_bake.reflector_modes(files))["Ball"]
    assert line.startswith("runtime mode: its morphing grid could not be baked") and problem in line
    morphing_fallback = render()
    bpy.data.objects["Ball"].curved_reflections.mode = 'RUNTIME'
    assert differing(render(), morphing_fallback) == 0.0
    monkeypatch.setattr(np, "savez_compressed", savez_compressed)
    files.curved_reflections.morph_cache_dir = ""
    bpy.data.objects["Ball"].curved_reflections.mode = 'MORPHING'
    render()
    assert _loaded() is not None


_KILLED_WORKER = """
import importlib.util, sys, time
spec = importlib.util.spec_from_file_location("link", sys.argv[1] + "/scripts/package_link.py")
link = importlib.util.module_from_spec(spec)
spec.loader.exec_module(link)
link.import_as_package(sys.argv[1])
import bpy
import curved_reflections
from curved_reflections.blender import morph_bake
from curved_reflections.engine.baking import bake_cache
bpy.ops.wm.open_mainfile(filepath=sys.argv[2])
curved_reflections.register()
morph_bake.FACE_RESOLUTION = 16
write = bake_cache.write_node
def stalled(directory, node, key, arrays):
    if len(list(directory.glob("node_*"))) == 2:  # the third node: killed while writing it
        (directory / f".node_{node:05d}.npz.{sys.argv[3]}.tmp").write_bytes(b"half a node")
        print("WRITING", flush=True)
        time.sleep(600)
    write(directory, node, key, arrays)
bake_cache.write_node = stalled
bpy.ops.curved_reflections.bake_morphing(processes=1, nodes="")
"""


def test_a_farm_worker_killed_mid_node(files, tmp_path, capfd):
    """A farm task is killed while writing its third node: the two nodes it finished
    stay, its half-written file is never read, and the next task bakes the rest only."""
    files.curved_reflections.morph_cache_dir = str(tmp_path / "farm")
    blend = tmp_path / "shot.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    worker = subprocess.Popen([sys.executable, "-c", _KILLED_WORKER, str(REPO_ROOT), str(blend), "killed"],
                              env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        for line in worker.stdout:
            if line.startswith("WRITING"):
                break
        worker.send_signal(signal.SIGKILL)
    finally:
        worker.wait(60)
    assert worker.returncode == -signal.SIGKILL
    (folder,) = (tmp_path / "farm" / "shot").glob("Ball-*")
    assert len(list(folder.glob("node_*.npz"))) == 2 and len(list(folder.glob(".*.tmp"))) == 1
    assert _loaded() is None
    assert "the morphing cache has 2 of 8 nodes" in morph_bake.morph_status(files)
    (abandoned,) = folder.glob(".*.tmp")
    os.utime(abandoned, (time.time() - 3600.0,) * 2)  # the next bake comes an hour later
    assert bpy.ops.curved_reflections.bake_morphing(processes=1) == {'FINISHED'}
    assert "baked 6 nodes" in capfd.readouterr().out
    assert not abandoned.exists() and not list(folder.glob(".*.tmp"))
    assert _loaded() is not None
    baked = render()
    bpy.data.objects["Ball"].curved_reflections.mode = 'RUNTIME'
    assert differing(baked, render(), 0.05) < 0.03  # the grid's picture is the exact camera's
