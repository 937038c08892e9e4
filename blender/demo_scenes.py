# SPDX-License-Identifier: GPL-3.0-or-later
"""Demo scenes built by code: curved mirrors with objects close to them.

Each scene is made to be *measured*: every diffuse object is a flat, distinct,
saturated emission colour and the world a further flat colour, so every rendered pixel
says which object it shows (the label metrics of ``tools/metrics.py``). Mirrors are
perfect (metallic 1, roughness 0, white) and carry the exact normals of the surface they
sample as custom split normals. No lights are needed: nothing is lit, everything emits.

Scenes:
- ``sbc_fig3``: Popescu, Sacks & Mei 2006, Fig. 3: a mirror sphere on a tiled floor among
  columns, two close in front, and a small cube almost touching the sphere.
- ``teapot``: a teapot-like mirror (body of revolution, lid and knob, curved spout,
  torus handle) with objects close around it.
- ``two_spheres``: two mirror spheres 0.18 apart, for second-order reflections.
- ``vase``: Chen & Arvo 2000, §IV: the cubic vase of mixed convexity, with objects near
  its neck and base.
- ``glass``: a glass ball and a thick lens (Glass BSDF, IOR 1.45) among columns, a cube
  close behind the ball (issue 47).
"""

from __future__ import annotations

import math

import bpy
import numpy as np
from bpy.props import EnumProperty, IntProperty
from mathutils import Vector

from ..engine.geometry import shapes
from ..engine.srgb import srgb_to_linear
from ..engine.geometry.sphere import bumpy_icosphere

#: Display-sRGB label colours, channels in {0, 0.5, 1} with at least one 1 and not white:
#: any two differ by >= 0.5 in some channel and all lie >= 1 away from black. Ordered so
#: that the first objects of a scene get the most different hues.
WORLD_COLOUR = (0.5, 0.5, 1.0)  # periwinkle sky
FLOOR_COLOURS = ((1.0, 1.0, 0.5), (1.0, 0.5, 0.5))  # cream and salmon tiles
DIFFUSE_COLOURS = (
    (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 1.0, 0.0), (0.0, 1.0, 1.0),
    (1.0, 0.0, 1.0), (1.0, 0.5, 0.0), (0.5, 0.0, 1.0), (0.0, 1.0, 0.5), (1.0, 0.0, 0.5),
    (0.5, 1.0, 0.0), (0.0, 0.5, 1.0), (1.0, 0.5, 1.0), (0.5, 1.0, 1.0), (0.5, 1.0, 0.5),
)
LABEL_COLOURS = (WORLD_COLOUR, *FLOOR_COLOURS, *DIFFUSE_COLOURS)
#: Palette key of the world background (no demo object has parentheses in its name).
WORLD_KEY = "(world)"
MIRROR_MATERIAL = "CR Mirror"

SCENES = (
    ("sbc_fig3", "SBC Fig. 3", "Mirror sphere, columns, tiled floor and a cube almost touching it"),
    ("teapot", "Teapot", "Teapot-shaped mirror with objects close to it"),
    ("two_spheres", "Two Spheres", "Two mirror spheres close together (second-order reflections)"),
    ("vase", "Chen-Arvo Vase", "The cubic vase of Chen & Arvo 2000 with objects near it"),
    ("bumpy_ball", "Bumpy Ball", "A bumpy mirror ball (star-shaped, not convex) among columns, a cube close by"),
    ("glass", "Glass", "A glass ball and a thick lens among columns, a cube close behind the ball (Render Image)"),
)
#: The demo glass's index of refraction (a Glass BSDF's, as Cycles renders it).
GLASS_IOR = 1.45


# --- scene set-up -------------------------------------------------------------------


def _prepare(scene, width: int, height: int):
    """Resolution, predictable colour (Standard view transform) and a flat world."""
    scene.render.resolution_x, scene.render.resolution_y = int(width), int(height)
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    scene.display_settings.display_device = "sRGB"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.world = _flat_world(scene.name)


def _flat_world(name: str):
    world = bpy.data.worlds.new(f"CR World {name}")
    background = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
    linear = srgb_to_linear(WORLD_COLOUR)
    background.inputs["Color"].default_value = (*linear, 1.0)
    background.inputs["Strength"].default_value = 1.0
    world.color = linear
    return world


def _mirror_material():
    """Perfect mirror: Principled BSDF, metallic 1, roughness 0, white base colour."""
    material = bpy.data.materials.get(MIRROR_MATERIAL)
    if material is not None:
        return material
    material = bpy.data.materials.new(MIRROR_MATERIAL)
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bsdf.inputs["Metallic"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = 0.0
    material.diffuse_color = (1.0, 1.0, 1.0, 1.0)
    material.metallic, material.roughness = 1.0, 0.0
    return material


def _shader_material(name: str, node_type: str, inputs: dict):
    """A material of one shader node, its ``inputs`` set, feeding the output's Surface."""
    material = bpy.data.materials.new(name)
    nodes = material.node_tree.nodes
    nodes.clear()
    shader = nodes.new(node_type)
    for socket, value in inputs.items():
        shader.inputs[socket].default_value = value
    output = nodes.new("ShaderNodeOutputMaterial")
    material.node_tree.links.new(shader.outputs[0], output.inputs["Surface"])
    return material


def _emission_material(name: str, display_colour):
    """Emission-only material: the pixel shows exactly this colour, unlit."""
    linear = (*srgb_to_linear(display_colour), 1.0)
    material = _shader_material(f"CR {name}", "ShaderNodeEmission", {"Color": linear, "Strength": 1.0})
    material.diffuse_color = linear
    return material


def _mesh_object(scene, name: str, shape: shapes.Shape, material, location=(0, 0, 0), rotation_z=0.0):
    """Link a new mesh object built from ``shape``; smooth, with its normals as custom normals."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(shape.vertices.tolist(), [], shape.faces())
    mesh.shade_smooth()
    mesh.normals_split_custom_set_from_vertices(shape.normals.tolist())
    mesh.materials.append(material)
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    obj.rotation_euler = (0.0, 0.0, rotation_z)
    scene.collection.objects.link(obj)
    return obj


def _reflector(scene, name: str, shape: shapes.Shape, location=(0, 0, 0), rotation_z=0.0):
    obj = _mesh_object(scene, name, shape, _mirror_material(), location, rotation_z)
    obj.curved_reflections.is_reflector = True
    obj.color = (1.0, 1.0, 1.0, 1.0)
    return obj


def _glass(scene, name: str, shape: shapes.Shape, location=(0, 0, 0)):
    material = _shader_material(f"CR Glass {name}", "ShaderNodeBsdfGlass", {"IOR": GLASS_IOR, "Roughness": 0.0})
    obj = _mesh_object(scene, name, shape, material, location)
    obj.curved_reflections.is_refractor = True
    return obj


def _diffuse(scene, name: str, shape: shapes.Shape, colour, location=(0, 0, 0), rotation_z=0.0):
    material = _emission_material(name, colour)
    obj = _mesh_object(scene, name, shape, material, location, rotation_z)
    obj.color = material.diffuse_color
    return obj


def _checker_floor(scene, count: int = 24, tile: float = 0.75):
    """Two objects, one per checker colour, so that every object has one colour."""
    for parity, suffix in ((0, "A"), (1, "B")):
        _diffuse(scene, f"Floor{suffix}", shapes.checker_tiles(count, tile, parity),
                 FLOOR_COLOURS[parity])


def _camera(scene, eye, target, lens_mm: float):
    data = bpy.data.cameras.new(f"CR Camera {scene.name}")
    data.lens = lens_mm
    data.clip_start, data.clip_end = 0.05, 100.0
    obj = bpy.data.objects.new(f"Camera {scene.name}", data)
    obj.location = eye
    direction = Vector(target) - Vector(eye)
    obj.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(obj)
    scene.camera = obj
    return obj


# --- the scenes ---------------------------------------------------------------------


def build_sbc_fig3(scene):
    """SBC paper Fig. 3: mirror sphere among columns on a checker floor, cube almost touching."""
    colours = iter(DIFFUSE_COLOURS)
    _checker_floor(scene)
    _reflector(scene, "MirrorSphere", shapes.sphere(1.0, 64, 32), (0.0, 0.0, 1.0))
    columns = ((-1.25, -1.15), (1.3, -0.95), (-2.5, 0.7), (2.6, 0.9), (-1.3, 2.7), (1.1, 2.9),
               (0.5, -8.0))
    column = shapes.cylinder(0.15, 2.6, 24)
    for k, (x, y) in enumerate(columns):
        _diffuse(scene, f"Column{k + 1}", column, next(colours), (x, y, 0.0))
    # A cube whose face is tangent to the sphere 0.03 away from it.
    direction = np.array([0.62, -0.72, -0.3]) / np.linalg.norm([0.62, -0.72, -0.3])
    half = 0.175
    centre = np.array([0.0, 0.0, 1.0]) + direction * (1.0 + 0.03 + half)
    cube = _diffuse(scene, "Cube", shapes.box((2 * half,) * 3), next(colours), tuple(centre))
    cube.rotation_euler = Vector(direction).to_track_quat("X", "Z").to_euler()
    _camera(scene, (0.0, -6.5, 2.3), (0.0, 0.0, 0.9), 45.0)


def build_teapot(scene):
    """Teapot-like mirror on a checker floor with a ball, a cup, a cube and more close by."""
    colours = iter(DIFFUSE_COLOURS)
    _checker_floor(scene)
    _reflector(scene, "MirrorTeapot", shapes.teapot(64), (0.0, 0.0, 0.0), math.radians(-15.0))
    _diffuse(scene, "Ball", shapes.sphere(0.35, 32, 16), next(colours), (0.35, -1.6, 0.35))
    _diffuse(scene, "Cube", shapes.box((0.4, 0.4, 0.4)), next(colours), (2.1, -0.9, 0.2), 0.4)
    _diffuse(scene, "Cup", shapes.cylinder(0.3, 0.6, 32), next(colours), (-1.35, -1.25, 0.0))
    _diffuse(scene, "Column", shapes.cylinder(0.18, 2.8, 24), next(colours), (-0.6, 2.0, 0.0))
    _diffuse(scene, "Gem", shapes.icosahedron(0.3), next(colours), (1.1, 1.2, 1.1))
    _diffuse(scene, "Panel", shapes.box((2.0, 0.08, 1.4)), next(colours), (0.5, -8.0, 1.2))
    _camera(scene, (3.0, -5.2, 2.6), (0.1, 0.0, 0.75), 45.0)


def build_two_spheres(scene):
    """Two mirror spheres 0.18 apart with coloured objects around and between them."""
    colours = iter(DIFFUSE_COLOURS)
    _checker_floor(scene)
    _reflector(scene, "MirrorSphereA", shapes.sphere(1.0, 64, 32), (-1.05, 0.0, 1.0))
    _reflector(scene, "MirrorSphereB", shapes.sphere(0.75, 64, 32), (0.85, -0.25, 0.75))
    _diffuse(scene, "Cube", shapes.box((0.5, 0.5, 0.5)), next(colours), (-0.4, -1.5, 0.25), 0.3)
    _diffuse(scene, "Gem", shapes.icosahedron(0.25), next(colours), (0.0, -0.9, 1.75))
    _diffuse(scene, "Block", shapes.box((0.4, 0.4, 0.6)), next(colours), (0.0, 0.9, 0.3))
    _diffuse(scene, "ColumnLeft", shapes.cylinder(0.15, 2.6, 24), next(colours), (-2.7, 1.2, 0.0))
    _diffuse(scene, "ColumnRight", shapes.cylinder(0.15, 2.6, 24), next(colours), (2.3, 1.0, 0.0))
    _diffuse(scene, "Panel", shapes.box((2.5, 0.08, 1.6)), next(colours), (0.0, -8.0, 1.2))
    _camera(scene, (0.3, -6.0, 2.2), (-0.1, 0.0, 0.9), 42.0)


def build_vase(scene):
    """Chen-Arvo vase (§IV) standing on a checker floor, objects near its neck and base."""
    colours = iter(DIFFUSE_COLOURS)
    _checker_floor(scene)
    _reflector(scene, "MirrorVase", shapes.vase(96, 64))
    _diffuse(scene, "Gem", shapes.icosahedron(0.25), next(colours), (0.65, -0.55, 1.55))
    _diffuse(scene, "Box", shapes.box((0.4, 0.4, 0.4)), next(colours), (0.95, -0.5, 0.2), 0.5)
    _diffuse(scene, "Window", shapes.box((1.2, 0.05, 1.6)), next(colours), (-1.5, 0.5, 1.0), -0.8)
    _diffuse(scene, "Column", shapes.cylinder(0.15, 2.6, 24), next(colours), (0.8, 1.8, 0.0))
    _diffuse(scene, "Panel", shapes.box((2.0, 0.08, 1.4)), next(colours), (-0.3, -7.0, 1.2))
    _camera(scene, (0.0, -5.2, 1.45), (0.0, 0.0, 0.95), 50.0)


def build_bumpy_ball(scene):
    """A mirror ball with bumps (radius 1 + 0.06 sin 5 phi sin 4 theta: star-shaped, not
    convex, several images of some points) among columns, a cube close to it."""
    colours = iter(DIFFUSE_COLOURS)
    _checker_floor(scene)
    ball = bumpy_icosphere((0.0, 0.0, 0.0), 1.0, 5, 0.06)
    _reflector(scene, "MirrorBumpy", shapes.Shape(ball.vertices, ball.normals, tris=ball.triangles), (0.0, 0.0, 1.1))
    for k, (x, y) in enumerate(((-1.4, -1.0), (1.5, -0.8), (-2.3, 1.0), (2.2, 1.3), (0.2, 2.6))):
        _diffuse(scene, f"Column{k + 1}", shapes.cylinder(0.15, 2.4, 24), next(colours), (x, y, 0.0))
    _diffuse(scene, "Cube", shapes.box((0.4, 0.4, 0.4)), next(colours), (0.95, -1.05, 0.2), 0.6)
    _camera(scene, (1.2, -6.2, 2.4), (0.0, 0.0, 1.0), 45.0)


def build_glass(scene):
    """A glass ball and a thick lens (a sphere squashed to 0.4 along the view) on a
    checker floor, columns behind them, a cube 0.1 (5 % of the ball) behind the ball."""
    colours = iter(DIFFUSE_COLOURS)
    _checker_floor(scene)
    _glass(scene, "GlassBall", shapes.sphere(1.0, 64, 32), (-1.1, 0.0, 1.0))
    ball = shapes.sphere(0.9, 64, 32)
    squash = np.array([1.0, 0.4, 1.0])
    normals = ball.normals / squash
    lens = shapes.Shape(ball.vertices * squash, normals / np.linalg.norm(normals, axis=1, keepdims=True),
                        ball.tris, ball.quads)
    _glass(scene, "GlassLens", lens, (1.3, 0.0, 1.1))
    _diffuse(scene, "Cube", shapes.box((0.5, 0.5, 0.5)), next(colours), (-1.1, 1.35, 0.9), 0.4)
    for k, (x, y) in enumerate(((-2.2, 2.2), (-0.2, 2.6), (1.0, 1.6), (1.8, 2.8), (2.9, 1.2))):
        _diffuse(scene, f"Column{k + 1}", shapes.cylinder(0.18, 2.6, 24), next(colours), (x, y, 0.0))
    _diffuse(scene, "Panel", shapes.box((6.0, 0.08, 2.5)), next(colours), (0.0, 4.5, 1.25))
    _camera(scene, (0.1, -6.5, 1.7), (0.1, 0.0, 1.0), 40.0)


BUILDERS = {
    "sbc_fig3": build_sbc_fig3,
    "teapot": build_teapot,
    "two_spheres": build_two_spheres,
    "vase": build_vase,
    "bumpy_ball": build_bumpy_ball,
    "glass": build_glass,
}


def build(kind: str, scene=None, width: int = 320, height: int = 240):
    """Build the demo scene ``kind`` into ``scene`` (a new scene named ``kind`` if None)."""
    if kind not in BUILDERS:
        raise ValueError(f"unknown demo scene {kind!r}; choose from {sorted(BUILDERS)}")
    scene = scene if scene is not None else bpy.data.scenes.new(kind)
    _prepare(scene, width, height)
    BUILDERS[kind](scene)
    for view_layer in scene.view_layers:
        view_layer.update()  # world matrices are valid from here on, active scene or not
    return scene


# --- reading a scene back -----------------------------------------------------------


def reflectors(scene) -> list:
    """The scene's mesh objects marked as reflectors."""
    return [o for o in scene.objects if o.type == "MESH" and o.curved_reflections.is_reflector]


def _emission_colour(material):
    if material is None or material.node_tree is None:
        return None
    node = next((n for n in material.node_tree.nodes if n.type == "EMISSION"), None)
    return None if node is None else tuple(node.inputs["Color"].default_value[:3])


def palette(scene) -> dict[str, tuple[float, float, float]]:
    """Label palette read from the materials: diffuse object name -> linear RGB, plus the world.

    The world's colour is under :data:`WORLD_KEY`, first. Objects whose material is not
    an emission shader (reflectors, glass, anything else) are left out.
    """
    result = {}
    if scene.world is not None and scene.world.node_tree is not None:
        node = next((n for n in scene.world.node_tree.nodes if n.type == "BACKGROUND"), None)
        if node is not None:
            result[WORLD_KEY] = tuple(node.inputs["Color"].default_value[:3])
    for obj in scene.objects:
        if obj.type != "MESH" or obj.curved_reflections.is_reflector or obj.curved_reflections.is_refractor:
            continue
        colour = _emission_colour(obj.active_material)
        if colour is not None:
            result[obj.name] = colour
    return result


# --- operator -----------------------------------------------------------------------


class CURVED_REFLECTIONS_OT_add_demo_scene(bpy.types.Operator):
    """Add a new scene with curved mirrors and objects close to them"""

    bl_idname = "curved_reflections.add_demo_scene"
    bl_label = "Add Curved Reflections Demo Scene"
    bl_options = {"REGISTER", "UNDO"}

    demo: EnumProperty(name="Scene", items=SCENES, default="sbc_fig3")
    width: IntProperty(name="Width", default=320, min=16, max=8192)
    height: IntProperty(name="Height", default=240, min=16, max=8192)

    def execute(self, context):
        scene = build(self.demo, width=self.width, height=self.height)
        if context.window is not None:
            context.window.scene = scene
        self.report({"INFO"}, f"Added demo scene {scene.name!r}")
        return {"FINISHED"}


classes = (CURVED_REFLECTIONS_OT_add_demo_scene,)
