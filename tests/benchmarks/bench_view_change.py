# SPDX-License-Identifier: GPL-3.0-or-later
"""Cost of a view change in the live view (issue #5): runtime mode against morphing mode,
measured in one run.

    .venv/bin/python tests/benchmarks/bench_view_change.py          # docs/benchmarks/view_change.md
    .venv/bin/python tests/benchmarks/bench_view_change.py --quick --out /tmp/view_change.md

The sbc_fig3 demo (mirror ball) is built with bpy and captured, and a
``ReflectionRenderer`` made for its meshes, as the live view does. The eye walks a path
inside the ball's morphing grid (default settings, 9x9x5 nodes, 96 px faces; nodes built
on demand before the clock runs, their build reported apart): small steps, so that
several views share a tetrahedron, and jumps into others. Per view, what the live view
does after the view changed (``blender/live.py``):

- **runtime** (SBC paper IV-V): build the view's sample-based camera (ray map and trees),
  then the renderer's projection with it (textures uploaded, every vertex projected on
  the GPU and read back, reflected triangles decided);
- **morphing** (SBC paper VI, ``tools/numpy_morph_source.py``): the renderer's projection
  from the grid: in a tetrahedron the eye has just entered, the four nodes project the
  vertices (on the GPU, ``drawing/methods/morph_source.GPUFaceImages``; also timed
  with numpy) and the images are
  matched and blended; in the same tetrahedron as before, only the blend.

Medians over the path's views. On this project's machines the GPU is Mesa llvmpipe
(the CPU): compare the ratios measured in this one run, not absolute times.

**Morphing rows on the GPU** (``drawing/methods/morph_pass.py``, what the live view draws
now): the sbc_fig3 meshes split to about ``--vertices`` drawn vertices, the eye moving
``--orbit-degrees`` a frame along an arc inside the ball's grid, every node the path
uses projected once before the clock runs (as the prefetch does), each frame timed as
the viewport draws it and, apart, the morph pass alone (blend and reflected meshes) and
the blend alone, against the plain draw; the frames that enter a new tetrahedron are
counted.

**Iterative rows** (Roger & Holzschuch 2006, ``drawing/methods/iterative_draw.py``): the
star-shaped demo scenes with their meshes split to about ``--vertices`` drawn vertices,
the view orbiting by ``--orbit-degrees`` every frame, each frame timed as the viewport
draws it (``ReflectionRenderer.draw``: pre-pass, this frame's search from the last
frame's answers, reflected meshes, composite) and, apart, the iterative reflected pass
alone (search and reflected meshes), against the plain draw of the same meshes
(``bench_draw``: the renderer's diffuse triangles, one colour, depth test), medians of
the frames; and the same pass drawing every triangle, the far sides of closed solids
included (``ReflectedMeshes.draw`` culls them in mirrored images), on the same frames. Then ``render_image(animation=True)`` at 480x320 with the camera moving
every frame against Workbench's ``render.render(animation=True)`` on the same scene.

**Mirrors that are not star-shaped** (issue 44, ``view_change_shapes.py``): a torus and a
monkey head in Auto mode, the live view's first frame after each view change timed
against a Workbench frame, and compared with the same view's once rested.
"""

from __future__ import annotations

import argparse
import datetime
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import animation_runs  # noqa: E402  (same folder: views turned without a camera)
import bench_draw  # noqa: E402  (same folder: machine facts with the GPU)
import bench_sbc  # noqa: E402  (same folder: package import)
import view_change_shapes  # noqa: E402  (same folder: the rows of mirrors that are not star-shaped)

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_OUT = REPO_ROOT / "docs" / "benchmarks" / "view_change.md"


def eye_path(centre: np.ndarray, radius: float, steps: int, jumps: int) -> list:
    """Eyes at 2.3 radii from the ball: ``jumps`` arcs apart, ``steps`` views 0.4 degree apart on each."""
    eyes = []
    for jump in range(jumps):
        base = np.radians(-100.0 + 35.0 * jump)
        for step in range(steps):
            angle = base + np.radians(0.4 * step)
            eyes.append(centre + radius * np.array([2.3 * np.cos(angle), 2.3 * np.sin(angle), 0.7]))
    return eyes


def measure(width: int, height: int, steps: int, jumps: int) -> dict:
    import bpy

    from curved_reflections.engine import look_at_view
    from curved_reflections.engine.methods.morphing import morph_grid, morphing
    from curved_reflections.engine.methods.sbc import build_sample_based_camera
    from curved_reflections.engine.scene import scene_bounds
    from curved_reflections.drawing.methods.morph_source import GPUFaceImages
    from curved_reflections.tools.numpy_morph_source import MorphSource
    from curved_reflections.drawing.methods.sbc_gpu import SBCTextures
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer
    from curved_reflections.drawing.frame_pass import Frame
    from curved_reflections.engine.frame_settings import FrameSettings
    from curved_reflections.drawing.methods.morph_pass import MorphPass
    from curved_reflections.blender.frame_pipeline import settings_of
    from curved_reflections.blender import demo_scenes
    from curved_reflections.blender.capture import capture_scene
    from curved_reflections.blender.gpu_init import ensure_gpu
    from curved_reflections.blender.render_inputs import BOUNDS_MARGIN, reflector_appearance

    ensure_gpu()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, width, height)
    captured = capture_scene(bpy.context.evaluated_depsgraph_get())
    mirror = captured.reflectors[0]
    matrix = np.array(bpy.data.objects[mirror.name].matrix_world, dtype=np.float64)
    lo, hi = scene_bounds(captured.reflectors, captured.meshes)
    bounds = scene_bounds(captured.reflectors, captured.meshes, BOUNDS_MARGIN * float(np.linalg.norm(hi - lo)))
    settings = scene.curved_reflections
    colors, reflectivity = reflector_appearance(captured.reflectors, scene)
    renderer = ReflectionRenderer(captured.reflectors, captured.meshes, colors, reflectivity,
                                  settings=FrameSettings(polish_camera=False))  # as live

    local = morph_grid.reflector_in_frame(mirror, morph_grid.rigid_frame(matrix))
    grid = morphing.grid_on_demand(local, morph_grid.MorphSettings())
    centre = mirror.vertices.mean(axis=0)
    radius = float(np.max(np.linalg.norm(mirror.vertices - centre, axis=1)))
    views = [look_at_view(eye, centre, fov_y_deg=45.0, width=width, height=height)
             for eye in eye_path(centre, radius, steps, jumps)]
    start = time.perf_counter()
    tetrahedra = [grid.check_view(view, matrix)[0] for view in views]  # builds the nodes used
    node_seconds = time.perf_counter() - start

    def projection_ms(source, view, camera=None) -> float:
        begin = time.perf_counter()
        renderer.camera_pass.triangles_of(source, view, camera)
        return 1000.0 * (time.perf_counter() - begin)

    # Warm-up: shaders compiled, textures of a first camera packed.
    warm = build_sample_based_camera(captured.reflectors, views[0], bounds, downsample=settings.downsample,
                                     accuracy_px=settings.accuracy_px)
    projection_ms(SBCTextures(warm), views[0], warm)
    rows = []
    for face_images in (GPUFaceImages(), None):
        grid.face_images = face_images
        grid._static.clear()
        previous = None
        for index, (view, tet) in enumerate(zip(views, tetrahedra)):
            row = rows[index] if face_images is None else {"tetrahedron": tet, "entered": tet != previous}
            previous = tet
            key = "morph_gpu" if face_images is not None else "morph_numpy"
            row[key] = projection_ms(MorphSource([(grid, matrix)], view), view)
            if face_images is not None:
                begin = time.perf_counter()
                sbc = build_sample_based_camera(captured.reflectors, view, bounds, downsample=settings.downsample,
                                                accuracy_px=settings.accuracy_px)
                row["build"] = 1000.0 * (time.perf_counter() - begin)
                row["runtime_projection"] = projection_ms(SBCTextures(sbc), view, sbc)
                row["runtime"] = row["build"] + row["runtime_projection"]
                rows.append(row)
    return {"width": width, "height": height, "vertices": int(len(renderer.geometry.vertices)),
            "views": len(views), "node_seconds": node_seconds, "nodes_built": len(grid.nodes), "rows": rows}


def _median(rows: list, key: str, entered: bool | None = None) -> float:
    values = [r[key] for r in rows if entered is None or r["entered"] == entered]
    return statistics.median(values) if values else float("nan")


def report(result: dict, command: str, machine: str) -> str:
    rows = result["rows"]
    runtime = _median(rows, "runtime")
    same, entered = _median(rows, "morph_gpu", False), _median(rows, "morph_gpu", True)
    lines = [
        "# Cost of a view change: runtime mode against morphing mode",
        "",
        f"Generated {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC by `{command}` on {machine}.",
        "",
        f"sbc_fig3 at {result['width']}x{result['height']}, {result['vertices']:,} drawn diffuse vertices "
        f"(the renderer's pre-subdivided meshes), {result['views']} views on a path inside the default "
        f"9x9x5 grid; {result['nodes_built']} nodes built on demand first ({result['node_seconds']:.1f} s, "
        "not in the times below). Milliseconds, medians over the views:",
        "",
        "| what runs after the view changed | ms |",
        "|---|---:|",
        f"| runtime: camera build | {_median(rows, 'build'):.0f} |",
        f"| runtime: projection (GPU) | {_median(rows, 'runtime_projection'):.0f} |",
        f"| **runtime: total** | **{runtime:.0f}** |",
        f"| morphing, same tetrahedron (blend only) | {same:.0f} |",
        f"| morphing, new tetrahedron, node projections on the GPU | {entered:.0f} |",
        f"| morphing, new tetrahedron, node projections in numpy | {_median(rows, 'morph_numpy', True):.0f} |",
        "",
        f"Runtime over morphing: **{runtime / same:.1f}x** in the same tetrahedron, "
        f"{runtime / entered:.1f}x entering a new one "
        f"({sum(r['entered'] for r in rows)} of {len(rows)} views entered one).",
        "",
        "Per view (ms):",
        "",
        "| view | tetrahedron | entered | runtime build | runtime projection | morph (GPU nodes) | morph (numpy nodes) |",
        "|---:|---:|:---:|---:|---:|---:|---:|",
    ]
    for k, r in enumerate(rows):
        lines.append(f"| {k} | {r['tetrahedron']} | {'yes' if r['entered'] else ''} | {r['build']:.0f} | "
                     f"{r['runtime_projection']:.0f} | {r['morph_gpu']:.0f} | {r['morph_numpy']:.0f} |")
    lines += ["", "Accuracy of morphing against the exact solver: [morphing.md](morphing.md). The GPU here is "
              "Mesa llvmpipe, which runs on the same two CPU cores as numpy, so the node projections' "
              "GPU/numpy ratio on a hardware GPU is not measured by this table.", ""]
    return "\n".join(lines)


#: Star-shaped demo scenes the Iterative rows are measured on.
ITERATIVE_SCENES = ("sbc_fig3", "two_spheres")


def measure_iterative(kind: str, width: int, height: int, target_vertices: int, frames: int,
                      orbit_degrees: float) -> dict:
    """Per frame of an orbit: the viewport's draw and the iterative pass against a plain draw."""
    import gpu
    from mathutils import Matrix

    from curved_reflections.drawing.frame_pass import Frame
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer
    from curved_reflections.engine.frame_settings import FrameSettings
    from curved_reflections.drawing.methods.morph_pass import MorphPass
    from curved_reflections.blender.frame_pipeline import settings_of
    from curved_reflections.blender import method_plan
    from curved_reflections.blender.capture import view_from_camera
    from curved_reflections.blender.render_inputs import reflector_properties, world_color

    scene, depsgraph, captured = bench_draw.built_scene(kind, width, height)
    start = time.perf_counter()
    plan = method_plan.plan(scene, captured.reflectors)
    plan_seconds = time.perf_counter() - start
    assert len(plan.engines_of(method_plan.ITERATIVE)) == len(captured.reflectors), plan.choices
    levels = bench_draw.levels_for(captured, target_vertices)
    meshes = bench_draw.scaled_meshes(captured.meshes, levels)
    renderer = ReflectionRenderer(captured.reflectors, meshes, passes=plan.pass_factories(),
                                  settings=settings_of(scene, live=True),
                                  **reflector_properties(captured.reflectors, scene))
    searched = renderer.pass_named("iterative")
    g = renderer.geometry
    world = world_color(scene)
    views = animation_runs.orbit_views(view_from_camera(scene.camera, scene, depsgraph), orbit_degrees, frames)
    plain = bench_draw.PlainDraw(g)

    def matrix(view):
        translate = np.eye(4)
        translate[:3, 3] = g.shift
        return Matrix((np.asarray(view.projection_matrix) @ np.asarray(view.view_matrix) @ translate).tolist())

    def reflected_pass(view, cull: bool = True):
        searched.search(view, warm=True)
        gpu.state.depth_test_set('LESS')
        gpu.state.depth_mask_set(True)
        setup = searched.reflected_setup(Frame(view, targets, None, None, warm=True))
        if not cull:
            setup["mirrored"] = frozenset()
        renderer.meshes.draw(matrix(view), targets, setup, renderer._image, searched.answers())
        gpu.state.depth_test_set('NONE')
        gpu.state.depth_mask_set(False)

    times = {"frame": [], "iterative pass": [], "every triangle": [], "search": [], "plain": []}
    offscreen = gpu.types.GPUOffScreen(width, height, format='RGBA16F')
    try:
        with offscreen.bind():
            framebuffer = gpu.state.active_framebuffer_get()
            targets = renderer.targets(width, height)
            for view in views[:2]:  # warm-up: shaders built, textures uploaded
                renderer.draw(view, None, world, reflectors_only=True)
            for k, view in enumerate(views):
                framebuffer.clear(color=(0.0, 0.0, 0.0, 1.0))
                bench_draw.scene_depth(framebuffer, plain, view)
                times["frame"].append(bench_draw.timed(lambda: renderer.draw(view, None, world, reflectors_only=True),
                                                       framebuffer))
                following = views[(k + 1) % len(views)]
                times["iterative pass"].append(bench_draw.timed(lambda: reflected_pass(following), framebuffer))
                framebuffer.clear(depth=1.0)
                times["every triangle"].append(bench_draw.timed(lambda: reflected_pass(following, cull=False),
                                                                framebuffer))
                times["search"].append(bench_draw.timed(lambda: searched.search(view, warm=True), framebuffer))
                times["plain"].append(bench_draw.timed(lambda: plain.draw(view), framebuffer))
        counts = searched.status_counts()
    finally:
        offscreen.free()
    ms = {name: 1000.0 * statistics.median(values) for name, values in times.items()}
    return {"scene": kind, "width": width, "height": height, "vertices": int(len(g.vertices)),
            "triangles": int(len(g.triangles)), "closed": int(g.stats["closed_triangles"]), "frames": frames, "orbit_degrees": orbit_degrees, "ms": ms,
            "plan_seconds": plan_seconds, "counts": counts}


def measure_animation(kind: str, frames: int, orbit_degrees: float) -> dict:
    """``render_image(animation=True)`` at 480x320 against Workbench's animation render."""
    import tempfile

    import bpy

    from curved_reflections.blender import demo_scenes
    from curved_reflections.blender.gpu_init import ensure_gpu

    ensure_gpu()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = demo_scenes.build(kind, bpy.context.scene, 480, 320)
    camera = scene.camera
    base = np.array(camera.location)
    target = bpy.data.objects.new("orbit target", None)
    scene.collection.objects.link(target)
    track = camera.constraints.new('TRACK_TO')
    track.target = target
    target.location = (0.0, 0.0, float(base[2]) * 0.3)
    scene.frame_start, scene.frame_end = 1, frames
    for frame in range(1, frames + 1):
        angle = np.radians(orbit_degrees * (frame - 1))
        camera.location = (np.cos(angle) * base[0] - np.sin(angle) * base[1],
                           np.sin(angle) * base[0] + np.cos(angle) * base[1], base[2])
        camera.keyframe_insert("location", frame=frame)
    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        assert bpy.ops.curved_reflections.render_image(filepath=f"{folder}/ours_###", animation=True) == {'FINISHED'}
        ours = time.perf_counter() - start
        written = len(list(Path(folder).glob("ours_*.png")))
        scene.render.engine = 'BLENDER_WORKBENCH'
        scene.render.filepath = f"{folder}/workbench_"
        start = time.perf_counter()
        bpy.ops.render.render(animation=True)
        workbench = time.perf_counter() - start
    assert written == frames
    return {"scene": kind, "frames": frames, "ours": ours / frames, "workbench": workbench / frames}


def measure_morph_frames(width: int, height: int, target_vertices: int, frames: int, orbit_degrees: float) -> dict:
    """Per frame of an arc inside the grid: the viewport's draw and the morph pass against a plain draw."""
    import bpy
    import gpu
    from mathutils import Matrix

    from curved_reflections.engine import look_at_view
    from curved_reflections.engine.methods.morphing import morph_grid, morphing
    from curved_reflections.drawing.methods.morph_source import GPUFaceImages
    from curved_reflections.drawing.methods.polish_gpu import GPUImagePolish
    from curved_reflections.drawing.frame_pass import Frame
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer
    from curved_reflections.engine.frame_settings import FrameSettings
    from curved_reflections.drawing.methods.morph_pass import MorphPass
    from curved_reflections.blender.frame_pipeline import settings_of
    from curved_reflections.blender.render_inputs import reflector_properties, world_color

    scene, _, captured = bench_draw.built_scene("sbc_fig3", width, height)
    mirror = captured.reflectors[0]
    matrix = np.array(bpy.data.objects[mirror.name].matrix_world, dtype=np.float64)
    # As the scene loads its grid (morph_bake.load_grids): nodes projected and polished on the GPU.
    grid = morphing.grid_on_demand(morph_grid.reflector_in_frame(mirror, morph_grid.rigid_frame(matrix)),
                                   morph_grid.MorphSettings(), polish=scene.curved_reflections.morph_polish_nodes)
    grid.face_images, grid.image_polish = GPUFaceImages(), GPUImagePolish()
    meshes = bench_draw.scaled_meshes(captured.meshes, bench_draw.levels_for(captured, target_vertices))
    renderer = ReflectionRenderer(captured.reflectors, meshes, passes=[MorphPass.factory([(grid, matrix)])],
                                  settings=settings_of(scene, live=True),
                                  **reflector_properties(captured.reflectors, scene))
    blended = renderer.pass_named("morphing")
    g = renderer.geometry
    world = world_color(scene)
    centre = mirror.vertices.mean(axis=0)
    radius = float(np.max(np.linalg.norm(mirror.vertices - centre, axis=1)))
    eyes = [centre + radius * np.array([2.3 * np.cos(a), 2.3 * np.sin(a), 0.7])
            for a in np.radians(-100.0 + orbit_degrees * np.arange(frames))]
    views = [look_at_view(eye, centre, fov_y_deg=45.0, width=width, height=height) for eye in eyes]
    tetrahedra = [grid.check_view(view, matrix)[0] for view in views]
    plain = bench_draw.PlainDraw(g)
    translate = np.eye(4)
    translate[:3, 3] = g.shift

    def morph_pass(view):
        blended.blend(view)
        gpu.state.depth_test_set('LESS')
        gpu.state.depth_mask_set(True)
        view_projection = Matrix((np.asarray(view.projection_matrix) @ np.asarray(view.view_matrix)
                                  @ translate).tolist())
        renderer.meshes.draw(view_projection, targets,
                             blended.reflected_setup(Frame(view, targets, None, None, warm=True)), renderer._image,
                             blended.answers())
        gpu.state.depth_test_set('NONE')
        gpu.state.depth_mask_set(False)

    times = {"frame": [], "morph pass": [], "blend": [], "plain": []}
    offscreen = gpu.types.GPUOffScreen(width, height, format='RGBA16F')
    try:
        with offscreen.bind():
            framebuffer = gpu.state.active_framebuffer_get()
            targets = renderer.targets(width, height)
            start = time.perf_counter()
            for view in views:  # every node of the path projected once (shaders built, nodes on the GPU)
                renderer.draw(view, None, world, reflectors_only=True)
            node_seconds = time.perf_counter() - start
            for view in views:
                framebuffer.clear(color=(0.0, 0.0, 0.0, 1.0))
                bench_draw.scene_depth(framebuffer, plain, view)
                times["frame"].append(bench_draw.timed(lambda: renderer.draw(view, None, world, reflectors_only=True),
                                                       framebuffer))
                times["morph pass"].append(bench_draw.timed(lambda: morph_pass(view), framebuffer))
                times["blend"].append(bench_draw.timed(lambda: blended.blend(view), framebuffer))
                times["plain"].append(bench_draw.timed(lambda: plain.draw(view), framebuffer))
        drawn = np.isfinite(blended.read(0)[..., 0]).any(axis=0).sum()
    finally:
        offscreen.free()
    ms = {name: 1000.0 * statistics.median(values) for name, values in times.items()}
    return {"width": width, "height": height, "vertices": int(len(g.vertices)), "triangles": int(len(g.triangles)),
            "frames": frames, "entered": int(sum(a != b for a, b in zip(tetrahedra[1:], tetrahedra[:-1]))),
            "ms": ms, "nodes": blended.counts["node_projections"], "node_seconds": node_seconds,
            "node_mb": blended.nodes.nbytes / 2 ** 20, "answered": int(drawn),
            "polish_frames": blended.polish_frames}


MORPH_HEADING = "## Morphing mode on the GPU (blend every frame)"


def morph_report(r: dict, command: str) -> list:
    ms = r["ms"]
    return [
        MORPH_HEADING, "",
        f"Generated {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC by `{command}` on "
        f"{bench_draw._machine()}.", "",
        f"sbc_fig3, its meshes split to {r['vertices']:,} drawn vertices ({r['triangles']:,} triangles), "
        f"{r['width']}x{r['height']}, the eye moving along an arc inside the default 9x9x5 grid for "
        f"{r['frames']} frames, {r['entered']} of which enter a new tetrahedron (their nodes already on the "
        f"GPU, as the prefetch leaves them). The {r['nodes']} nodes of the path were projected once before "
        f"the clock ran ({r['node_seconds']:.1f} s with the node cameras' builds, {r['node_mb']:.0f} MB on "
        "the GPU). Milliseconds, medians over the frames; *frame* is what the viewport draws (pre-pass, "
        "blend, reflected meshes, composite), *morph pass* the blend and the reflected meshes alone, drawn as "
        "the live view draws them (vertices snapped to the scene's Accuracy, 1 px; the ball is convex, so the "
        "far sides of closed solids are culled; the nodes' images polished, *Polish Node Images*, and "
        + ("each frame's blend polished on the mirror, *Polish Every Frame*" if r["polish_frames"] else
           "the frames' blends not polished") + ", the defaults' choices):", "",
        "| frame ms | morph pass ms | of which blend ms | plain ms | pass / plain | blend / plain | "
        "frame / plain | vertices with an image |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|",
        f"| {ms['frame']:.1f} | {ms['morph pass']:.1f} | {ms['blend']:.1f} | {ms['plain']:.1f} | "
        f"**{ms['morph pass'] / ms['plain']:.2f}x** | {ms['blend'] / ms['plain']:.2f}x | "
        f"{ms['frame'] / ms['plain']:.2f}x | {r['answered']:,} |", ""]


def replace_section(text: str, heading: str, section: list) -> str:
    """``text`` with the section under ``heading`` (up to the next ``## `` heading)
    replaced by ``section``, or appended."""
    before, found, after = text.partition(heading)
    rest = after[after.find("\n## "):] if found and "\n## " in after else ""
    return before.rstrip() + "\n\n" + "\n".join(section).rstrip() + "\n" + rest


ITERATIVE_HEADING = "## Iterative mode (GPU search every frame)"


def iterative_report(rows: list, animations: list) -> list:
    lines = [
        ITERATIVE_HEADING,
        "",
        "The view orbits every frame; milliseconds, medians over the frames. *Frame*: what the viewport "
        "draws (pre-pass, search from the last frame's answers, reflected meshes, composite). *Iterative "
        "pass*: the search and the reflected meshes alone; *every triangle*: the same pass without culling "
        "the far sides of closed solids (*closed*: their triangles; culled only in convex mirrors), on the "
        "same frames. *Plain*: the same meshes drawn once with one colour and the depth test (bench_draw), "
        "as Blender draws them (no culling). The plan (star-shaped check and cube maps) is made once per "
        "reflector geometry, not per frame.",
        "",
        "| scene | size | drawn vertices | triangles | closed | frame ms | iterative pass ms | of which search ms | "
        "every triangle ms | plain ms | pass / plain | every triangle / plain | search / plain | frame / plain | "
        "unanswered vertices | plan s |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        ms = r["ms"]
        unanswered = sum(c["unanswered"] for c in r["counts"].values())
        lines.append(f"| {r['scene']} | {r['width']}x{r['height']} | {r['vertices']:,} | {r['triangles']:,} | "
                     f"{r['closed']:,} | {ms['frame']:.1f} | {ms['iterative pass']:.1f} | {ms['search']:.1f} | "
                     f"{ms['every triangle']:.1f} | {ms['plain']:.1f} | **{ms['iterative pass'] / ms['plain']:.2f}x** | "
                     f"{ms['every triangle'] / ms['plain']:.2f}x | {ms['search'] / ms['plain']:.2f}x | "
                     f"{ms['frame'] / ms['plain']:.2f}x | {unanswered:,} | {r['plan_seconds']:.2f} |")
    lines += ["", "`render_image(animation=True)`, 480x320, camera orbiting every frame, against Workbench's "
              "`bpy.ops.render.render(animation=True)` on the same scene (seconds per frame, both writing PNGs):",
              "", "| scene | frames | ours s/frame | Workbench s/frame | ratio |", "|---|---:|---:|---:|---:|"]
    for a in animations:
        lines.append(f"| {a['scene']} | {a['frames']} | {a['ours']:.3f} | {a['workbench']:.3f} | "
                     f"**{a['ours'] / a['workbench']:.2f}x** |")
    return lines + [""]


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="markdown file to write")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--steps", type=int, default=6, help="views per arc (0.4 degree apart)")
    parser.add_argument("--jumps", type=int, default=3, help="arcs, 35 degrees apart")
    parser.add_argument("--vertices", type=int, default=100_000, help="drawn vertices of the Iterative rows")
    parser.add_argument("--frames", type=int, default=24, help="frames of the Iterative rows and the animation")
    parser.add_argument("--orbit-degrees", type=float, default=2.0, help="view turn per frame (Iterative rows)")
    parser.add_argument("--iterative-only", action="store_true", help="only the Iterative rows and the animation")
    parser.add_argument("--morph-only", action="store_true", help="only the Morphing rows on the GPU")
    parser.add_argument("--shapes-only", action="store_true",
                        help="only the rows of mirrors that are not star-shaped (view_change_shapes.py)")
    parser.add_argument("--quick", action="store_true", help="small: 160x120, 2 arcs of 3 views")
    args = parser.parse_args(argv)
    if args.quick:
        args.width, args.height, args.steps, args.jumps = 160, 120, 3, 2
        args.vertices, args.frames = 5_000, 4
    return args


def _shapes(args, command: str) -> list:
    """The section of the mirrors that are not star-shaped (``view_change_shapes.py``)."""
    return view_change_shapes.shapes_report(
        [view_change_shapes.measure_shape(kind, args.width, args.height, args.steps, args.orbit_degrees)
         for kind in view_change_shapes.SHAPES], command)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = parse_args(argv)
    bench_sbc.import_package()
    command = bench_draw.command_line("bench_view_change.py", argv)
    previous = args.out.read_text(encoding="utf-8") if args.out.exists() else "# Cost of a view change\n"
    if args.shapes_only:
        return bench_draw.write_report(args.out, replace_section(previous, view_change_shapes.SHAPES_HEADING,
                                                                 _shapes(args, command)))
    if not args.iterative_only:
        morph = morph_report(measure_morph_frames(args.width, args.height, args.vertices, args.frames,
                                                  args.orbit_degrees), command)
    if args.morph_only:
        return bench_draw.write_report(args.out, replace_section(previous, MORPH_HEADING, morph))
    rows = [measure_iterative(kind, args.width, args.height, args.vertices, args.frames, args.orbit_degrees)
            for kind in ITERATIVE_SCENES]
    animations = [measure_animation(kind, args.frames, args.orbit_degrees) for kind in ITERATIVE_SCENES]
    if args.iterative_only:
        # The Iterative section of the report in ``--out`` is replaced, the rest kept.
        generated = f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M}"
        text = replace_section(previous, ITERATIVE_HEADING, [
            ITERATIVE_HEADING, "", f"Generated {generated} UTC by `{command}` on {bench_draw._machine()}.", ""]
            + iterative_report(rows, animations)[1:])
    else:
        result = measure(args.width, args.height, args.steps, args.jumps)
        text = (report(result, command, bench_draw._machine()) + "\n" + "\n".join(morph) + "\n"
                + "\n".join(iterative_report(rows, animations)) + "\n" + "\n".join(_shapes(args, command)))
    return bench_draw.write_report(args.out, text)



if __name__ == "__main__":
    sys.exit(main())
