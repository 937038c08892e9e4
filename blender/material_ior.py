# SPDX-License-Identifier: GPL-3.0-or-later
"""The index of refraction of a glass object: its own setting, else its material's.

A glass object (``obj.curved_reflections.is_refractor``) bends rays by its index of
refraction (``engine/glass``). The panel's *IOR* overrides; at 0 it comes from the
material Cycles renders: a Glass or Refraction BSDF's IOR, or a Principled BSDF's when
its Transmission Weight is at least :data:`MIN_TRANSMISSION` (it is then mostly glass);
else window glass's :data:`DEFAULT_IOR`.
"""

from __future__ import annotations

from .material_color import surface_shader

#: Window glass; what a glass object whose material says nothing refracts with.
DEFAULT_IOR = 1.5
#: A Principled BSDF counts as glass from this Transmission Weight.
MIN_TRANSMISSION = 0.5
#: Shader nodes whose IOR input is the glass's.
REFRACTING_SHADERS = frozenset({'ShaderNodeBsdfGlass', 'ShaderNodeBsdfRefraction'})


def glass_reflects(obj) -> bool:
    """Whether a glass object's surface reflects as well as refracts: not when its first
    glass material is a Refraction BSDF (Cycles' refraction without reflection)."""
    shader = _first_glass_shader(obj)
    return shader is None or shader.bl_idname != 'ShaderNodeBsdfRefraction'


def glass_ior(obj) -> float:
    """The IOR a glass object refracts with: its own *IOR* when above 0, else its first
    glass material's, else :data:`DEFAULT_IOR`."""
    own = float(obj.curved_reflections.ior)
    if own > 0.0:
        return own
    shader = _first_glass_shader(obj)
    return DEFAULT_IOR if shader is None else float(shader.inputs["IOR"].default_value)


def _glass_shader(material):
    """``material``'s surface shader when it is glass (a refracting BSDF, or a Principled
    BSDF transmitting at least :data:`MIN_TRANSMISSION`), else ``None``."""
    shader = None if material is None else surface_shader(material)
    if shader is None:
        return None
    if shader.bl_idname in REFRACTING_SHADERS:
        return shader
    if (shader.bl_idname == 'ShaderNodeBsdfPrincipled'
            and float(shader.inputs["Transmission Weight"].default_value) >= MIN_TRANSMISSION):
        return shader
    return None


def _first_glass_shader(obj):
    """The glass shader of the object's first glass material, or ``None``."""
    return next((shader for shader in map(_glass_shader, (slot.material for slot in obj.material_slots))
                 if shader is not None), None)
