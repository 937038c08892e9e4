# SPDX-License-Identifier: GPL-3.0-or-later
"""Draw a picture of the Reflections tab for the user guide.

    .venv/bin/python scripts/panel_picture.py --out docs/images/panel.png

Background mode draws no UI, so the panel's own ``draw`` (``operators/panel.py``) runs
with a layout that records what it shows (labels, properties with their current values,
operator buttons, boxes, greyed rows), and the record is drawn with Blender's font
module (``blf``) into an offscreen image. The picture shows the panel's real content
and order on the mirror-ball demo scene with a torus mirror added, baked, both in the
default Auto mode: the ball is star-shaped and searched on the GPU (Iterative), the
torus is not and is drawn in Runtime mode, each line saying why, and the morphing box
offers to bake a grid for the torus; the scene camera's view is drawn and checked, so each
mirror's line also shows its accuracy measured in that view. The widgets' look is a
sketch, not Blender's theme.
With ``--perturbation`` the ball is in Perturbation mode on its declared exact sphere:

    .venv/bin/python scripts/panel_picture.py --perturbation --out docs/images/panel_perturbation.png
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]
WIDTH, LINE, INDENT, MARGIN = 540, 22, 14, 10


class Recorder:
    """A UILayout stand-in: every call becomes a row (depth, items, greyed, boxed)."""

    def __init__(self, rows: list, depth: int = 0, active: bool = True, entry: dict | None = None, boxed=False):
        self.rows, self.depth, self.active, self.entry, self.boxed = rows, depth, active, entry, boxed
        self.use_property_split = self.use_property_decorate = False

    def __setattr__(self, name, value):
        if name == "active" and "active" in self.__dict__:
            value = value and self.__dict__["active"]
        object.__setattr__(self, name, value)

    def _emit(self, kind: str, text: str) -> None:
        item = (kind, text, self.active)
        if self.entry is not None:
            self.entry["items"].append(item)
        else:
            self.rows.append({"depth": self.depth, "items": [item], "boxed": self.boxed})

    def column(self, heading="", **_kwargs):
        child = Recorder(self.rows, self.depth, self.active, None, self.boxed)
        if heading:
            child._emit("heading", heading)
        return child

    def row(self, **_kwargs):
        entry = {"depth": self.depth, "items": [], "boxed": self.boxed}
        self.rows.append(entry)
        return Recorder(self.rows, self.depth, self.active, entry, self.boxed)

    def grid_flow(self, columns=2, **_kwargs):
        return _Grid(self, columns)

    def box(self):
        self.rows.append({"depth": self.depth, "items": [("gap", "", True)], "boxed": False})
        return Recorder(self.rows, self.depth + 1, self.active, None, True)

    def label(self, text="", icon='NONE'):
        self._emit("label", text)

    def prop(self, data, name, text=None, **_kwargs):
        rna = data.bl_rna.properties[name]
        value = getattr(data, name)
        if rna.type == 'BOOLEAN':
            shown = "[x]" if value else "[ ]"
        elif rna.type == 'ENUM':
            shown = rna.enum_items[value].name
        elif hasattr(value, "__len__") and not isinstance(value, str):
            shown = " x ".join(f"{v:.3g}" if isinstance(v, float) else str(v) for v in value)
        elif rna.type == 'FLOAT':
            shown = f"{value:.3g}"
        else:
            shown = str(value)
        self._emit("prop", f"{text or rna.name}:  {shown}")

    def operator(self, idname, text=None, **_kwargs):
        import bpy

        group, name = idname.split(".")
        self._emit("button", text or getattr(getattr(bpy.ops, group), name).get_rna_type().name)

    def operator_menu_enum(self, idname, _property, text=None, **kwargs):
        self.operator(idname, text=text, **kwargs)


class _Grid:
    """``grid_flow``: items fill rows of ``columns``."""

    def __init__(self, parent: Recorder, columns: int):
        self.parent, self.columns, self.current = parent, columns, None

    def label(self, text="", icon='NONE'):
        if self.current is None or len(self.current.entry["items"]) >= self.columns:
            self.current = self.parent.row()
        self.current.label(text=text)


def record_panel(scene, obj) -> list:
    from curved_reflections.operators.panel import VIEW3D_PT_curved_reflections

    rows: list = []
    layout = Recorder(rows)
    VIEW3D_PT_curved_reflections.draw(SimpleNamespace(layout=layout), SimpleNamespace(scene=scene, active_object=obj))
    return [r for r in rows if r["items"]]


def draw_rows(rows: list) -> np.ndarray:
    """(H, W, 4) uint8 RGBA, rows bottom to top: a dark panel, boxes lighter, buttons framed."""
    import blf
    import gpu
    from gpu_extras.batch import batch_for_shader
    from mathutils import Matrix

    height = 2 * MARGIN + LINE * len(rows)
    offscreen = gpu.types.GPUOffScreen(WIDTH, height, format='RGBA8')
    shader = gpu.shader.from_builtin('UNIFORM_COLOR')

    def rect(x0, y0, x1, y1, color):
        batch = batch_for_shader(shader, 'TRIS', {"pos": [(x0, y0), (x1, y0), (x1, y1), (x0, y0), (x1, y1), (x0, y1)]})
        shader.uniform_float("color", color)
        batch.draw(shader)

    with offscreen.bind():
        gpu.state.active_framebuffer_get().clear(color=(0.16, 0.16, 0.16, 1.0))
        with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
            gpu.matrix.load_matrix(Matrix.Identity(4))
            gpu.matrix.load_projection_matrix(Matrix(((2 / WIDTH, 0, 0, -1), (0, 2 / height, 0, -1), (0, 0, 1, 0),
                                                      (0, 0, 0, 1))))
            shader.bind()
            blf.size(0, 13)
            for k, row in enumerate(rows):
                top = height - MARGIN - k * LINE
                left = MARGIN + INDENT * row["depth"]
                if row["boxed"]:
                    rect(left - 6, top - LINE, WIDTH - MARGIN + 2, top, (0.22, 0.22, 0.22, 1.0))
                width = (WIDTH - MARGIN - left) / len(row["items"])
                for j, (kind, text, active) in enumerate(row["items"]):
                    x = left + j * width
                    if kind == "button":
                        rect(x, top - LINE + 3, x + width - 4, top - 2, (0.33, 0.33, 0.33, 1.0))
                        shader.bind()
                    shade = (0.92 if active else 0.5)
                    blf.color(0, shade, shade, shade if kind != "heading" else 0.6, 1.0)
                    text_x = x + (max(4, (width - 4 - blf.dimensions(0, text)[0]) / 2) if kind == "button" else 0)
                    blf.position(0, text_x, top - LINE + 7, 0)
                    blf.draw(0, text)
    buffer = offscreen.texture_color.read()
    buffer.dimensions = WIDTH * height * 4
    offscreen.free()
    return np.array(buffer, dtype=np.uint8).reshape(height, WIDTH, 4)


def draw_and_check(scene) -> None:
    """Draw the scene camera's view as the viewport would, then let it settle: the live
    view checks each mirror's drawn reflections (the panel's "In this view" lines)."""
    import bpy
    import gpu

    from curved_reflections.operators import live
    from curved_reflections.operators.capture import view_from_camera

    depsgraph = bpy.context.evaluated_depsgraph_get()
    view = view_from_camera(scene.camera, scene, depsgraph)
    offscreen = gpu.types.GPUOffScreen(view.width, view.height, format='RGBA32F')
    try:
        with offscreen.bind():
            live.draw_safely(scene, live.CAMERA_KEY, view)
    finally:
        offscreen.free()
    live.process(scene, depsgraph, wait=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "images" / "panel.png")
    parser.add_argument("--perturbation", action="store_true",
                        help="the ball in Perturbation mode on its declared exact sphere (panel_perturbation.png)")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(REPO_ROOT / "scripts"))
    import package_link

    package_link.isolate_blender_user_folder()
    package = package_link.import_as_package(REPO_ROOT)
    import bpy

    from curved_reflections.operators import demo_scenes
    from curved_reflections.operators.gpu_init import ensure_gpu
    from curved_reflections.operators.png import write_png

    ensure_gpu()
    package.register()
    try:
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        scene = demo_scenes.build("sbc_fig3", bpy.context.scene, 320, 240)
        bpy.ops.mesh.primitive_torus_add(major_radius=0.5, minor_radius=0.18, location=(2.2, -1.6, 0.4))
        ring = bpy.context.active_object
        ring.name = "Ring"
        ring.curved_reflections.is_reflector = True
        mirror = bpy.data.objects["MirrorSphere"]
        if args.perturbation:
            mirror.curved_reflections.mode = 'PERTURBATION'
            mirror.curved_reflections.analytic_shape = 'SPHERE'
        bpy.context.view_layer.objects.active = mirror
        bpy.ops.curved_reflections.bake()
        draw_and_check(scene)
        image = draw_rows(record_panel(scene, mirror))
    finally:
        package.unregister()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_png(args.out, image.astype(np.float32) / 255.0)
    print(f"wrote {args.out} ({image.shape[1]}x{image.shape[0]})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
