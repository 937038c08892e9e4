# SPDX-License-Identifier: GPL-3.0-or-later
"""The colour a material shows on a reflected mesh: flat, from a colour attribute, or emitted.

Reflected meshes are drawn with one colour per vertex, so a material is reduced to what
its surface shader shows at a glance: the emission colour when it glows (drawn unlit,
e.g. the demo scenes' labels), else the base colour, else the viewport display colour
(``material.diffuse_color``). A base colour that comes from a colour attribute node is
reported so the caller can read that attribute per vertex, and one that comes from an
Image Texture node names the image (sampled through the mesh's UVs, SBC paper V-C).
"""

from __future__ import annotations

from dataclasses import dataclass

import bpy


@dataclass(frozen=True)
class MaterialColor:
    """``rgba`` is linear; ``attribute`` names a colour attribute to read instead
    (``""``: the mesh's default colour attribute), ``None`` when the colour is flat.
    When the attribute is missing on a mesh, ``rgba`` is shown. ``image`` is the
    ``bpy.types.Image`` of an Image Texture node feeding the colour (``rgba`` is then the
    viewport display colour, shown where the image cannot be used), else ``None``."""

    rgba: tuple[float, float, float, float]
    emissive: bool = False
    attribute: str | None = None
    image: object = None


def material_color(material) -> MaterialColor | None:
    """What ``material`` shows; ``None`` for an empty material slot."""
    if material is None:
        return None
    display = tuple(material.diffuse_color)
    shader = surface_shader(material)
    if shader is not None:
        if shader.bl_idname == 'ShaderNodeEmission':
            if _scalar(shader.inputs["Strength"]) > 0:
                return _socket_color(shader.inputs["Color"], 1.0, display, emissive=True) or MaterialColor(display)
            return MaterialColor((0.0, 0.0, 0.0, 1.0))
        alpha = _scalar(shader.inputs["Alpha"]) if "Alpha" in shader.inputs else 1.0
        emission = shader.inputs.get("Emission Color")
        strength = shader.inputs.get("Emission Strength")
        if emission is not None and strength is not None and _scalar(strength) > 0:
            glow = _socket_color(emission, alpha, display, emissive=True)
            if glow is not None and (glow.attribute is not None or max(glow.rgba[:3]) > 0):
                return glow
        base = shader.inputs.get("Base Color") or shader.inputs.get("Color")
        if base is not None:
            color = _socket_color(base, alpha, display, emissive=False)
            if color is not None:
                return color
    return MaterialColor(display)


def surface_shader(material):
    """The shader node feeding the active material output's Surface, or ``None``."""
    # Blender 5.0 always uses nodes and deprecates ``use_nodes``; 4.x may not use them.
    if bpy.app.version < (5, 0, 0) and not material.use_nodes:
        return None
    tree = material.node_tree
    if tree is None:
        return None
    outputs = [
        node for node in tree.nodes
        if node.bl_idname == 'ShaderNodeOutputMaterial' and node.target in {'ALL', 'EEVEE'}
    ]
    if not outputs:
        return None
    output = next((node for node in outputs if node.is_active_output), outputs[0])
    return _source_node(output.inputs["Surface"])


def _source_node(socket):
    """The node linked into ``socket``, through reroutes; ``None`` if unlinked or muted."""
    while socket.is_linked:
        link = socket.links[0]
        if link.is_muted:
            return None
        node = link.from_node
        if node.bl_idname != 'NodeReroute':
            return node
        socket = node.inputs[0]
    return None


def _scalar(socket) -> float:
    return float(socket.default_value)


def _socket_color(socket, alpha: float, fallback, *, emissive: bool) -> MaterialColor | None:
    """The colour at a colour input: its value, or the attribute node linked to it.

    ``fallback`` is shown where the attribute is missing. ``None`` when something else
    (e.g. an image texture) drives the input.
    """
    if not socket.is_linked:
        r, g, b = socket.default_value[:3]
        return MaterialColor((r, g, b, alpha), emissive)
    node = _source_node(socket)
    if node is None:
        return None
    if node.bl_idname == 'ShaderNodeVertexColor':
        return MaterialColor(fallback, emissive, node.layer_name)
    if node.bl_idname == 'ShaderNodeAttribute' and node.attribute_type == 'GEOMETRY':
        return MaterialColor(fallback, emissive, node.attribute_name)
    if node.bl_idname == 'ShaderNodeTexImage' and node.image is not None:
        return MaterialColor((*fallback[:3], alpha), emissive, image=node.image)
    return None

