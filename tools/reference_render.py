# SPDX-License-Identifier: GPL-3.0-or-later
"""Reference renders of a scene's camera view: Cycles, EEVEE, and the reflector footprint.

These are what our viewport reflections are measured against (``scripts/demo.py``, the
tests and the benchmarks; the extension itself never renders them, so this is not shipped):
- Cycles (CPU) is ground truth: it path-traces the mirrors exactly, with enough glossy
  bounces for second-order reflections. With a tiny pixel filter, and only mirrors and
  emitters in the scene, every sample of a pixel follows the same path, so a few
  samples give the exact point-sampled image.
- EEVEE is what Blender offers interactively: screen-space ray tracing (misses what is
  off screen or hidden), and sphere light probes (environment mapping from one centre,
  wrong for nearby objects; SBC paper, Fig. 3 left).
- The mask is the reflectors' footprint: a flat Workbench render, reflectors white and
  everything else black, no anti-aliasing.

Images come back as float32 numpy arrays (H, W, 4) of *display* sRGB in [0, 1] (the
"Standard" view transform), rows bottom to top as Blender stores pixels (y up, as
the pixel convention of docs/overview.md). Every render is also written as a PNG.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np

#: EEVEE settings compared in the demo: name -> (screen-space ray tracing, sphere probes).
EEVEE_VARIANTS = {
    "eevee_raytrace": (True, False),
    "eevee_raytrace_probe": (True, True),
    "eevee_probe": (False, True),
}
#: Pixel filter width used everywhere: point sampling at the pixel centre, as a rasteriser.
FILTER_WIDTH_PX = 0.01
PROBE_NAME_PREFIX = "CR Probe "


@dataclass
class RenderResult:
    """One rendered frame: the image, its PNG, and the wall time per frame in seconds.

    ``first_seconds`` is the time of the first frame when a warm-up frame was rendered
    (EEVEE compiles its shaders then); ``seconds`` is the steady time per frame.
    """

    name: str
    image: np.ndarray
    seconds: float
    path: Path
    first_seconds: float | None = None
    notes: str = ""


# --- PNG read-back ------------------------------------------------------------------


def read_png(path) -> np.ndarray:
    """(H, W, 4) float32 of a PNG's stored values / 255, rows bottom to top."""
    image = bpy.data.images.load(str(path), check_existing=False)
    try:
        width, height = image.size
        pixels = np.empty(width * height * 4, dtype=np.float32)
        image.pixels.foreach_get(pixels)
        return pixels.reshape(height, width, 4)
    finally:
        bpy.data.images.remove(image)


# --- rendering ----------------------------------------------------------------------


def _set_png_output(scene, path):
    scene.render.filepath = str(path)
    settings = scene.render.image_settings
    settings.file_format = "PNG"
    settings.color_mode = "RGBA"
    settings.color_depth = "8"
    scene.render.dither_intensity = 0.0
    scene.render.use_compositing = False
    scene.render.use_sequencer = False


def _timed_render(scene, path) -> float:
    _set_png_output(scene, path)
    start = time.perf_counter()
    bpy.ops.render.render(write_still=True, scene=scene.name)
    return time.perf_counter() - start


def render(scene, name: str, path, warm_up: bool = False, frames: int = 1) -> RenderResult:
    """Render the scene camera with the engine as set, to ``path``; time it.

    With ``warm_up`` a first frame is rendered and timed separately, so that ``seconds``
    is the steady per-frame time (EEVEE compiles shaders on its first frame). With
    ``frames`` > 1, ``seconds`` is the median over that many frames (timings on a busy
    CPU vary from frame to frame).
    """
    path = Path(path)
    first = _timed_render(scene, path) if warm_up else None
    seconds = float(np.median([_timed_render(scene, path) for _ in range(max(1, frames))]))
    return RenderResult(name, read_png(path), seconds, path, first)


def configure_cycles(scene, samples: int = 16, bounces: int = 8, transmission_bounces: int = 0):
    """Cycles on the CPU: exact mirrors, point-sampled pixels, no denoising;
    ``transmission_bounces`` for glass (none by default: scenes of mirrors)."""
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = samples
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    cycles.filter_width = FILTER_WIDTH_PX
    cycles.max_bounces = bounces
    cycles.glossy_bounces = bounces
    cycles.transparent_max_bounces = bounces
    cycles.diffuse_bounces = 0
    cycles.transmission_bounces = transmission_bounces
    cycles.volume_bounces = 0
    cycles.sample_clamp_direct = cycles.sample_clamp_indirect = 0.0


def render_cycles(scene, path, samples: int = 16, bounces: int = 8, frames: int = 1,
                  transmission_bounces: int = 0) -> RenderResult:
    """Ground truth: Cycles CPU with ``bounces`` glossy bounces (>= 2 for two mirrors)
    and ``transmission_bounces`` (glass)."""
    configure_cycles(scene, samples, bounces, transmission_bounces)
    result = render(scene, "cycles", path, frames=frames)
    result.notes = (f"{samples} samples, {bounces} glossy and {transmission_bounces} transmission bounces, "
                    f"filter {FILTER_WIDTH_PX} px")
    return result


def configure_eevee(scene, raytrace: bool, samples: int = 16, probe_resolution: str = "1024"):
    """EEVEE at its best for mirrors: full-resolution screen tracing, finest trace, no fast GI."""
    scene.render.engine = "BLENDER_EEVEE"
    scene.render.filter_size = FILTER_WIDTH_PX
    eevee = scene.eevee
    eevee.taa_render_samples = samples
    eevee.use_raytracing = raytrace
    eevee.ray_tracing_method = "SCREEN"
    options = eevee.ray_tracing_options
    options.resolution_scale = "1"
    options.screen_trace_quality = 1.0
    options.screen_trace_thickness = 0.2
    options.trace_max_roughness = 0.5
    options.use_denoise = True
    eevee.use_fast_gi = False
    eevee.gi_cubemap_resolution = probe_resolution


def reflector_bounds(obj) -> tuple[np.ndarray, float]:
    """World centre of the object's bounding box and the largest vertex distance from it."""
    matrix = np.array(obj.matrix_world)
    count = len(obj.data.vertices)
    local = np.empty(count * 3)
    obj.data.vertices.foreach_get("co", local)
    world = local.reshape(-1, 3) @ matrix[:3, :3].T + matrix[:3, 3]
    centre = 0.5 * (world.min(axis=0) + world.max(axis=0))
    return centre, float(np.linalg.norm(world - centre, axis=1).max())


def add_sphere_probes(scene, reflectors) -> list:
    """One sphere light probe per reflector, at its centre, seeing past the reflector.

    ``clip_start`` is the reflector's bounding radius about the probe, so the mirror never
    hides its own surroundings from its probe (every point of it lies nearer than the
    clip planes); the influence radius is 5 % larger, just enough to cover the mirror, with
    no falloff, so the probe alone (not a blend with the world probe) lights the whole
    mirror. EEVEE captures sphere probes by itself when it renders a frame: no bake step.
    """
    for view_layer in scene.view_layers:
        view_layer.update()  # reflector_bounds reads world matrices
    probes = []
    for reflector in reflectors:
        centre, radius = reflector_bounds(reflector)
        data = bpy.data.lightprobes.new(f"{PROBE_NAME_PREFIX}{reflector.name}", "SPHERE")
        data.clip_start = radius
        data.clip_end = 100.0
        data.influence_type = "ELIPSOID"
        data.influence_distance = 1.05 * radius
        data.falloff = 0.0
        obj = bpy.data.objects.new(data.name, data)
        obj.location = centre
        scene.collection.objects.link(obj)
        probes.append(obj)
    return probes


def remove_probes(probes):
    for obj in probes:
        data = obj.data
        bpy.data.objects.remove(obj)
        bpy.data.lightprobes.remove(data)


def render_eevee(scene, name: str, path, reflectors, samples: int = 16, frames: int = 1) -> RenderResult:
    """EEVEE with one of :data:`EEVEE_VARIANTS`; probes are added for the frame, then removed."""
    raytrace, use_probes = EEVEE_VARIANTS[name]
    configure_eevee(scene, raytrace, samples)
    probes = add_sphere_probes(scene, reflectors) if use_probes else []
    try:
        result = render(scene, name, path, warm_up=True, frames=frames)
    finally:
        remove_probes(probes)
    parts = ["screen-space ray tracing" if raytrace else "no ray tracing",
             f"{len(probes)} sphere probe(s)" if probes else "world probe only", f"{samples} samples"]
    result.notes = ", ".join(parts)
    return result


@contextlib.contextmanager
def _mask_colours(scene, reflectors):
    """Temporarily paint reflectors white and everything else (world included) black."""
    white = {obj.name for obj in reflectors}
    saved = {obj.name: tuple(obj.color) for obj in scene.objects}
    saved_world = tuple(scene.world.color) if scene.world else None
    try:
        for obj in scene.objects:
            obj.color = (1.0, 1.0, 1.0, 1.0) if obj.name in white else (0.0, 0.0, 0.0, 1.0)
        if scene.world:
            scene.world.color = (0.0, 0.0, 0.0)
        yield
    finally:
        for obj in scene.objects:
            if obj.name in saved:
                obj.color = saved[obj.name]
        if scene.world and saved_world is not None:
            scene.world.color = saved_world


def configure_mask(scene):
    """Workbench: flat object colours, no anti-aliasing, outline, cavity or shadows."""
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.render_aa = "OFF"
    shading = scene.display.shading
    shading.light = "FLAT"
    shading.color_type = "OBJECT"
    shading.show_object_outline = False
    shading.show_cavity = False
    shading.show_shadows = False
    shading.show_specular_highlight = False
    shading.show_xray = False
    shading.show_backface_culling = False
    shading.use_dof = False


def render_mask(scene, path, reflectors) -> tuple[np.ndarray, RenderResult]:
    """(H, W) bool footprint of ``reflectors`` in the camera view, rows bottom to top."""
    configure_mask(scene)
    with _mask_colours(scene, reflectors):
        result = render(scene, "mask", path)
    return result.image[..., :3].mean(axis=2) > 0.5, result
