# SPDX-License-Identifier: GPL-3.0-or-later
"""The Reflections tab's draw code (operators/panel.py) on a baked scene.

Background mode draws no UI, so the panel's ``draw`` runs with a layout that records
what it is asked to show; every ``prop`` must name a real property of its data (RNA),
and the live box shows the stats and the status line of the live state.
"""

from types import SimpleNamespace

import bpy

from curved_reflections.operators import demo_scenes, live
from curved_reflections.operators.panel import VIEW3D_PT_curved_reflections


class RecordingLayout:
    """Records labels, properties (checked against RNA), operators and greyed rows."""

    def __init__(self, log=None, active=True):
        self.log = log if log is not None else {"labels": [], "props": [], "operators": [], "greyed": []}
        self.active = active
        self.use_property_split = self.use_property_decorate = False

    def _child(self, *_args, **_kwargs):
        return RecordingLayout(self.log, self.active)

    column = row = box = grid_flow = _child

    def __setattr__(self, name, value):
        if name == "active" and "log" in self.__dict__:
            value = value and self.__dict__.get("active", True)
        object.__setattr__(self, name, value)

    def label(self, text="", icon='NONE'):
        self.log["labels"].append((text, icon))

    def prop(self, data, name, **_kwargs):
        assert name in data.bl_rna.properties, name
        self.log["props"].append(name)
        if not self.active:
            self.log["greyed"].append(name)

    def operator(self, idname, **_kwargs):
        self.log["operators"].append(idname)

    def operator_menu_enum(self, idname, _property, **_kwargs):
        self.log["operators"].append(idname)


def _draw(scene, obj):
    layout = RecordingLayout()
    VIEW3D_PT_curved_reflections.draw(SimpleNamespace(layout=layout), SimpleNamespace(scene=scene, active_object=obj))
    return layout.log


def test_panel_shows_settings_buttons_stats_and_status(empty_scene, registered, gpu_ready):
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, 64, 48)
    mirror = bpy.data.objects["MirrorSphere"]
    log = _draw(scene, mirror)
    assert {"curved_reflections.bake", "curved_reflections.refresh", "curved_reflections.clear"} <= set(log["operators"])
    assert {"is_reflector", "reflectivity", "use_fresnel", "fresnel_f0", "attenuation_distance", "mode", "downsample",
            "accuracy_px", "max_order", "auto_refresh", "morph_grid", "morph_margin", "morph_polish_nodes",
            "morph_polish_frames", "morph_gpu_budget_mb"} <= set(
        log["props"])
    # Not applicable: Facing Reflectance without Fresnel, the morphing grid without a morphing reflector.
    assert set(log["greyed"]) == {"fresnel_f0", "morph_grid", "morph_margin", "morph_polish_nodes",
                                  "morph_polish_frames", "morph_gpu_budget_mb"}
    assert ("Not baked: no live reflections", 'INFO') in log["labels"]

    bpy.ops.curved_reflections.bake()
    texts = [text for text, _ in _draw(scene, mirror)["labels"]]
    state = live.state_of(scene)
    for name, value in (("Rays", f"{state.stats['rays']:,}"), ("Leaves", f"{state.stats['leaves']:,}"),
                        ("Build", f"{state.stats['build_ms']:.0f} ms"), ("Memory", f"{state.stats['memory_mb']:.1f} MB")):
        assert texts[texts.index(name) + 1] == value
    assert "Draw" in texts and "Reflections up to date" in texts

    bpy.data.objects["Cube"].curved_reflections.use_fresnel = True  # not a reflector: all its settings greyed
    log = _draw(scene, bpy.data.objects["Cube"])
    assert {"reflectivity", "use_fresnel", "fresnel_f0", "mode"} <= set(log["greyed"])
    mirror.curved_reflections.is_reflector = False
    bpy.context.view_layer.update()
    labels = _draw(scene, None)["labels"]
    assert ("No reflector marked", 'INFO') in labels
    assert any(text.startswith("'Scene': has no visible object marked as a reflector") and icon == 'CANCEL'
               for text, icon in labels)


def test_panel_shows_the_morphing_box_when_a_reflector_is_in_morphing_mode(empty_scene, registered):
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, 64, 48)
    mirror = bpy.data.objects["MirrorSphere"]
    assert "curved_reflections.bake_morphing" not in _draw(scene, mirror)["operators"]
    mirror.curved_reflections.mode = 'MORPHING'
    log = _draw(scene, mirror)
    assert {"curved_reflections.bake_morphing", "curved_reflections.clear_morphing"} <= set(log["operators"])
    assert not {"morph_grid", "morph_margin"} & set(log["greyed"])
    assert ("MirrorSphere: runtime mode: not baked or loaded yet", 'INFO') in log["labels"]
