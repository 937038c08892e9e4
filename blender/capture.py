# SPDX-License-Identifier: GPL-3.0-or-later
"""Capture: the evaluated Blender scene and view as the engine's world-space arrays.

Geometry comes from the evaluated depsgraph, so modifiers, constraints, animation and
instancing are applied exactly as the viewport shows them. Each object is triangulated
(``loop_triangles``) and moved to world space. A reflector keeps Blender's corner
normals (sharp edges, flat faces, custom split normals): corners that share a vertex
but not a normal become separate vertices, as the engine's mirror surface needs. A
diffuse mesh is split the same way where its per-corner colour changes.

Everything is read with ``foreach_get`` into numpy; no Python loop runs per vertex.
Bad input raises :class:`SceneInputError` naming the object.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from mathutils import Matrix

from ..engine.errors import SceneInputError
from ..engine.glass import Glass
from ..engine.srgb import srgb_to_linear
from ..engine.scene import DiffuseMesh, Reflector, vertex_normals
from ..engine.view import View
from .material_color import MaterialColor, material_color
from .material_ior import glass_ior, glass_reflects

#: Object types with a surface that Blender converts to a mesh.
SURFACE_TYPES = frozenset({'MESH', 'CURVE', 'SURFACE', 'FONT', 'META'})

#: A world matrix whose smallest singular value is below this share of its largest
#: squashes the object flat; its normals (inverse-transpose) are undefined.
MIN_SCALE_RATIO = 1e-9


@dataclass(frozen=True)
class CapturedScene:
    """The reflectors and the diffuse (reflected) meshes of one evaluated scene."""

    reflectors: tuple[Reflector, ...]
    meshes: tuple[DiffuseMesh, ...]
    #: The glass objects (``engine.glass.Glass``); each is among ``meshes`` too, as the
    #: solid object the mirrors reflect.
    glass: tuple = ()

    @property
    def reflector_triangles(self) -> int:
        return sum(len(r.triangles) for r in self.reflectors)

    @property
    def mesh_triangles(self) -> int:
        return sum(len(m.triangles) for m in self.meshes)


def capture_scene(depsgraph, *, require_reflector: bool = True, reflectors_as_before=None) -> CapturedScene:
    """Reflectors (objects marked ``is_reflector``), glass (``is_refractor``, with its
    index of refraction, ``material_ior.glass_ior``) and every other visible surface.

    Only what the depsgraph shows is captured: hidden objects are not in it. With
    ``require_reflector``, a scene without a visible reflector or glass is an error.
    ``reflectors_as_before``: an earlier capture's reflectors, known unchanged (only
    diffuse objects were edited): each one not instanced is taken from there by name
    instead of read again (a million-triangle mirror took a second to read).
    """
    before = {r.name: r for r in reflectors_as_before or ()}
    reflectors, meshes, glass = [], [], []
    names = _UniqueNames()
    for instance in depsgraph.object_instances:
        if not instance.show_self or _own_geometry(instance):
            continue
        obj = instance.object
        # Settings are read from the original: setting a property from Python does not
        # tag the depsgraph, so the evaluated copy can hold a stale value.
        is_reflector = obj.original.curved_reflections.is_reflector
        is_refractor = obj.original.curved_reflections.is_refractor
        name = names.claim(_instance_name(instance))
        if is_reflector and is_refractor:
            raise SceneInputError(name, "is marked both as a reflector and as glass; untick one of them")
        if obj.type not in SURFACE_TYPES:
            if is_reflector or is_refractor:
                raise SceneInputError(
                    name, f"is marked as {'a reflector' if is_reflector else 'glass'} but is "
                    f"{_a(obj.type.lower())} object, which has no surface"
                )
            continue
        if is_reflector and name in before and not instance.is_instance:
            # An instance moves with its instancer, which is no reflector: read again.
            reflectors.append(before[name])
            continue
        matrix = np.array(instance.matrix_world, dtype=np.float64)
        with _triangulated(obj) as mesh:
            if is_reflector:
                reflectors.append(_reflector(name, mesh, matrix))
                continue
            if is_refractor:
                glass.append(Glass(_reflector(name, mesh, matrix), glass_ior(obj.original),
                                   glass_reflects(obj.original)))
            if (diffuse := _diffuse_mesh(name, obj, mesh, matrix)) is not None:
                meshes.append(diffuse)
    if require_reflector and not reflectors and not glass:
        raise SceneInputError(
            depsgraph.scene.name, "has no visible object marked as a reflector or as glass "
            "(tick Reflector or Glass in the sidebar's Reflections tab)"
        )
    return CapturedScene(tuple(reflectors), tuple(meshes), tuple(glass))


def view_from_camera(camera_object, scene, depsgraph) -> View:
    """The view a render of ``scene`` through ``camera_object`` shows.

    Image size is the render resolution times its percentage; the projection includes
    lens, sensor fit, shift and pixel aspect (``Object.calc_matrix_camera``). Camera
    scale is ignored, as in a render.
    """
    if camera_object is None:
        raise SceneInputError(scene.name, "has no camera")
    if camera_object.type != 'CAMERA':
        raise SceneInputError(
            camera_object.name, f"is not a camera (it is {_a(camera_object.type.lower())} object)"
        )
    camera = camera_object.evaluated_get(depsgraph)
    if camera.data.type == 'PANO':
        raise SceneInputError(
            camera_object.name, "is a panoramic camera; only perspective and "
            "orthographic cameras are supported"
        )
    render = scene.render
    width = max(1, render.resolution_x * render.resolution_percentage // 100)
    height = max(1, render.resolution_y * render.resolution_percentage // 100)
    projection = camera.calc_matrix_camera(
        depsgraph, x=width, y=height, scale_x=render.pixel_aspect_x, scale_y=render.pixel_aspect_y
    )
    location, rotation, _scale = camera.matrix_world.decompose()
    view = Matrix.LocRotScale(location, rotation, None).inverted()
    return View(np.array(view), np.array(projection), width, height, name=camera_object.name)


def view_from_region(region, rv3d) -> View:
    """The view of a 3D viewport region (``context.region``, ``context.region_data``)."""
    return View(
        np.array(rv3d.view_matrix), np.array(rv3d.window_matrix),
        region.width, region.height, name="viewport",
    )


class _UniqueNames:
    """Names for error messages and the engine: instances of one object get ``#2``, ``#3``..."""

    def __init__(self):
        self._seen = {}

    def claim(self, name: str) -> str:
        count = self._seen.get(name, 0) + 1
        self._seen[name] = count
        return name if count == 1 else f"{name} #{count}"


def _a(word: str) -> str:
    """``word`` with its indefinite article ("an empty", "a light")."""
    return f"{'an' if word[:1] in 'aeiou' else 'a'} {word}"


#: ``DepsgraphObjectInstance.persistent_id`` entry of a geometry that is no instance of
#: an instance list (Blender's INT_MAX): an object's own geometry, listed again.
NO_INSTANCE_INDEX = 2**31 - 1


def _own_geometry(instance) -> bool:
    """Whether ``instance`` is an object's own evaluated geometry listed as an instance of
    itself: Blender lists a curve, text, surface or metaball object once as itself and
    once so. The object itself is captured; capturing both drew it twice, and a metaball
    mirror's copy blocked its own reflected rays. Geometry Nodes instances of geometry
    (Instance on Points of a mesh, not of an object) are listed as instances of their
    object too, but each with its index in the instance list: they are captured."""
    return (instance.is_instance and instance.parent is not None
            and instance.object.original == instance.parent.original
            and instance.persistent_id[1] == NO_INSTANCE_INDEX)


def _instance_name(instance) -> str:
    if instance.is_instance and instance.parent is not None:
        obj = instance.object
        # A Geometry Nodes instance of geometry is listed under its instancer's name: its mesh names it.
        name = obj.data.name if obj.original == instance.parent.original and obj.data is not None else obj.name
        return f"{name} (instanced by {instance.parent.name})"
    return instance.object.name


@contextmanager
def _triangulated(obj):
    """The evaluated object's mesh with loop triangles; freed on exit."""
    mesh = obj.to_mesh()
    try:
        if mesh is not None:
            mesh.calc_loop_triangles()
        yield mesh
    finally:
        obj.to_mesh_clear()


def _read(collection, attribute: str, width: int, dtype) -> np.ndarray:
    """``foreach_get`` of one attribute into an (N, width) array, or (N,) for width 1."""
    out = np.empty(len(collection) * width, dtype=dtype)
    collection.foreach_get(attribute, out)
    return out.reshape(-1, width) if width > 1 else out


def _corners(mesh) -> tuple[np.ndarray, np.ndarray]:
    """Loop index and vertex index of every triangle corner, both (3T,)."""
    loops = _read(mesh.loop_triangles, "loops", 3, np.int32).ravel()
    loop_vertex = _read(mesh.loops, "vertex_index", 1, np.int32)
    return loops, loop_vertex[loops]


#: Corners whose values :func:`_weld` compares at a time.
WELD_BLOCK = 1 << 16


def _value_bits(values: np.ndarray) -> np.ndarray:
    """The int32 bit patterns of float32 values, (n, k), -0.0 as 0.0."""
    as_float = np.ascontiguousarray(values, dtype=np.float32) + np.float32(0)  # -0.0 -> 0.0
    return as_float.view(np.int32).reshape(len(as_float), -1)


def _weld(corner_vertex: np.ndarray, *corner_values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge corners that share a vertex and bit-identical values.

    Returns the first (lowest) corner of each output vertex and each corner's output
    vertex (flat), output vertices numbered by vertex, then by values (their bit
    patterns). Where every corner of a vertex has its first corner's values (a smooth
    mesh) the vertex is one output vertex, found a block of corners at a time; only
    the vertices split by a sharp edge or a seam are sorted by their values: a
    million-triangle mirror's weld held 240 MB of sort keys and orders."""
    corner_vertex = np.asarray(corner_vertex)
    n_corners = len(corner_vertex)
    n_vertices = int(corner_vertex.max()) + 1 if n_corners else 0
    first_of_vertex = np.full(n_vertices, n_corners, dtype=np.int64)
    np.minimum.at(first_of_vertex, corner_vertex, np.arange(n_corners))
    differs = np.zeros(n_corners, dtype=bool)
    for start in range(0, n_corners, WELD_BLOCK):
        rows = slice(start, start + WELD_BLOCK)
        reference = first_of_vertex[corner_vertex[rows]]
        for values in corner_values:
            differs[rows] |= (_value_bits(values[rows]) != _value_bits(values[reference])).any(axis=1)
    used = np.zeros(n_vertices, dtype=bool)
    used[corner_vertex] = True
    if not differs.any():
        return first_of_vertex[used], (np.cumsum(used) - 1)[corner_vertex]
    split = np.zeros(n_vertices, dtype=bool)
    split[corner_vertex[differs]] = True
    del differs
    sub = np.flatnonzero(split[corner_vertex])  # the split vertices' corners, in order
    sub_first, sub_inverse = _weld_sorted(corner_vertex[sub], *(values[sub] for values in corner_values))
    group_vertex = corner_vertex[sub[sub_first]]  # ascending: groups sort by vertex first
    groups = np.where(split, np.bincount(group_vertex, minlength=n_vertices), used)
    offset = np.cumsum(groups) - groups  # each vertex's first output vertex
    rank = np.arange(len(group_vertex)) - np.searchsorted(group_vertex, group_vertex)  # within its vertex
    first = np.empty(int(groups.sum()), dtype=np.int64)
    plain = used & ~split
    first[offset[plain]] = first_of_vertex[plain]
    first[offset[group_vertex] + rank] = sub[sub_first]
    inverse = offset[corner_vertex]
    inverse[sub] += rank[sub_inverse]
    return first, inverse


def _weld_sorted(corner_vertex: np.ndarray, *corner_values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_weld` by sorting every corner by vertex and values: (first corner of each
    output vertex, each corner's output vertex)."""
    columns = [corner_vertex.astype(np.int32)[:, None]] + [_value_bits(values) for values in corner_values]
    key = np.concatenate(columns, axis=1)
    # np.unique(key, axis=0) gives the same, but sorts rows as opaque records: 3x slower.
    order = np.lexsort(key.T[::-1])  # by vertex, then by values
    ordered = key[order]
    starts = np.ones(len(key), dtype=bool)
    starts[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    inverse = np.empty(len(key), dtype=np.int64)
    inverse[order] = np.cumsum(starts) - 1
    return order[starts], inverse


def _to_world(mesh, corner_vertex: np.ndarray, first: np.ndarray, matrix: np.ndarray):
    positions = _read(mesh.vertices, "co", 3, np.float32).astype(np.float64)
    return positions[corner_vertex[first]] @ matrix[:3, :3].T + matrix[:3, 3]


def _finite_transform(name: str, matrix: np.ndarray) -> np.ndarray:
    """The linear part of an object's world matrix; a SceneInputError naming the object
    where any of it is not a number (a NaN or infinite scale, rotation or location)."""
    if not np.isfinite(matrix).all():
        raise SceneInputError(name, "has a location, rotation or scale that is not a number (NaN or infinite); "
                                    "fix its transform")
    return matrix[:3, :3]


def _squashed(linear: np.ndarray) -> bool:
    """Whether a (finite) linear transform has zero scale along some axis."""
    singular = np.linalg.svd(linear, compute_uv=False)
    return bool(singular[-1] <= singular[0] * MIN_SCALE_RATIO)


def _reflector(name: str, mesh, matrix: np.ndarray) -> Reflector:
    if mesh is None or len(mesh.loop_triangles) == 0:
        raise SceneInputError(
            name, "has no faces once its modifiers are applied (a mirror needs at least one triangle)"
        )
    linear = _finite_transform(name, matrix)
    if _squashed(linear):
        raise SceneInputError(
            name, "has zero scale along an axis, so its mirror normals are undefined "
            "(fix the object's scale)"
        )
    loops = _read(mesh.loop_triangles, "loops", 3, np.int32).ravel()
    loop_vertex = _read(mesh.loops, "vertex_index", 1, np.int32)
    loop_normals = _read(mesh.corner_normals, "vector", 3, np.float32)
    if np.bincount(loops, minlength=len(loop_vertex)).all():
        # Every face corner (loop) is some triangle's corner (as triangulations make
        # them): weld the loops, not their copies per triangle corner (a third fewer,
        # and no (3T, 3) gather of the normals). The same vertices, in the same order.
        first, loop_welded = _weld(loop_vertex, loop_normals)
        triangles = loop_welded[loops].reshape(-1, 3)
        del loop_welded
    else:
        loop_normals, loop_vertex = loop_normals[loops], loop_vertex[loops]
        first, triangles = _weld(loop_vertex, loop_normals)
        triangles = triangles.reshape(-1, 3)
    vertices = _to_world(mesh, loop_vertex, first, matrix)
    # Normals transform by the inverse-transpose: n' = M^-T n, i.e. rows times M^-1.
    normals = loop_normals[first].astype(np.float64) @ np.linalg.inv(linear)
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)
    if np.linalg.det(linear) < 0:
        triangles = triangles[:, ::-1]  # a mirroring transform flips the winding
    return Reflector(name, vertices, np.ascontiguousarray(triangles), normals)


def _diffuse_mesh(name: str, obj, mesh, matrix: np.ndarray) -> DiffuseMesh | None:
    """The object as a reflected mesh, or ``None`` when it has no faces (nothing to show).

    Besides the colours: Blender's corner normals (shading, SBC paper V-C) and, when a
    material's colour comes from an image texture, the active UV map and that image."""
    if mesh is None or len(mesh.loop_triangles) == 0:
        return None
    loops, corner_vertex = _corners(mesh)
    triangle_material = _read(mesh.loop_triangles, "material_index", 1, np.int32)
    colors, emissive, image = _corner_colors(obj, mesh, loops, corner_vertex, triangle_material)
    normals = _read(mesh.corner_normals, "vector", 3, np.float32)[loops]
    values = [colors, normals]
    uvs = None
    if image is not None and mesh.uv_layers.active is not None:
        uvs = _read(mesh.uv_layers.active.uv, "vector", 2, np.float32)[loops]
        values.append(uvs)
    else:
        image = None
    first, triangles = _weld(corner_vertex, *values)
    triangles = triangles.reshape(-1, 3)
    linear = _finite_transform(name, matrix)
    vertices = _to_world(mesh, corner_vertex, first, matrix)
    if _squashed(linear):
        # Squashed flat (zero scale along an axis): still seen, as a flat shape whose
        # transformed normals are undefined; it is shaded with its faces' own normals.
        world_normals = vertex_normals(vertices, triangles)
    else:
        world_normals = normals[first].astype(np.float64) @ np.linalg.inv(linear)
    lengths = np.linalg.norm(world_normals, axis=1, keepdims=True)
    world_normals = np.divide(world_normals, lengths, out=np.zeros_like(world_normals), where=lengths > 0)
    if np.linalg.det(linear) < 0:
        triangles = triangles[:, ::-1]
    return DiffuseMesh(name, vertices, np.ascontiguousarray(triangles), colors[first], emissive=emissive,
                       uvs=None if uvs is None else uvs[first].astype(np.float64), normals=world_normals,
                       image=None if image is None else _image_pixels(image))


def _image_pixels(image) -> np.ndarray:
    """(H, W, 4) float32 linear RGBA of a ``bpy.types.Image``, rows bottom to top.

    Byte images store display values in their colour space; an sRGB one is linearised."""
    width, height = image.size
    if width == 0 or height == 0:
        raise SceneInputError(image.name, "is an image texture without pixels (missing file?)")
    pixels = np.empty(width * height * int(image.channels), dtype=np.float32)
    image.pixels.foreach_get(pixels)
    pixels = pixels.reshape(height, width, int(image.channels))
    rgba = np.ones((height, width, 4), np.float32)
    rgba[..., :min(4, pixels.shape[2])] = pixels[..., :4]
    if pixels.shape[2] < 3:
        rgba[..., 1:3] = rgba[..., :1]
    if not image.is_float and image.colorspace_settings.name == 'sRGB':
        rgba[..., :3] = srgb_to_linear(rgba[..., :3])
    return rgba


def _corner_colors(obj, mesh, loops, corner_vertex, triangle_material):
    """Linear RGBA per triangle corner (3T, 4), whether every triangle glows, and the image
    texture of the mesh (or ``None``).

    Per material slot: its emission or base colour, or a colour attribute it reads.
    An empty slot (or no material at all) shows the mesh's colour attribute if it has
    one, else the object colour. A mesh carries one image: it is used when every
    triangle's slot reads that same image (else the slots show their flat colours).
    """
    slots = [material_color(slot.material) for slot in obj.material_slots] or [None]
    # Blender draws an out-of-range material index with the last slot.
    slot_of_triangle = np.clip(triangle_material, 0, len(slots) - 1)
    n_triangles = len(triangle_material)
    colors = np.empty((n_triangles, 3, 4), dtype=np.float32)
    emissive = np.zeros(n_triangles, dtype=bool)
    attribute_values = {}
    images = set()
    for index, color in enumerate(slots):
        chosen = slot_of_triangle == index
        if not chosen.any():
            continue
        if color is None:
            color = MaterialColor(tuple(obj.color), attribute="")
        values = None
        if color.attribute is not None:
            if color.attribute not in attribute_values:
                attribute_values[color.attribute] = _attribute_colors(mesh, color.attribute, loops, corner_vertex)
            values = attribute_values[color.attribute]
        if values is None:
            colors[chosen] = color.rgba
        else:
            colors[chosen] = values.reshape(n_triangles, 3, 4)[chosen]
        emissive[chosen] = color.emissive
        images.add(color.image)
    image = images.pop() if len(images) == 1 else None
    if image is not None:  # the image's texels are the colour: vertex colours white
        colors[..., :3] = 1.0
    return colors.reshape(-1, 4), bool(emissive.all()), image


def _attribute_colors(mesh, name: str, loops, corner_vertex) -> np.ndarray | None:
    """Linear RGBA of a colour attribute per triangle corner (3T, 4), or ``None``.

    ``name`` ``""`` picks the mesh's default (render) colour attribute.
    """
    attributes = mesh.color_attributes
    if name:
        attribute = attributes.get(name)
    elif 0 <= attributes.render_color_index < len(attributes):
        attribute = attributes[attributes.render_color_index]
    else:
        attribute = None
    if attribute is None or attribute.domain not in {'POINT', 'CORNER'}:
        return None
    values = _read(attribute.data, "color", 4, np.float32)
    return values[corner_vertex] if attribute.domain == 'POINT' else values[loops]
