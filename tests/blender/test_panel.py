# SPDX-License-Identifier: GPL-3.0-or-later
"""The Reflections tab (blender/panel.py): its panels, and what each one draws.

The structure is read from the registered classes: the sub-panels hang under the main
panel, in the sidebar's Reflections tab, registered after it, two of them closed by
default. Background mode draws no UI, so each panel's ``draw`` (and ``draw_header``)
runs with a layout that records what it is asked to show: every ``prop`` must name a
real property of its data (RNA), and what is drawn greyed is recorded with it.
"""

from types import SimpleNamespace

import bpy
import pytest

from curved_reflections import blender
from curved_reflections.blender import demo_scenes, live, method_plan, method_registry, panel, scene_status

MAIN = panel.VIEW3D_PT_curved_reflections
MIRROR = panel.VIEW3D_PT_curved_reflections_mirror
GLASS = panel.VIEW3D_PT_curved_reflections_glass
REFLECTORS = panel.VIEW3D_PT_curved_reflections_reflectors
QUALITY = panel.VIEW3D_PT_curved_reflections_quality
GRIDS = panel.VIEW3D_PT_curved_reflections_grids
STATISTICS = panel.VIEW3D_PT_curved_reflections_statistics
SUB_PANELS = (MIRROR, GLASS, REFLECTORS, QUALITY, GRIDS, STATISTICS)
LIVE_BUTTONS = ("curved_reflections.start_live", "curved_reflections.refresh", "curved_reflections.clear")


class RecordingLayout:
    """Records labels, properties (checked against RNA), operators and what is greyed."""

    def __init__(self, log=None, active=True):
        self.log = log if log is not None else {"labels": [], "props": [], "blender": [], "greyed": [],
                                                "headings": [], "texts": {}}
        self.active = active
        self.use_property_split = self.use_property_decorate = False
        self.alignment = 'EXPAND'

    def _child(self, *_args, heading="", **_kwargs):
        if heading:
            self.log["headings"].append(heading)
        return RecordingLayout(self.log, self.active)

    column = row = box = grid_flow = split = _child

    def __setattr__(self, name, value):
        if name == "active" and "log" in self.__dict__:
            value = value and self.__dict__.get("active", True)
        object.__setattr__(self, name, value)

    def separator(self, **_kwargs):
        pass

    def label(self, text="", icon='NONE'):
        self.log["labels"].append((text, icon))

    def _item(self, name):
        if not self.active:
            self.log["greyed"].append(name)

    def prop(self, data, name, text=None, **_kwargs):
        assert name in data.bl_rna.properties, name
        self.log["props"].append(name)
        if text is not None:
            self.log["texts"][name] = text
        self._item(name)

    def operator(self, idname, **_kwargs):
        group, name = idname.split(".")
        getattr(getattr(bpy.ops, group), name).get_rna_type()  # raises KeyError for an unknown operator
        self.log["blender"].append(idname)
        self._item(idname)

    def operator_menu_enum(self, idname, _property, **kwargs):
        self.operator(idname, **kwargs)


def _context(scene, obj):
    return SimpleNamespace(scene=scene, active_object=obj)


def _draw(cls, scene, obj=None):
    """What ``cls.draw`` shows, and whether it split its properties as Blender's property panels do."""
    layout = RecordingLayout()
    cls.draw(SimpleNamespace(layout=layout), _context(scene, obj))
    layout.log["split"] = layout.use_property_split and not layout.use_property_decorate
    return layout.log


def _header(cls, scene, obj=None):
    layout = RecordingLayout()
    cls.draw_header(SimpleNamespace(layout=layout), _context(scene, obj))
    return layout.log


def _texts(log):
    return [text for text, _ in log["labels"]]


def test_sub_panels_hang_under_the_main_panel_in_the_reflections_tab(registered):
    assert panel.classes == (MAIN, *SUB_PANELS)
    assert not hasattr(MAIN, "bl_parent_id")
    for cls in panel.classes:
        registered_cls = getattr(bpy.types, cls.__name__)
        assert registered_cls is cls and cls.is_registered
        assert (cls.bl_space_type, cls.bl_region_type, cls.bl_category) == ('VIEW_3D', 'UI', "Reflections")
        assert cls.__name__.startswith("VIEW3D_PT_curved_reflections")
        assert cls.__doc__ and "\n" not in cls.__doc__.strip()  # the one-line tooltip
    for cls in SUB_PANELS:
        assert cls.bl_parent_id == MAIN.bl_rna.identifier == "VIEW3D_PT_curved_reflections"
    assert [cls.bl_label for cls in panel.classes] == ["Curved Reflections", "Mirror", "Glass", "Reflectors",
                                                       "Quality", "Morphing Grids", "Statistics"]
    closed = {cls.bl_label for cls in panel.classes if 'DEFAULT_CLOSED' in getattr(cls, "bl_options", set())}
    assert closed == {"Glass", "Morphing Grids", "Statistics"}
    # The package registers every sub-panel after its parent (Blender needs the parent first).
    order = [cls.__name__ for cls in blender._classes()]
    for cls in SUB_PANELS:
        assert order.index(cls.__name__) > order.index(cls.bl_parent_id)


def test_an_empty_scene_greys_what_does_not_apply(empty_scene, registered):
    scene = empty_scene
    main = _draw(MAIN, scene)
    assert main["split"]
    assert set(LIVE_BUTTONS) | {"curved_reflections.render_image", "curved_reflections.add_demo_scene"} \
        == set(main["blender"])
    assert main["props"] == ["auto_refresh"] and not main["greyed"]
    assert ("Not started: no live reflections", 'INFO') in main["labels"]

    assert _header(MIRROR, scene)["props"] == []  # no object: no Reflector checkbox
    assert _draw(MIRROR, scene)["labels"] == [("No active object", 'INFO')]

    reflectors = _draw(REFLECTORS, scene)
    assert reflectors["labels"] == [("No reflector marked", 'INFO')]
    assert reflectors["blender"] == ["curved_reflections.mark_reflector", "curved_reflections.check_scene"]

    quality = _draw(QUALITY, scene)
    assert quality["split"] and quality["headings"] == ["Polish"]
    assert quality["props"] == ["max_order", "downsample", "accuracy_px", "morph_polish_nodes", "morph_polish_frames",
                                "morph_gpu_budget_mb"]
    assert quality["texts"] == {"morph_polish_nodes": "Node Images", "morph_polish_frames": "Every Frame"}
    # No reflector wants a morphing grid: its polish and memory are greyed, the rest applies.
    assert quality["greyed"] == ["morph_polish_nodes", "morph_polish_frames", "morph_gpu_budget_mb"]

    grids = _draw(GRIDS, scene)
    assert grids["split"]
    assert grids["props"] == ["morph_grid", "morph_margin", "morph_cache_dir"]
    assert grids["blender"] == ["curved_reflections.bake_morphing", "curved_reflections.clear_morphing"]
    # Clearing stays available: grids baked before a mode changed can still be removed.
    assert grids["greyed"] == ["morph_grid", "morph_margin", "morph_cache_dir", "curved_reflections.bake_morphing"]
    texts = _texts(grids)
    assert texts[texts.index("Nodes") + 1] == "405 a grid, numbered 0-404"

    assert _draw(STATISTICS, scene)["labels"] == [("Not started: no statistics", 'INFO')]


def test_the_mirror_panel_greys_what_the_object_and_its_mode_leave_unused(empty_scene, registered):
    bpy.ops.mesh.primitive_uv_sphere_add()
    ball = bpy.context.active_object
    header = _header(MIRROR, empty_scene, ball)
    assert header["props"] == ["is_reflector"] and not header["greyed"]
    log = _draw(MIRROR, empty_scene, ball)
    assert log["split"] and log["labels"] == [(ball.name, 'OBJECT_DATA')]
    assert log["props"] == ["reflectivity", "use_fresnel", "fresnel_f0", "attenuation_distance", "mode",
                            "analytic_shape", "analytic_radii", "analytic_exponent"]
    assert set(log["greyed"]) == set(log["props"])  # not a reflector: every setting greyed

    settings = ball.curved_reflections
    settings.is_reflector = True
    assert _draw(MIRROR, empty_scene, ball)["greyed"] == ["fresnel_f0", "analytic_shape", "analytic_radii",
                                                          "analytic_exponent"]
    settings.use_fresnel = True
    settings.mode = 'PERTURBATION'
    assert _draw(MIRROR, empty_scene, ball)["greyed"] == ["analytic_radii", "analytic_exponent"]  # shape: mesh
    settings.analytic_shape = 'SPHERE'
    assert _draw(MIRROR, empty_scene, ball)["greyed"] == ["analytic_exponent"]
    settings.analytic_shape = 'SUPERQUADRIC'
    assert _draw(MIRROR, empty_scene, ball)["greyed"] == []

    bpy.ops.object.camera_add()
    camera = bpy.context.active_object
    assert _header(MIRROR, empty_scene, camera)["props"] == []
    assert _draw(MIRROR, empty_scene, camera)["labels"] == [(f"{camera.name}: a camera object cannot be a mirror",
                                                             'INFO')]


def test_the_glass_panel_shows_the_index_of_refraction_in_use_and_what_draws_the_glass(empty_scene, registered):
    bpy.ops.mesh.primitive_uv_sphere_add()
    ball = bpy.context.active_object
    assert _header(GLASS, empty_scene, ball)["props"] == ["is_refractor"]
    log = _draw(GLASS, empty_scene, ball)
    assert log["split"] and log["props"] == ["ior"] and log["greyed"] == ["ior"]  # not glass: greyed
    assert _texts(log) == ["From the material: 1.500"]
    ball.curved_reflections.is_refractor = True
    ball.curved_reflections.ior = 1.33
    log = _draw(GLASS, empty_scene, ball)
    assert not log["greyed"] and _texts(log)[0].startswith("Render Image ray traces it")
    assert " ".join(_texts(log)).endswith("the viewport does once reflections are started.")
    bpy.ops.object.camera_add()
    assert _draw(GLASS, empty_scene, bpy.context.active_object)["labels"] == [("No active object with a surface",
                                                                                'INFO')]


def test_the_glass_note_names_what_draws_each_glass_in_the_viewport_and_why():
    """Once reflections are started, the note follows the live state's glass layer: the
    GPU's trace for any glass; past the image textures its atlas holds, the refraction search for convex
    glass and the reason it has neither for other glass."""
    from types import SimpleNamespace

    from curved_reflections.blender.panel import glass_note

    reason = "'Bottle' is not convex: a ray inside it may leave and enter it again"
    glasses = [SimpleNamespace(name="Ball"), SimpleNamespace(name="Bottle")]
    layer = SimpleNamespace(glass=SimpleNamespace(glasses=glasses), unsearched={}, traced=True)
    state = SimpleNamespace(glass=layer)
    for name in ("Ball", "Bottle"):
        assert glass_note(name, state).startswith("The viewport and Render Image trace it on the GPU every frame")
    layer.traced, layer.unsearched = False, {"Bottle": reason}
    assert glass_note("Ball", state).startswith("The viewport draws what lies behind it by the refraction search")
    assert glass_note("Bottle", state).startswith(f"The viewport shows it as a solid object: {reason}. The scene's")
    assert glass_note("Lamp", state).endswith("once reflections are started.")
    assert glass_note("Ball", None).endswith("once reflections are started.")


def test_panels_on_a_baked_scene_show_methods_stats_and_status(empty_scene, registered, gpu_ready):
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, 64, 48)
    mirror = bpy.data.objects["MirrorSphere"]
    assert _texts(_draw(REFLECTORS, scene))[0] == "MirrorSphere: Auto (not started yet)"

    bpy.ops.curved_reflections.start_live()
    state = live.state_of(scene)
    choice = method_plan.last_choices(scene)[0]
    reflectors = _draw(REFLECTORS, scene)
    method = method_registry.get(choice.method)
    assert reflectors["labels"][0] == (f"MirrorSphere: {method.label}", method.icon)
    assert " ".join(_texts(reflectors)[1:]).startswith(choice.reason[:40])

    main = _texts(_draw(MAIN, scene))
    assert "Reflections up to date" in main and "Rays" not in main  # the numbers are in Statistics

    texts = _texts(_draw(STATISTICS, scene))
    for name, value in (("Rays", f"{state.stats['rays']:,}"), ("Leaves", f"{state.stats['leaves']:,}"),
                        ("Build", f"{state.stats['build_ms']:.0f} ms"),
                        ("Memory", f"{state.stats['memory_mb']:.1f} MB"),
                        ("Views", f"{state.stats['views']}")):
        assert texts[texts.index(name) + 1] == value
    assert "Draw" in texts

    mirror.curved_reflections.is_reflector = False
    bpy.context.view_layer.update()
    labels = _draw(MAIN, scene)["labels"]
    assert any(text.startswith("'Scene': has no visible object marked") and icon == 'CANCEL' for text, icon in labels)
    assert ("No reflector marked", 'INFO') in _draw(REFLECTORS, scene)["labels"]


@pytest.mark.parametrize("mode", ['MORPHING', 'OCTREE'])
def test_a_reflector_wanting_a_grid_makes_the_grid_settings_apply(empty_scene, registered, mode):
    scene = demo_scenes.build("sbc_fig3", bpy.context.scene, 64, 48)
    scene_status.forget_all()
    bpy.data.objects["MirrorSphere"].curved_reflections.mode = mode
    grids = _draw(GRIDS, scene)
    assert grids["greyed"] == []
    assert ("MirrorSphere: runtime mode: not baked or loaded yet", 'INFO') in grids["labels"]
    assert _draw(QUALITY, scene)["greyed"] == []
    scene.curved_reflections.morph_polish_nodes = False
    assert _draw(QUALITY, scene)["greyed"] == ["morph_polish_frames"]  # it polishes the node images' answers
