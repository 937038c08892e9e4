# SPDX-License-Identifier: GPL-3.0-or-later
"""Draw a picture of the Reflections tab for the user guide.

    .venv/bin/python scripts/panel_picture.py --out docs/images/panel.png

Background mode draws no UI, so each panel's own ``draw`` and ``draw_header``
(``blender/panel.py``) run with a layout that records what they show (labels,
properties with their current values, operator buttons, boxes, greyed rows), and the
record is drawn with Blender's font module (``blf``) into an offscreen image: the main
panel, then each sub-panel's header, open or closed as it is by default (a closed one
shows its header only), its body below when open. Properties of a panel that splits
them (``use_property_split``) are drawn as Blender does: the name right-aligned in the
left column, the field in the right one. The picture shows the tab on the mirror-ball
demo scene with a torus mirror added, baked, both in the default Auto mode: the ball is
star-shaped and searched on the GPU (Iterative), the torus is not and is ray traced on
the GPU, each line saying why; the scene camera's view is drawn and checked, so the
ball's lines also show its accuracy measured in that view (the check measures answers
per vertex: the trace has none). The widgets' look is a
sketch, not Blender's theme.
With ``--perturbation`` the ball is in Perturbation mode on its declared exact sphere:

    .venv/bin/python scripts/panel_picture.py --perturbation --out docs/images/panel_perturbation.png

Prints one line per panel (``panel Statistics: closed, 0 rows``), one per mirror checked
in the view (``checked MirrorSphere: In this view (Iterative): p95 ...``), then the file written.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / "scripts"))
import package_link  # noqa: E402  (found through the line above)

package_link.isolate_blender_user_folder()  # before bpy is imported
PACKAGE = package_link.import_as_package(REPO_ROOT)

import bpy  # noqa: E402  (first: it makes Blender's other modules importable)
import blf  # noqa: E402
import gpu  # noqa: E402
from gpu_extras.batch import batch_for_shader  # noqa: E402
from mathutils import Matrix  # noqa: E402

from curved_reflections.blender import accuracy, demo_scenes, live, method_plan, panel  # noqa: E402
from curved_reflections.blender.capture import view_from_camera  # noqa: E402
from curved_reflections.blender.gpu_init import ensure_gpu  # noqa: E402
from curved_reflections.blender.png import write_png  # noqa: E402

WIDTH, LINE, HEADER, GAP, INDENT, MARGIN, ICON = 540, 22, 26, 8, 14, 10, 18
#: Share of a split property's row taken by its name (Blender's ``use_property_split``).
SPLIT = 0.4
BACKGROUND, PANEL, HEADER_MAIN, HEADER_SUB, BOX = (0.14,) * 3, (0.19,) * 3, (0.25,) * 3, (0.23,) * 3, (0.16,) * 3
BUTTON, FIELD, TEXT_FIELD, CHECKED = (0.33,) * 3, (0.27,) * 3, (0.11,) * 3, (0.28, 0.45, 0.70)


class Recorder:
    """A UILayout stand-in: every call becomes a row (a dict of depth, items, box, height)."""

    def __init__(self, rows: list, depth: int = 0, active: bool = True, entry: dict | None = None, box=None,
                 split: bool = False, heading: str = ""):
        self.rows, self.depth, self.entry, self.boxed, self.heading = rows, depth, entry, box, heading
        self.active, self.alignment = active, 'EXPAND'
        self.use_property_split, self.use_property_decorate = split, False

    def __setattr__(self, name, value):
        if name == "active" and "active" in self.__dict__:
            value = value and self.__dict__["active"]
        object.__setattr__(self, name, value)

    def _row(self, items=(), height=LINE, **extra) -> dict:
        entry = {"depth": self.depth, "items": list(items), "box": self.boxed, "height": height, **extra}
        self.rows.append(entry)
        return entry

    def _emit(self, item: dict) -> None:
        item.setdefault("active", self.active)
        item.setdefault("align", self.alignment)
        if self.entry is not None:
            self.entry["items"].append(item)
        else:
            self._row([item])

    def _child(self, entry=None, box=None, heading=""):
        return Recorder(self.rows, self.depth + (box is not None), self.active, entry,
                        box if box is not None else self.boxed, self.use_property_split, heading)

    def column(self, heading="", **_kwargs):
        return self._child(heading=heading) if self.entry is None else self._child(self.entry)

    def row(self, **_kwargs):
        return self._child(self.entry if self.entry is not None else self._row())

    def split(self, factor=0.5, **_kwargs):
        return self._child(self._row(factor=factor))

    def box(self):
        self._row(height=GAP // 2)
        return self._child(box=len(self.rows))

    def separator(self, **_kwargs):
        self._row(height=GAP)

    def label(self, text="", icon='NONE'):
        self._emit({"kind": "label", "text": text, "icon": icon})

    def prop(self, data, name, text=None, **_kwargs):
        rna = data.bl_rna.properties[name]
        value = getattr(data, name)
        label = rna.name if text is None else text
        if rna.type == 'BOOLEAN':
            widget, shown = "check", bool(value)
        elif rna.type == 'ENUM':
            widget, shown = "menu", bpy.types.UILayout.enum_item_name(data, name, value)  # dynamic enums too
        elif rna.type == 'STRING':
            widget, shown = "text", value
        elif getattr(rna, "array_length", 0):
            widget, shown = "vector", [f"{v:.3g}" if isinstance(v, float) else str(v) for v in value]
        else:
            widget, shown = "number", f"{value:.3g}" if rna.type == 'FLOAT' else str(value)
        heading, self.heading = (self.heading if widget == "check" else ""), ""
        self._emit({"kind": "prop", "text": label, "widget": widget, "value": shown, "heading": heading,
                    "split": self.use_property_split})

    def operator(self, idname, text=None, icon='NONE', **_kwargs):
        group, name = idname.split(".")
        self._emit({"kind": "button", "text": text or getattr(getattr(bpy.ops, group), name).get_rna_type().name,
                    "icon": icon})

    def operator_menu_enum(self, idname, _property, text=None, **kwargs):
        self.operator(idname, text=text, **kwargs)


def record_panels(scene, obj) -> list:
    """(panel class, open, body rows) of the tab's panels in their order, each drawn as by
    default: the closed ones (``DEFAULT_CLOSED``) show their header alone."""
    context = SimpleNamespace(scene=scene, active_object=obj)
    panels = []
    for cls in panel.classes:
        header: list = []
        if hasattr(cls, "draw_header"):
            cls.draw_header(SimpleNamespace(layout=Recorder(header)), context)
        is_open = 'DEFAULT_CLOSED' not in getattr(cls, "bl_options", set())
        rows: list = []
        if is_open:
            cls.draw(SimpleNamespace(layout=Recorder(rows)), context)
        items = [item for row in header for item in row["items"]]
        panels.append((cls, is_open, items, [r for r in rows if r["items"] or r["height"] != LINE]))
    return panels


def layout_rows(panels) -> list:
    """Every row to draw, headers included, top to bottom."""
    rows = []
    for cls, is_open, header_items, body in panels:
        main = not hasattr(cls, "bl_parent_id")
        rows.append({"header": cls.bl_label, "main": main, "open": is_open, "items": header_items,
                     "height": HEADER if main else LINE + 2, "depth": 0, "box": None})
        rows.extend(body)
        if is_open:
            rows.append({"items": [], "height": GAP // 2, "depth": 0, "box": None})
    return rows


def _text(x, y, text, active=True, grey=0.92):
    shade = grey if active else 0.5
    blf.color(0, shade, shade, shade, 1.0)
    blf.position(0, x, y, 0)
    blf.draw(0, text)


def draw_rows(rows: list) -> np.ndarray:
    """(H, W, 4) uint8 RGBA, rows bottom to top: headers with their disclosure triangle,
    panels lighter than the region, boxes darker, buttons and fields framed; icons leave
    their room empty."""
    height = 2 * MARGIN + sum(row["height"] for row in rows)
    offscreen = gpu.types.GPUOffScreen(WIDTH, height, format='RGBA8')
    shader = gpu.shader.from_builtin('UNIFORM_COLOR')

    def shape(points, color, active=True):
        batch = batch_for_shader(shader, 'TRIS', {"pos": points})
        shader.bind()
        dim = 1.0 if active else 0.75
        shader.uniform_float("color", (*(c * dim for c in color), 1.0))
        batch.draw(shader)

    def rect(x0, y0, x1, y1, color, active=True):
        shape([(x0, y0), (x1, y0), (x1, y1), (x0, y0), (x1, y1), (x0, y1)], color, active)

    def check(x, y, checked, active):
        rect(x, y, x + 14, y + 14, CHECKED if checked else BUTTON, active)
        if checked:
            _text(x + 2, y + 2, "\u2713", active)

    def field(x0, x1, y, item):
        """The value part of a property, between x0 and x1 on the row whose text sits at y."""
        widget, value, active = item["widget"], item["value"], item["active"]
        if widget == "check":
            check(x0, y - 2, value, active)
            _text(x0 + 20, y, item["text"], active)
        elif widget == "vector":
            step = (x1 - x0) / len(value)
            for k, part in enumerate(value):
                rect(x0 + k * step, y - 5, x0 + (k + 1) * step - 2, y + 14, FIELD, active)
                _text(x0 + k * step + (step - blf.dimensions(0, part)[0]) / 2, y, part, active)
        else:
            rect(x0, y - 5, x1, y + 14, TEXT_FIELD if widget == "text" else FIELD, active)
            if widget == "number":
                _text(x0 + (x1 - x0 - blf.dimensions(0, value)[0]) / 2, y, value, active)
            else:
                _text(x0 + 6, y, value, active)
            if widget == "menu":
                _text(x1 - 14, y, "\u2304", active, 0.7)

    with offscreen.bind():
        gpu.state.active_framebuffer_get().clear(color=(*BACKGROUND, 1.0))
        with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
            gpu.matrix.load_matrix(Matrix.Identity(4))
            gpu.matrix.load_projection_matrix(Matrix(((2 / WIDTH, 0, 0, -1), (0, 2 / height, 0, -1), (0, 0, 1, 0),
                                                      (0, 0, 0, 1))))
            blf.size(0, 13)
            top = height - MARGIN
            for row in rows:
                bottom = top - row["height"]
                base = bottom + (row["height"] - 13) / 2 + 2
                if "header" in row:
                    rect(MARGIN / 2, bottom + 1, WIDTH - MARGIN / 2, top, HEADER_MAIN if row["main"] else HEADER_SUB)
                    x = MARGIN
                    tip = base + 4
                    if row["open"]:
                        shape([(x, tip + 4), (x + 10, tip + 4), (x + 5, tip - 3)], (0.75,) * 3)
                    else:
                        shape([(x + 2, tip + 6), (x + 2, tip - 4), (x + 9, tip + 1)], (0.75,) * 3)
                    x += 18
                    for item in row["items"]:  # the header's checkbox
                        check(x, base - 2, item["value"], item["active"])
                        x += 20
                    _text(x, base, row["header"])
                    top = bottom
                    continue
                rect(MARGIN / 2, bottom, WIDTH - MARGIN / 2, top, PANEL)
                left = MARGIN + INDENT * row["depth"]
                right = WIDTH - MARGIN
                if row["box"] is not None:
                    rect(left - 4, bottom, right + 2, top, BOX)
                    left += 4
                items = row["items"]
                factor = row.get("factor")
                widths = ([factor * (right - left), (1 - factor) * (right - left)] if factor and len(items) == 2
                          else [(right - left) / max(len(items), 1)] * len(items))
                x = left
                for item, width in zip(items, widths):
                    kind, text, active = item["kind"], item["text"], item["active"]
                    if kind == "button":
                        rect(x, bottom + 2, x + width - 2, top - 2, BUTTON, active)
                        text_width = blf.dimensions(0, text)[0] + (ICON if item["icon"] != 'NONE' else 0)
                        start = x + max(4, (width - 2 - text_width) / 2)
                        _text(start + (ICON if item["icon"] != 'NONE' else 0), base, text, active)
                    elif kind == "label":
                        offset = ICON if item["icon"] != 'NONE' else 0
                        start = x + width - 6 - blf.dimensions(0, text)[0] if item["align"] == 'RIGHT' else x
                        _text(start + offset, base, text, active)
                    elif item["split"]:
                        name = item["heading"] if item["widget"] == "check" else item["text"]
                        name_right = x + SPLIT * width - 8
                        _text(name_right - blf.dimensions(0, name)[0], base, name, active)
                        field(x + SPLIT * width, x + width - 2, base, item)
                    else:
                        field(x, x + width - 2, base, item)
                    x += width
                top = bottom
    buffer = offscreen.texture_color.read()
    buffer.dimensions = WIDTH * height * 4
    offscreen.free()
    return np.array(buffer, dtype=np.uint8).reshape(height, WIDTH, 4)


def draw_and_check(scene) -> None:
    """Draw the scene camera's view as the viewport would, then let it settle: the live
    view checks each mirror's drawn reflections (the panel's "In this view" lines)."""
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
    parser.add_argument("--resolution", type=int, nargs=2, default=(320, 240), metavar=("WIDTH", "HEIGHT"),
                        help="the scene camera's view (its statistics; the picture is the panels')")
    parser.add_argument("--perturbation", action="store_true",
                        help="the ball in Perturbation mode on its declared exact sphere (panel_perturbation.png)")
    parser.add_argument("--check-sample", type=int, default=accuracy.CAMERA_SAMPLE, metavar="VERTICES",
                        help="vertices the Runtime camera projects for the live accuracy check (the tests' "
                             "quick run: fewer)")
    args = parser.parse_args(argv)
    accuracy.CAMERA_SAMPLE = args.check_sample
    ensure_gpu()
    PACKAGE.register()
    try:
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        scene = demo_scenes.build("sbc_fig3", bpy.context.scene, *args.resolution)
        bpy.ops.mesh.primitive_torus_add(major_radius=0.5, minor_radius=0.18, location=(2.2, -1.6, 0.4))
        ring = bpy.context.active_object
        ring.name = "Ring"
        ring.curved_reflections.is_reflector = True
        mirror = bpy.data.objects["MirrorSphere"]
        if args.perturbation:
            mirror.curved_reflections.mode = 'PERTURBATION'
            mirror.curved_reflections.analytic_shape = 'SPHERE'
        bpy.context.view_layer.objects.active = mirror
        bpy.ops.curved_reflections.start_live()
        draw_and_check(scene)
        panels = record_panels(scene, mirror)
        checks = {name: accuracy.panel_line(found) for name, found in method_plan.measured(scene).items()}
        image = draw_rows(layout_rows(panels))
    finally:
        PACKAGE.unregister()
    for cls, is_open, _header, body in panels:
        print(f"panel {cls.bl_label}: {'open' if is_open else 'closed'}, {sum(bool(r['items']) for r in body)} rows")
    for name, line in sorted(checks.items()):
        print(f"checked {name}: {line}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_png(args.out, image.astype(np.float32) / 255.0)
    print(f"wrote {args.out} ({image.shape[1]}x{image.shape[0]})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
