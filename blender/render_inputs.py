# SPDX-License-Identifier: GPL-3.0-or-later
"""What the renderer reads from the scene besides the geometry: the world's colour that
reflected rays leaving the scene show, each reflector's surface properties (SBC paper,
Popescu, Sacks, Mei 2006, section V-D), and the margin of the scene box where reflected
rays end. Shared by the live view (``live.py``) and Render Image (``render_image.py``).
"""

from __future__ import annotations

import numpy as np

from .material_color import material_color

#: Scene box margin (share of its diagonal) where reflected rays end: points on the
#: scene's outer faces (a floor's edge) must lie well inside it, since a projection
#: interpolates the ray ends of four neighbouring rays, which may leave by different faces.
BOUNDS_MARGIN = 0.05


def world_color(scene) -> tuple[float, float, float, float]:
    """Linear RGBA of the world's background: the Background node's colour times its
    strength when nothing is linked into it, else the world's viewport colour."""
    world = scene.world
    if world is None:
        return (0.0, 0.0, 0.0, 1.0)
    tree = world.node_tree
    node = None if tree is None else next((n for n in tree.nodes if n.type == 'BACKGROUND'), None)
    if node is not None and not node.inputs["Color"].is_linked and not node.inputs["Strength"].is_linked:
        strength = float(node.inputs["Strength"].default_value)
        rgb = [strength * float(c) for c in node.inputs["Color"].default_value[:3]]
        return (*rgb, 1.0)
    return (*(float(c) for c in world.color[:3]), 1.0)


def reflector_properties(reflectors, scene) -> dict:
    """Surface properties of each captured reflector (SBC paper, section V-D), as the
    keyword arguments of ``ReflectionRenderer``: ``reflector_colors`` (R, 4) linear (what
    the material shows, ``material_color``), ``reflectivity`` (R,), ``fresnel_f0`` (R,)
    (NaN where ``use_fresnel`` is off) and ``attenuation_distance`` (R,) (0: no fading).

    Captured names are object names (an instance's is not an object's: it gets white,
    reflectivity 1, no Fresnel, no fading).
    """
    colors = np.ones((len(reflectors), 4), np.float32)
    reflectivity = np.ones(len(reflectors), np.float32)
    fresnel_f0 = np.full(len(reflectors), np.nan, np.float32)
    attenuation = np.zeros(len(reflectors), np.float32)
    for k, reflector in enumerate(reflectors):
        obj = scene.objects.get(reflector.name)
        if obj is None:
            continue
        settings = obj.curved_reflections
        reflectivity[k] = settings.reflectivity
        if settings.use_fresnel:
            fresnel_f0[k] = settings.fresnel_f0
        attenuation[k] = settings.attenuation_distance
        color = material_color(obj.active_material)
        colors[k] = color.rgba if color is not None else tuple(obj.color)
    return {"reflector_colors": colors, "reflectivity": reflectivity, "fresnel_f0": fresnel_f0,
            "attenuation_distance": attenuation}


def reflector_appearance(reflectors, scene) -> tuple[np.ndarray, np.ndarray]:
    """Own colour (R, 4) linear and reflectivity (R,) of each captured reflector
    (:func:`reflector_properties` has Fresnel and attenuation too)."""
    properties = reflector_properties(reflectors, scene)
    return properties["reflector_colors"], properties["reflectivity"]
