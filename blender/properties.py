# SPDX-License-Identifier: GPL-3.0-or-later
"""Settings stored in the .blend: per object and per scene PropertyGroups."""

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty, IntVectorProperty,
                       PointerProperty, StringProperty)

from . import method_registry, scene_changes


#: The option that declares a path property's "//" (the .blend file's folder) supported;
#: Blender 4.5 and newer warn about path properties without it (older ones lack it).
BLEND_RELATIVE = {'PATH_SUPPORTS_BLEND_RELATIVE'} if bpy.app.version >= (4, 5, 0) else set()


def _reflector_toggled(self, context):
    scene_changes.notify(context, reflectors=True)


def _appearance_changed(self, context):
    scene_changes.notify(context, meshes=True)


class CurvedReflectionsObjectSettings(bpy.types.PropertyGroup):
    """Per-object settings, as ``obj.curved_reflections``."""

    is_reflector: BoolProperty(
        name="Reflector",
        description="Treat this object as a curved mirror: nearby objects are reflected in it",
        default=False,
        update=_reflector_toggled,
    )
    is_refractor: BoolProperty(
        name="Glass",
        description="Treat this object as glass: objects behind it are drawn refracted through it, and what it "
                    "reflects mixed in by Fresnel (the viewport and Render Image)",
        default=False,
        update=_reflector_toggled,
    )
    ior: FloatProperty(
        name="IOR",
        description="Index of refraction of the glass (0: from its material: a Glass BSDF's IOR, or a Principled "
                    "BSDF's when its Transmission Weight is at least 0.5; else 1.5)",
        default=0.0, min=0.0, soft_max=3.0, precision=3,
        update=_reflector_toggled,
    )
    reflectivity: FloatProperty(
        name="Reflectivity",
        description="Share of the reflected image in the mirror's colour (1 = perfect mirror)",
        default=1.0, min=0.0, max=1.0, subtype='FACTOR',
        update=_appearance_changed,
    )
    use_fresnel: BoolProperty(
        name="Fresnel",
        description="Reflect more at grazing angles (Schlick's approximation, SBC paper V-D)",
        default=False,
        update=_appearance_changed,
    )
    fresnel_f0: FloatProperty(
        name="Facing Reflectance",
        description="Share reflected when looking straight at the surface; rises to 1 at grazing angles",
        default=0.04, min=0.0, max=1.0, subtype='FACTOR',
        update=_appearance_changed,
    )
    attenuation_distance: FloatProperty(
        name="Fade Distance",
        description="Reflected objects fade out over this distance from the mirror (0: no fading)",
        default=0.0, min=0.0, soft_max=100.0, subtype='DISTANCE',
        update=_appearance_changed,
    )
    mode: EnumProperty(
        name="Mode",
        description="How this reflector's reflections are computed",
        # The registered methods (method_registry.py); their numbers keep saved files' modes.
        items=method_registry.enum_items,
        default=0,  # Auto
        update=_reflector_toggled,
    )
    analytic_shape: EnumProperty(
        name="Exact Surface",
        description="Declare the reflector an exact surface: Perturbation mode then reflects off it, not off its "
                    "mesh, which is only drawn (the panel reports how far the mesh is from it)",
        items=(
            ('NONE', "Mesh", "Reflect off the mesh (its interpolated normals)"),
            ('SPHERE', "Sphere", "A sphere of radius Radii X around the object's origin, in its local axes"),
            ('ELLIPSOID', "Ellipsoid", "An ellipsoid with the radii along the object's local axes"),
            ('SUPERQUADRIC', "Superquadric", "|x/a|^p + |y/b|^p + |z/c|^p = 1 with the radii a, b, c along the "
                                             "object's local axes and the exponent p: a rounded box"),
        ),
        default='NONE',
        update=_reflector_toggled,
    )
    analytic_exponent: FloatProperty(
        name="Exponent",
        description="The superquadric's exponent p: 2 is an ellipsoid, 4 a rounded box, larger a boxier one",
        default=4.0, min=2.0, max=64.0,
        update=_reflector_toggled,
    )
    analytic_radii: FloatVectorProperty(
        name="Radii",
        description="Radii of the exact surface along the object's local X, Y and Z (scaled by the object)",
        size=3, default=(1.0, 1.0, 1.0), min=1e-6, soft_max=100.0, subtype='XYZ',
        update=_reflector_toggled,
    )


class CurvedReflectionsSceneSettings(bpy.types.PropertyGroup):
    """Per-scene method settings, as ``scene.curved_reflections``."""

    downsample: IntProperty(
        name="Down-sampling",
        description="Ray map resolution divisor: one traced ray per d x d pixels",
        default=2, min=1, max=16,
    )
    accuracy_px: FloatProperty(
        name="Accuracy (px)",
        description="Largest projection error allowed, in pixels of the view",
        default=1.0, min=0.05, max=16.0,
    )
    max_order: IntProperty(
        name="Max Order",
        description="Highest number of mirror bounces drawn (2: reflections of reflections, "
                    "and a curved mirror's reflections of itself)",
        default=2, min=1, max=4,
    )
    auto_refresh: BoolProperty(
        name="Auto Refresh",
        description="Rebuild reflections when the view or the scene changes",
        default=True,
    )
    morph_grid: IntVectorProperty(
        name="Morph Grid",
        description="Nodes of the morphing grid around each morphing reflector along X, Y and Z",
        size=3, default=(9, 9, 5), min=2, max=64,
    )
    morph_margin: FloatProperty(
        name="Morph Margin",
        description="How far the morphing grid reaches beyond the reflector, in reflector sizes",
        default=1.0, min=0.05, soft_max=10.0,
    )
    morph_polish_nodes: BoolProperty(
        name="Polish Node Images",
        description="Place each morphing node's images exactly on the mirror (on the GPU, once per node): "
                    "reflections land within a fraction of a pixel of the exact ones instead of a pixel or more. "
                    "Off: the nodes' images as their cameras give them",
        default=True,
        update=_reflector_toggled,  # the grids are loaded again, with or without the mirror to polish on
    )
    morph_polish_frames: BoolProperty(
        name="Polish Every Frame",
        description="Move each frame's blended reflections onto the mirror's exact reflection points (on the "
                    "GPU; on a CPU-emulated GPU it adds about a third to the morphing pass): exact on mirrors of any "
                    "shape, where a blend alone errs by many pixels on mirrors whose curvature changes quickly. "
                    "Needs Polish Node Images",
        default=True,
        update=_reflector_toggled,  # a new renderer, polishing or not
    )
    morph_cache_dir: StringProperty(
        name="Cache Folder",
        description="Folder for baked morphing grids (empty: the extension's user folder). Set a folder every "
                    "machine of a render farm can write to, to bake ranges of nodes in parallel into one cache",
        default="", subtype='DIR_PATH', options=BLEND_RELATIVE,
    )
    morph_gpu_budget_mb: FloatProperty(
        name="Node Memory (MB)",
        description="GPU memory for the morphing nodes' images of the scene's vertices; the least "
                    "recently used nodes are dropped beyond it and projected again when needed",
        default=256.0, min=8.0, soft_max=4096.0,
    )


classes = (
    CurvedReflectionsObjectSettings,
    CurvedReflectionsSceneSettings,
)


def register_pointers():
    bpy.types.Object.curved_reflections = PointerProperty(type=CurvedReflectionsObjectSettings)
    bpy.types.Scene.curved_reflections = PointerProperty(type=CurvedReflectionsSceneSettings)


def unregister_pointers():
    del bpy.types.Scene.curved_reflections
    del bpy.types.Object.curved_reflections
