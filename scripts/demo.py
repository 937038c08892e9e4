# SPDX-License-Identifier: GPL-3.0-or-later
"""Build the demo scenes, render them with every renderer, and measure their reflections.

    .venv/bin/python scripts/demo.py --out out/demo [--width 320 --height 240]
        [--scenes sbc_fig3 teapot two_spheres vase] [--renderers cycles eevee_raytrace ...]
        [--max-order 2] [--trace-edges]

For each scene this saves DIR/<scene>.blend (set up for the Cycles reference), renders
the reflector mask, Cycles (the reference) and each other renderer, and compares labels
(which object each pixel shows, ``tools/metrics.py``) against Cycles on all reflector
pixels and on the near-contact region. It writes the images, one side-by-side PNG per
scene and DIR/results.md, and prints the table.

A renderer is one :class:`Renderer` entry in :func:`renderers`: a name and a function
``(scene, reflectors, png_path) -> RenderResult``. Ours, ``curved_reflections``
(:func:`render_ours`), is one such entry.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
SCENE_NAMES = ("sbc_fig3", "teapot", "two_spheres", "vase", "bumpy_ball")
REFERENCE = "cycles"
OURS = "curved_reflections"
#: Our renderer also with every reflector in one mode (the plain entry is the default, Auto).
OUR_MODES = ("RUNTIME", "ITERATIVE")


def import_package():
    """The repository as ``curved_reflections`` (isolated Blender user folder), registered."""
    spec = importlib.util.spec_from_file_location("_package_link", REPO_ROOT / "scripts" / "package_link.py")
    link = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(link)
    return link.import_registered(REPO_ROOT, prefix="curved_reflections_demo_")


@dataclass(frozen=True)
class Renderer:
    """A named way to render a scene's camera view to a PNG, timed."""

    name: str
    render: Callable  # (scene, reflectors, png_path) -> reference_render.RenderResult


def renderers(args) -> list[Renderer]:
    """The reference (Cycles) first, then every renderer compared with it."""
    from curved_reflections.tools import reference_render as rr

    def eevee(variant):
        return lambda scene, reflectors, path: rr.render_eevee(
            scene, variant, path, reflectors, args.eevee_samples, args.frames)

    entries = [Renderer(REFERENCE, lambda scene, reflectors, path: rr.render_cycles(
        scene, path, args.cycles_samples, args.bounces, args.frames))]
    entries += [Renderer(variant, eevee(variant)) for variant in rr.EEVEE_VARIANTS]
    entries.append(Renderer(OURS, lambda scene, reflectors, path: render_ours(scene, path, args)))
    entries += [Renderer(f"{OURS}_{mode.lower()}", lambda scene, reflectors, path, mode=mode: render_ours(
        scene, path, args, mode)) for mode in OUR_MODES]
    wanted = set(args.renderers or [e.name for e in entries]) | {REFERENCE}
    return [e for e in entries if e.name in wanted]


def render_ours(scene, path, args, mode: str | None = None):
    """Our reflections (``blender/render_image.py``): capture, the method of each
    reflector (``mode`` for all of them if given, else their own: Auto) and GPU drawing,
    timed together per frame with the PNG writing, as the other renderers.

    A warm-up frame first (shader compilation, the star-shaped check and cube maps of
    the iterative search), timed separately as the first frame. Settings are the
    scene's (``scene.curved_reflections``) except the highest order, ``--max-order``.
    The notes split the last frame's time into its stages.
    """
    import bpy
    import numpy as np
    from curved_reflections.blender import render_image
    from curved_reflections.blender.png import write_png
    from curved_reflections.tools import reference_render as rr

    depsgraph = bpy.context.evaluated_depsgraph_get()  # run_scene builds into the context's scene
    mirrors = [o for o in scene.objects if o.curved_reflections.is_reflector]
    saved = [o.curved_reflections.mode for o in mirrors]

    def frame():
        start = time.perf_counter()
        result = render_image.render_scene(scene, depsgraph, max_order=args.max_order,
                                           trace_edges=args.trace_edges)
        write_png(path, result.display)
        return time.perf_counter() - start, result

    try:
        for mirror in mirrors:
            mirror.curved_reflections.mode = mode or mirror.curved_reflections.mode
        first, _ = frame()
        frames = [frame() for _ in range(max(1, args.frames))]
    finally:
        for mirror, original in zip(mirrors, saved):
            mirror.curved_reflections.mode = original
    seconds = float(np.median([f[0] for f in frames]))
    result = frames[-1][1]
    settings = scene.curved_reflections
    s, stats = result.seconds, result.stats
    methods = ", ".join(f"{name} {method.lower()}" for name, method in stats["methods"].items())
    notes = (f"{methods}; d = {settings.downsample}, accuracy {settings.accuracy_px:g} px, max order "
             f"{args.max_order}, {stats['traced_pixels']} px traced{' (edges too)' if args.trace_edges else ''}; "
             f"last frame: capture {s['capture']:.2f} s, sample-based camera {s['sbc']:.2f} s "
             f"(ray map {s['trace']:.2f} s), drawing {s['draw']:.2f} s; {stats.get('n_sheets', 0)} sheet(s), "
             f"{stats['reflected_triangles']} reflected triangles, {stats.get('mixed_triangles', 0)} mixed "
             f"(subdivided, SBC V-B)")
    name = OURS if mode is None else f"{OURS}_{mode.lower()}"
    return rr.RenderResult(name, rr.read_png(path), seconds, path, first, notes)


@dataclass
class Row:
    scene: str
    renderer: str
    seconds: float
    first_seconds: float | None
    all_reflector: float
    near_contact: float
    notes: str


def measure(kind: str, results, mask, palette) -> tuple[list[Row], dict]:
    """Label disagreement of every result with the reference, on the mask and near contact."""
    from curved_reflections.tools import metrics
    from curved_reflections.blender.demo_scenes import WORLD_KEY

    names = metrics.palette_names(palette)
    reference = metrics.label_image(results[0].image, palette)
    contact = metrics.contact_region(mask, reference, [names.index(WORLD_KEY)])
    rows, differences = [], {}
    for result in results:
        labels = metrics.label_image(result.image, palette)
        differences[result.name] = (labels != reference) & mask
        rows.append(Row(kind, result.name, result.seconds, result.first_seconds,
                        metrics.share_differing(labels, reference, mask),
                        metrics.share_differing(labels, reference, contact), result.notes))
    return rows, {"contact": contact, "differences": differences}


def side_by_side(results, mask, contact, differences):
    """Top row: the renders; bottom row: mask and near-contact region, then each difference map.

    Difference maps show the reference dimmed, reflector pixels light grey, and in red the
    reflector pixels whose label differs from the reference.
    """
    import numpy as np

    reference = results[0].image[..., :3]
    top = [r.image[..., :3] for r in results]
    region = np.zeros_like(reference)
    region[mask] = 0.6
    region[contact] = (1.0, 0.8, 0.0)
    bottom = [region]
    for result in results[1:]:
        panel = 0.35 * reference
        panel[mask] = 0.85
        panel[differences[result.name]] = (1.0, 0.0, 0.0)
        bottom.append(panel)
    bottom += [np.zeros_like(reference)] * (len(top) - len(bottom))
    # Rows are stored bottom to top: the first block in the array is the bottom row.
    return np.concatenate([np.concatenate(bottom, axis=1), np.concatenate(top, axis=1)], axis=0)


#: Causes of a disagreeing reflector pixel (:func:`causes`), in the order they are tested,
#: with the colour each gets in ``<scene>_causes.png``.
CAUSES = {
    "silhouette band": (1.0, 0.85, 0.0),  # within d px of the mirror's footprint edge
    "reflection missing": (1.0, 0.0, 0.0),  # ours shows the world, the reference an object
    "reflection where the reference shows world": (0.0, 0.4, 1.0),
    "wrong object, at an edge": (1.0, 0.0, 1.0),  # within 1 px of a label edge of the reference
    "wrong object, inside": (0.0, 0.8, 0.0),
}


def causes(ours, reference, mask, world: int, band_px: int):
    """Why each reflector pixel of ``ours`` (labels) disagrees with ``reference``: (H, W)
    int, -1 where they agree, else the index into :data:`CAUSES` of the first that applies.

    The silhouette band is the reflector pixels within ``band_px`` (Chebyshev) of a
    non-reflector pixel; "at an edge" means within 1 px of a change of reference label.
    """
    import numpy as np

    def near(binary, radius):
        padded = np.pad(binary, radius, constant_values=False)
        out = np.zeros_like(binary)
        h, w = binary.shape
        for dy in range(-radius, radius + 1):
            for dx in range(-radius, radius + 1):
                out |= padded[radius + dy:radius + dy + h, radius + dx:radius + dx + w]
        return out

    differ = (ours != reference) & mask
    band = near(~mask, max(1, band_px)) & mask
    edge = np.zeros_like(mask)
    edge[:, 1:] |= reference[:, 1:] != reference[:, :-1]
    edge[:, :-1] |= reference[:, 1:] != reference[:, :-1]
    edge[1:] |= reference[1:] != reference[:-1]
    edge[:-1] |= reference[1:] != reference[:-1]
    tests = [band, (ours == world) & (reference != world), (ours != world) & (reference == world), edge,
             np.ones_like(mask)]
    out = np.full(mask.shape, -1, dtype=np.int64)
    for index, test in reversed(list(enumerate(tests))):
        out[differ & test] = index
    return out


def causes_image(reference_image, cause):
    """The reference dimmed, each disagreeing pixel in its cause's colour (:data:`CAUSES`)."""
    panel = 0.35 * reference_image[..., :3].copy()
    for index, colour in enumerate(CAUSES.values()):
        panel[cause == index] = colour
    return panel


def run_scene(kind: str, args, out: Path) -> list[Row]:
    """Build, save, render and measure one demo scene."""
    import bpy
    from curved_reflections.blender import demo_scenes
    from curved_reflections.blender.png import write_png
    from curved_reflections.tools import reference_render as rr

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.scene.name = kind  # before building: camera and world are named after it
    scene = demo_scenes.build(kind, bpy.context.scene, args.width, args.height)
    rr.configure_cycles(scene, args.cycles_samples, args.bounces)
    bpy.ops.wm.save_as_mainfile(filepath=str((out / f"{kind}.blend").resolve()), copy=True)
    reflectors = demo_scenes.reflectors(scene)
    palette = demo_scenes.palette(scene)
    mask, _ = rr.render_mask(scene, out / f"{kind}_mask.png", reflectors)
    results = []
    for entry in renderers(args):
        print(f"[demo] {kind}: {entry.name} ...", flush=True)
        results.append(entry.render(scene, reflectors, out / f"{kind}_{entry.name}.png"))
    rows, maps = measure(kind, results, mask, palette)
    write_png(out / f"{kind}_side_by_side.png",
              side_by_side(results, mask, maps["contact"], maps["differences"]))
    for row in rows:
        row.notes += f"; {int(mask.sum())} reflector px, {int(maps['contact'].sum())} near contact"
    ours = next((r for r in results if r.name == OURS), None)
    if ours is not None:
        from curved_reflections.tools import metrics
        from curved_reflections.blender.demo_scenes import WORLD_KEY

        cause = causes(metrics.label_image(ours.image, palette), metrics.label_image(results[0].image, palette),
                       mask, metrics.palette_names(palette).index(WORLD_KEY), scene.curved_reflections.downsample)
        write_png(out / f"{kind}_causes.png", causes_image(results[0].image, cause))
        counts = ", ".join(f"{name} {100.0 * (cause == k).sum() / max(1, mask.sum()):.2f} %"
                           for k, name in enumerate(CAUSES))
        next(r for r in rows if r.renderer == OURS).notes += f"; disagreement by cause: {counts}"
        print(f"[demo] {kind}: {counts}", flush=True)
    return rows


def _percent(value: float) -> str:
    return "n/a" if value != value else f"{100.0 * value:.1f}"


def table(rows: list[Row]) -> str:
    """The results as a markdown table (disagreement in % of pixels)."""
    lines = ["| scene | renderer | time per frame (s) | label disagreement, all reflector px (%) "
             "| near contact (%) |", "|---|---|---:|---:|---:|"]
    for row in rows:
        lines.append(f"| {row.scene} | {row.renderer} | {row.seconds:.2f} | "
                     f"{_percent(row.all_reflector)} | {_percent(row.near_contact)} |")
    return "\n".join(lines)


def details(rows: list[Row]) -> str:
    lines = ["| scene | renderer | first frame (s) | settings |", "|---|---|---:|---|"]
    for row in rows:
        first = "" if row.first_seconds is None else f"{row.first_seconds:.2f}"
        lines.append(f"| {row.scene} | {row.renderer} | {first} | {row.notes} |")
    return "\n".join(lines)


def report(rows: list[Row], args) -> str:
    from curved_reflections.tools.metrics import CONTACT_RADIUS_FRACTION

    radius = CONTACT_RADIUS_FRACTION * args.width
    return "\n\n".join([
        "# Curved Reflections demo: our reflections and the reference renderers",
        "Produced by `make demo`, i.e. `.venv/bin/python scripts/demo.py " + " ".join(sys.argv[1:]) + "`.",
        f"Resolution {args.width}x{args.height}, {os.cpu_count()} CPU cores. Label disagreement: "
        "share of reflector pixels (Workbench mask) that show another object than Cycles "
        "shows there (every object and the world have a distinct flat emission colour). "
        f"Near contact: reflector pixels within {radius:.1f} px ({CONTACT_RADIUS_FRACTION:.4f} of "
        "the width) of a non-reflector pixel showing a diffuse object. Cycles is the "
        "reference, so its own row is 0 by definition.",
        table(rows),
        f"Time per frame is the wall time of one `render.render` call, PNG writing included "
        f"(median of {args.frames} frame(s)); EEVEE renders a warm-up frame first (shader "
        "compilation, faster when Mesa's shader cache is warm), shown below as the first frame. "
        "EEVEE's probe variants capture their sphere probes in every frame. Ours "
        f"(`{OURS}`, `blender/render_image.py`) is timed from capture to PNG: the scene "
        "capture, each reflector's method (the iterative search on the GPU, or the "
        "sample-based camera's ray map and trees) and the GPU drawing, on Mesa llvmpipe (CPU) "
        "here; a warm-up frame first (shader compilation, star-shaped checks and cube maps). "
        f"`{OURS}` draws each reflector in its default mode, Auto (Iterative where it is "
        f"star-shaped, Runtime otherwise; second-order reflections by the sample-based camera); "
        + ", ".join(f"`{OURS}_{m.lower()}`" for m in OUR_MODES) + " draw every reflector in that mode "
        "(Iterative falls back to Runtime where a reflector is not star-shaped).",
        details(rows),
        "Images: `<scene>_side_by_side.png`, top row the renders in table order, bottom row "
        "the mask (grey) with the near-contact region (yellow), then per renderer its "
        "disagreeing reflector pixels in red.",
    ]) + "\n"


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "out" / "demo")
    parser.add_argument("--width", type=int, default=320)
    parser.add_argument("--height", type=int, default=240)
    parser.add_argument("--scenes", nargs="+", choices=SCENE_NAMES, default=list(SCENE_NAMES))
    parser.add_argument("--renderers", nargs="+", default=None,
                        help="renderers to run besides the Cycles reference (default: all)")
    parser.add_argument("--cycles-samples", type=int, default=16)
    parser.add_argument("--eevee-samples", type=int, default=16)
    parser.add_argument("--bounces", type=int, default=8, help="Cycles glossy bounces")
    parser.add_argument("--max-order", type=int, default=2,
                        help="highest reflection order drawn by our renderer (curved_reflections)")
    parser.add_argument("--trace-edges", action="store_true",
                        help="our renderer also ray traces mirror pixels next to a drawn reflection that got none")
    parser.add_argument("--frames", type=int, default=1,
                        help="timed frames per renderer; the time is their median")
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    import_package()
    rows = []
    for kind in args.scenes:
        rows += run_scene(kind, args, args.out)
    text = report(rows, args)
    (args.out / "results.md").write_text(text)
    print(table(rows))
    print(f"[demo] wrote {args.out / 'results.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
