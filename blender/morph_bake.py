# SPDX-License-Identifier: GPL-3.0-or-later
"""Bake and clear morphing grids (SBC paper VI), and the morphing status for the panel.

``curved_reflections.bake_morphing`` bakes the grid of every visible reflector whose
mode is Morphing (panoramic sample-based cameras at the nodes) or Octree (ray octrees at
the nodes, Martin & Popescu 2004): the grid each mode needs (``engine/baking/bake.py``: worker
processes, one node each). Invoked from the
UI it is modal: the bake runs on a thread that drives the worker processes, the window
manager's progress bar and the panel's status line follow it, and Esc cancels between
nodes (the previous cache stays as it was). ``execute`` (scripts, background mode)
bakes synchronously. ``curved_reflections.clear_morphing`` removes the baked grids.

:func:`load_morphing` is what drawing code calls per reflector: it returns the baked
grid, or None with the reason recorded for :func:`morph_status` (runtime mode is then
used), so a missing, stale or corrupt cache never stops drawing.
"""

from __future__ import annotations

import hashlib
import shutil
import threading
from pathlib import Path

import bpy
import numpy as np
from bpy.app.handlers import persistent

from ..engine.baking import bake, bake_cache
from ..engine.errors import SceneInputError
from ..engine.heap import release_freed_memory
from ..engine.methods.morphing.morph_grid import TETRAHEDRAL, MorphSettings
from ..drawing.methods.morph_source import GPUFaceImages
from ..drawing.methods.polish_gpu import GPUImagePolish
from . import method_plan, scene_changes
from .capture import capture_scene
from .scene_status import SceneStatus, status_of


def cache_root(scene) -> Path:
    """The folder holding every file's grids: the scene's *Cache Folder* when set (a
    folder a render farm shares; ``//`` is the .blend's folder), else the extension's
    user folder (``extension_path_user``)."""
    chosen = scene.curved_reflections.morph_cache_dir.strip()
    if chosen:
        return Path(bpy.path.abspath(chosen))
    package = __package__.rpartition(".")[0]
    try:
        path = bpy.utils.extension_path_user(package, path="morphing", create=True)
    except ValueError:  # not installed as an extension (tests, scripts importing the repository)
        path = bpy.utils.user_resource('CONFIG', path="curved_reflections_morphing", create=True)
    return Path(path)


def file_token(filepath: str, shared: bool) -> str:
    """This .blend file's sub-folder of the cache root: its name and a hash of its full
    path (``shared``, a chosen cache folder: its name alone, so that farm machines that
    mount the file elsewhere find one cache); "unsaved" for a file never saved."""
    if not filepath:
        return "unsaved"
    path = Path(filepath)
    stem = bake_cache.safe_name(path.stem)
    if shared:
        return stem
    return f"{stem}-{hashlib.sha256(str(path.resolve()).encode()).hexdigest()[:12]}"


def cache_directory(scene) -> Path:
    """Where this file's baked grids live: one folder per .blend file under
    :func:`cache_root`, so that two files never load, replace or clear each other's
    grids, even of objects with the same name."""
    shared = bool(scene.curved_reflections.morph_cache_dir.strip())
    return cache_root(scene) / file_token(bpy.data.filepath, shared)


_SAVED_FROM: dict = {}


@persistent
def on_save_pre(*_args) -> None:
    """Remember each scene's cache folder before the file is saved (maybe under a new name)."""
    _SAVED_FROM.clear()
    _SAVED_FROM.update({scene.name: cache_directory(scene) for scene in bpy.data.scenes})


#: Guards a scene's running bake against a save carrying its folder meanwhile.
_CARRY_LOCK = threading.Lock()


@persistent
def on_save_post(*_args) -> None:
    """A file saved under a new name takes its grids along: an unsaved file's are moved,
    another file's copied (that file keeps its own). A scene whose bake is running keeps
    baking into the folder it started in, and its grids are carried once it ends
    (:func:`_carry_after_bake`): moving the folder under the bake broke it."""
    for scene in bpy.data.scenes:
        old, new = _SAVED_FROM.get(scene.name), cache_directory(scene)
        if old is None or old == new:
            continue
        status = status_of(scene)
        with _CARRY_LOCK:
            if status.bake.get("running"):
                earlier = status.bake.get("carry")  # saved twice during the bake: from where it bakes
                status.bake["carry"] = (earlier[0] if earlier else old, new)
                continue
        if not old.is_dir() or new.exists():
            continue
        try:
            _carry(old, new)
        except OSError as error:
            status.bake = {"running": False, "done": 0, "total": 0, "reflector": "",
                           "message": f"The morphing grids were not carried to {new}: {error}"}
    _SAVED_FROM.clear()


def _carry(old: Path, new: Path) -> None:
    """Move an unsaved file's grids to its new folder, or copy another file's there (the
    grids already in the new folder stay)."""
    if old.name == "unsaved" and not new.exists():
        shutil.move(str(old), str(new))
        return
    shutil.copytree(old, new, dirs_exist_ok=True)
    if old.name == "unsaved":
        shutil.rmtree(old, ignore_errors=True)


def _carry_after_bake(state: dict) -> str:
    """Once a bake ends (``state``: its scene's ``SceneStatus.bake``): carry its file's
    grids to where a save during the bake moved the file; what went wrong, or ""."""
    with _CARRY_LOCK:
        carry = state.pop("carry", None)
        state["running"] = False
    if carry is None or not carry[0].is_dir():
        return ""
    try:
        _carry(*carry)
    except OSError as error:
        return f"the morphing grids were not carried to {carry[1]}: {error}"
    return ""


#: Cube-face resolution of the baked cameras (MorphSettings' default); tests lower it.
FACE_RESOLUTION = MorphSettings.face_resolution


def morph_settings(scene, kind: str = TETRAHEDRAL) -> MorphSettings:
    """The grid settings of ``scene.curved_reflections`` (grid nodes and margin) for a
    grid of ``kind``: ray octrees at the nodes (Martin & Popescu 2004) or panoramic
    sample-based cameras (SBC paper VI)."""
    settings = scene.curved_reflections
    return MorphSettings(grid=tuple(settings.morph_grid), margin=float(settings.morph_margin),
                         face_resolution=FACE_RESOLUTION, kind=kind)


def reflector_settings(scene, reflector) -> MorphSettings:
    """:func:`morph_settings` for the grid the reflector's mode needs (``method_plan.grid_kind_wanted``)."""
    return morph_settings(scene, method_plan.grid_kind_wanted(scene, reflector) or TETRAHEDRAL)


def morph_status(scene, per_reflector: bool = True) -> str:
    """One line: a bake in progress, else the last bake's outcome and (``per_reflector``)
    the last outcome of bake, clear, load or draw of each reflector."""
    status = status_of(scene)
    state = status.bake
    if state and state["running"]:
        return f"Baking {state['reflector']}: {state['done']}/{state['total']} nodes (Esc cancels)"
    if not per_reflector:
        return state.get("message", "") if state else ""
    lines = [f"{name}: {text}" for name, text in sorted(status.grid_lines.items())]
    if state and state.get("message") and not set(state["message"].split("; ")) <= set(lines):
        lines.insert(0, state["message"])  # what the reflectors' lines do not already say
    return "; ".join(lines) if lines else "No morphing grid baked in this session"


def morphing_reflectors(context):
    """(captured reflector, object matrix) of every visible reflector that wants a grid
    (Morphing or Octree mode, or Auto where it is not star-shaped)."""
    depsgraph = context.evaluated_depsgraph_get()
    captured = capture_scene(depsgraph)
    chosen = []
    for reflector in captured.reflectors:
        obj = context.scene.objects.get(reflector.name)
        if obj is None or not method_plan.wants_grid(context.scene, reflector):
            continue
        chosen.append((reflector, np.array(obj.matrix_world, dtype=np.float64)))
    return chosen


def adopt_renamed_grid(reflector, matrix, scene, settings: MorphSettings) -> bool:
    """Whether a grid this reflector had under an old name (the mirror was renamed, or
    a rename undone) was given its name (``bake_cache.adopt_grid``)."""
    return bake.adopt_renamed(reflector, matrix, settings, cache_directory(scene), bpy.data.objects.keys()) is not None


def load_morphing(reflector, matrix, scene, reflector_index: int = 0):
    """The baked grid for this reflector as it is now (its grid under an old name too),
    or None (runtime mode) with the reason recorded."""
    settings, directory = reflector_settings(scene, reflector), cache_directory(scene)
    polish = scene.curved_reflections.morph_polish_nodes
    try:
        try:
            grid = bake.load_for(reflector, matrix, settings, directory, reflector_index, polish=polish)
        except bake_cache.CacheError as error:
            if error.reason not in ("missing", "stale") or not adopt_renamed_grid(reflector, matrix, scene, settings):
                raise
            grid = bake.load_for(reflector, matrix, settings, directory, reflector_index, polish=polish)
    except SceneInputError as error:
        status_of(scene).grid_lines[reflector.name] = f"{error.problem}"
        return None
    status_of(scene).grid_lines[reflector.name] = "morphing (baked grid loaded)"
    return grid


def load_grids(scene, reflectors, bake_missing: bool = False, warnings: list | None = None) -> list:
    """(grid, object matrix) of each reflector in Morphing or Octree mode (or Auto, where
    it is not star-shaped) whose baked grid matches it; the others are drawn in runtime mode
    (:func:`load_morphing` records why). With ``bake_missing`` (Render Image) a reflector
    set to Morphing or Octree mode whose grid is missing, stale or unfinished is baked first, in
    this process, on every core; where that bake cannot write its cache, a message
    naming the reflector is added to ``warnings``. The grids' nodes project, and their
    images are polished (*Polish Node Images*), on the GPU."""
    faces, polish = GPUFaceImages(), GPUImagePolish()
    grids = []
    for index, reflector in enumerate(reflectors):
        obj = scene.objects.get(reflector.name)
        if obj is None or not method_plan.wants_grid(scene, reflector):
            continue
        matrix = np.array(obj.matrix_world, dtype=np.float64)
        grid = load_morphing(reflector, matrix, scene, index)
        if grid is None and bake_missing and obj.curved_reflections.mode in method_plan.GRID_MODES \
                and _bake_if_missing(reflector, matrix, scene, warnings):
            grid = load_morphing(reflector, matrix, scene, index)
        if grid is not None:
            grid.face_images, grid.image_polish = faces, polish
            grids.append((grid, matrix))
    return grids


def _bake_if_missing(reflector, matrix, scene, warnings: list | None = None) -> bool:
    """Bake this reflector's grid where none matching it is whole (the nodes already baked
    are kept); returns whether it baked. A damaged node file is found, and rebuilt by the
    next bake, when it is read. A cache folder that cannot be written leaves the
    reflector in runtime mode, with the reason in its panel line and in ``warnings``."""
    settings, directory = reflector_settings(scene, reflector), cache_directory(scene)
    try:
        bake.load_for(reflector, matrix, settings, directory)
    except SceneInputError as error:
        if getattr(error, "reason", "") == "corrupt":
            return False
        reason = {"missing": "none baked yet", "stale": "it was baked for other geometry or settings",
                  "incomplete": "its bake is unfinished"}.get(getattr(error, "reason", ""), error.problem)
        print(f"Curved Reflections: baking the morphing grid of {reflector.name!r} first: {reason}")
        try:
            bake.bake_grid(reflector, matrix, settings, directory)
        except OSError as failure:  # a cache folder that is read-only, full, or not a folder
            message = (f"{reflector.name!r}: its morphing grid could not be baked into {str(directory)!r} "
                       f"({failure.strerror or failure}); drawn in runtime mode (set a writable Cache Folder)")
            status_of(scene).grid_lines[reflector.name] = f"runtime mode: {message.partition(': ')[2]}"
            if warnings is not None:
                warnings.append(message)
            return False
        return True
    return False


def note_cache_fault(status: SceneStatus, reflector_name: str, error) -> None:
    """Record a damaged cache met while drawing: runtime mode, and which file."""
    status.grid_lines[reflector_name] = f"runtime mode: {error.problem}"


def note_runtime_fallback(status: SceneStatus, error) -> None:
    """Record a ViewOutsideGrid (the view left the grid) for the status line: runtime mode is drawn."""
    status.grid_lines[error.reflector_name] = f"runtime mode: {error.reason}"


def note_morphing_active(status: SceneStatus, reflector_name: str) -> None:
    """Record that the live view draws this reflector from its baked grid."""
    status.grid_lines[reflector_name] = "morphing: the view is inside the baked grid"


def reflector_modes(scene) -> list[tuple[str, str]]:
    """(reflector, which mode draws it and why) for every reflector of ``scene`` in
    Morphing mode: the last load, bake or draw outcome recorded for it."""
    lines = []
    for obj in scene.objects:
        settings = obj.curved_reflections
        if settings.is_reflector and method_plan.grid_wanted_by_last_plan(scene, obj):
            lines.append((obj.name, status_of(scene).grid_lines.get(obj.name, "runtime mode: not baked or loaded yet")))
    return lines


def _refresh_live(context) -> None:
    """Tell the live view that grids changed (it reloads them with the reflectors)."""
    scene_changes.notify(context, reflectors=True)


class CURVED_REFLECTIONS_OT_bake_morphing(bpy.types.Operator):
    """Bake the grids of the reflectors in Morphing or Octree mode (Esc cancels; the nodes baked so far are kept)"""

    bl_idname = "curved_reflections.bake_morphing"
    bl_label = "Bake Morphing Grid"
    bl_options = {'REGISTER'}

    processes: bpy.props.IntProperty(name="Processes", description="Worker processes (0: every core)",
                                     default=0, min=0, max=256)
    object_name: bpy.props.StringProperty(
        name="Object", description="Bake only this reflector (empty: every reflector in Morphing or Octree mode)",
        default="")
    nodes: bpy.props.StringProperty(
        name="Nodes", description="Bake only these grid nodes, 'first-last' (e.g. 0-99) or 'first-': one range of a "
        "render farm's job; nodes already baked are skipped (empty: every node)", default="")

    _thread = None
    _timer = None

    @classmethod
    def poll(cls, context):
        if context.scene is None:
            return False
        state = status_of(context.scene).bake
        return not (state and state["running"])

    def _jobs(self, context):
        try:
            jobs = morphing_reflectors(context)
        except SceneInputError as error:
            self.report({'ERROR'}, str(error))
            return None
        if self.object_name:
            jobs = [job for job in jobs if job[0].name == self.object_name]
            if not jobs:
                self.report({'ERROR'}, f"{self.object_name!r}: not a visible reflector in Morphing or Octree mode")
                return None
        if not jobs:
            self.report({'ERROR'}, "No visible reflector is in Morphing or Octree mode (set Mode in the Reflections "
                        "tab)")
            return None
        return jobs

    def _run(self, status: SceneStatus, jobs, directory, cancel):
        """Bake each reflector in turn (on the bake thread, or inline from execute) and
        keep the progress in the scene's ``status``: ``jobs`` are (reflector, object
        matrix, the settings of the grid its mode needs)."""
        state = status.bake
        outcome = []
        try:
            for reflector, matrix, settings in jobs:
                state.update(reflector=reflector.name, done=0, total=int(np.prod(settings.grid)))

                def progress(done, total, state=state):
                    state.update(done=done, total=total)

                result = bake.bake_grid(reflector, matrix, settings, directory, processes=self.processes or None,
                                        progress=progress, cancel=cancel,
                                        nodes=bake.parse_node_range(self.nodes, int(np.prod(settings.grid))))
                if result.cancelled:
                    status.grid_lines[reflector.name] = ("bake cancelled; the nodes baked are kept, the next bake "
                                                         "goes on from there")
                    outcome.append(f"{reflector.name}: cancelled")
                    break
                done = f"baked {result.n_built} nodes in {result.seconds:.1f} s ({result.nbytes / 2**20:.1f} MB)"
                if result.n_skipped:
                    done += f", {result.n_skipped} were baked already"
                elif result.replaced:
                    done += "; the mirror's shape or its grid settings changed since its last bake, so no node was reused"
                if result.directory is None:
                    done += f"; {result.n_baked} of {result.n_nodes} nodes baked, the other ranges still to bake"
                status.grid_lines[reflector.name] = done
                outcome.append(f"{reflector.name}: {done}")
        except (SceneInputError, OSError, ValueError) as error:
            outcome.append(f"bake failed: {error}")
        except Exception as error:  # the bake thread's boundary: report, never leave "running" behind
            outcome.append(f"bake failed: {type(error).__name__}: {error}")
        finally:
            release_freed_memory()  # the bake's node cameras, freed in this process's heap
            carried = _carry_after_bake(state)
            state.update(running=False, message="; ".join(outcome + ([carried] if carried else [])))
        return outcome

    def _start(self, context):
        jobs = self._jobs(context)
        if jobs is None:
            return None
        try:
            jobs = [(reflector, matrix, reflector_settings(context.scene, reflector))
                    for reflector, matrix in jobs]
            bake.parse_node_range(self.nodes, int(np.prod(jobs[0][2].grid)))
            for reflector, matrix, settings in jobs:  # a renamed mirror bakes on into its grid
                adopt_renamed_grid(reflector, matrix, context.scene, settings)
        except (SceneInputError, ValueError) as error:
            self.report({'ERROR'}, str(error))
            return None
        status_of(context.scene).bake = {"running": True, "done": 0, "total": 0, "reflector": jobs[0][0].name,
                                         "message": ""}
        return jobs, cache_directory(context.scene)

    def execute(self, context):
        started = self._start(context)
        if started is None:
            return {'CANCELLED'}
        outcome = self._run(status_of(context.scene), *started, threading.Event())
        failed = any("failed" in line for line in outcome)
        self.report({'ERROR'} if failed else {'INFO'}, "; ".join(outcome))
        _refresh_live(context)
        return {'CANCELLED'} if failed else {'FINISHED'}

    def invoke(self, context, event):
        started = self._start(context)
        if started is None:
            return {'CANCELLED'}
        self._cancel = threading.Event()
        self._status = status_of(context.scene)
        self._thread = threading.Thread(target=self._run, args=(self._status, *started, self._cancel),
                                        daemon=True)
        self._thread.start()
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.2, window=context.window)
        wm.modal_handler_add(self)
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        if event.type == 'ESC':
            self._cancel.set()
        if event.type != 'TIMER':
            return {'PASS_THROUGH'} if event.type != 'ESC' else {'RUNNING_MODAL'}
        state = self._status.bake
        context.window_manager.progress_update(int(100 * state["done"] / max(state["total"], 1)))
        for area in context.screen.areas if context.screen else ():
            area.tag_redraw()
        if self._thread.is_alive():
            return {'RUNNING_MODAL'}
        context.window_manager.event_timer_remove(self._timer)
        context.window_manager.progress_end()
        message = state.get("message", "")
        cancelled = "cancelled" in message
        _refresh_live(context)
        self.report({'WARNING'} if cancelled or "failed" in message else {'INFO'}, message or "Bake finished")
        return {'CANCELLED'} if cancelled or "failed" in message else {'FINISHED'}


class CURVED_REFLECTIONS_OT_clear_morphing(bpy.types.Operator):
    """Remove the baked morphing grids of this file's reflectors (runtime mode until baked again)"""

    bl_idname = "curved_reflections.clear_morphing"
    bl_label = "Clear Morphing Grid"
    bl_options = {'REGISTER'}

    def execute(self, context):
        status = status_of(context.scene)
        if status.bake and status.bake["running"]:
            self.report({'ERROR'}, "A bake is running: cancel it first (Esc)")
            return {'CANCELLED'}
        names = [obj.name for obj in context.scene.objects if obj.curved_reflections.is_reflector]
        removed = sum(bake_cache.clear_cache(cache_directory(context.scene), name) for name in names)
        for name in names:
            status.grid_lines[name] = "no morphing cache (cleared); runtime mode"
        self.report({'INFO'}, f"Removed {removed} baked grid(s)")
        _refresh_live(context)
        return {'FINISHED'}


classes = (
    CURVED_REFLECTIONS_OT_bake_morphing,
    CURVED_REFLECTIONS_OT_clear_morphing,
)
