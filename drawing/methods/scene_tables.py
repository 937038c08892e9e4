# SPDX-License-Identifier: GPL-3.0-or-later
"""The scene's triangles on the GPU as a bounding volume hierarchy, for rays traced per pixel.

The tree of ``engine/geometry/bvh.py`` (Morton-sorted triangles under a complete binary
tree) packed into textures: two texels per node, one per triangle slot, and the
vertices' positions, colours, normals and texture coordinates. ``glsl/scene_bvh.glsl``
finds a ray's nearest triangle without a stack, and ``glsl/scene_colors.glsl`` lights
what it meets as the reflected meshes are lit, reflecting off mirrors to the scene's Max
Order as Render Image does (``engine/geometry/band_trace.py``) and refracting through
glass as it does (``engine/glass/paths.py``). The glass's trace
(``glass_trace.py``) and the mirrors' (``traced_pass.py``) meet their pixels' rays with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...engine.errors import SceneInputError
from ...engine.geometry.bvh import build_bvh
from ..draw_geometry import mesh_attributes
from ..draw_shaders import shading_source
from ..gpu_data import data_texture
from ..shader_sources import glsl_source
from . import image_atlas
from .sbc_pack import MAX_TEXTURE_HEIGHT

#: Texels a slot of the tree: its triangle's first corner and its two edges from it, what
#: the walk reads (w: the corners' vertex indices; -1 for an empty slot).
SLOT_TEXELS = 3
#: Triangles per leaf of the tree: the slab tests of a deeper tree cost more than the
#: triangle tests of a fuller leaf.
LEAF_SIZE = 4
#: A ray meets triangles from this share of the scene's diameter on (past the surface it
#: leaves, which an object may touch).
START_SHARE = 1e-7
#: Barycentric slack of the ray-triangle test: in float32 a ray through the edge two
#: triangles share can miss both (a glass box's ray escaping through its face's diagonal);
#: this keeps the mesh closed, at a millionth of a triangle's size.
EDGE_SLACK = 1e-6
#: Added to the size of a node's parent order (``glsl/scene_bvh.glsl``'s ``split``, at
#: most 3) where the node holds no triangle: one texel says both.
EMPTY_NODE = 4
#: A mesh's image index for a mirror's triangles (``glsl/scene_bvh.glsl``; -1: no image).
MIRROR_CODE = -2
#: A mesh's image index for a glass's triangles: the ray crosses them (their vertices' colours
#: hold the glass's index of refraction, whether it reflects, and its index).
GLASS_CODE = -3
#: Glass interfaces a ray crosses or reflects totally at before it is given up as trapped
#: and black (Render Image's ``engine/glass/paths.MAX_INTERFACES``).
MAX_INTERFACES = 8
#: log2 of the texels in a row of every table (``glsl/scene_bvh.glsl``'s ``table_texel``
#: finds a texel by shifts and masks; integer division costs llvmpipe more): 4096 texels,
#: so that a tree of 22 million slots (some 16 million triangles) fits the rows every
#: OpenGL 4.5 allows.
TABLE_ROW_BITS = 12
#: The samplers of the tables, in the order :meth:`SceneTables.bind` binds them.
TABLES = ("bvh_boxes", "bvh_slots", "scene_vertices", "vertex_colors", "vertex_normals", "vertex_uvs",
          "image_rects", "scene_images")


@dataclass(frozen=True)
class TracedScene:
    """What a trace shows besides the meshes' colours: the ``world`` colour (linear RGB)
    where a ray meets nothing, which meshes are ``mirrors`` (by name: a ray reflects off
    them) and how many mirror reflections a ray follows (the scene's Max Order)."""

    world: tuple = (0.0, 0.0, 0.0)
    mirrors: frozenset = frozenset()
    max_order: int = 1


def samples_every_image(meshes) -> bool:
    """Whether a trace samples every image texture of ``meshes`` (``DiffuseMesh`` each):
    they all fit its atlas (:mod:`.image_atlas`)."""
    return image_atlas.fits([mesh.image.shape[1::-1] for mesh in meshes if getattr(mesh, "image", None) is not None])


def declare(info, first_sampler: int, world: bool = True) -> None:
    """The tables' samplers (from slot ``first_sampler`` on) and push constants (12 bytes:
    ``t_min``, ``leaf_first``, ``max_order``; 16 more for ``world`` with ``world``) on a
    compute shader's create-info."""
    if world:
        info.push_constant('VEC4', "world")
    info.push_constant('FLOAT', "t_min")
    info.push_constant('INT', "leaf_first")
    info.push_constant('INT', "max_order")
    for slot, name in enumerate(TABLES, first_sampler):
        info.sampler(slot, 'FLOAT_2D', name)


def prelude(world: bool = True) -> str:
    """The GLSL a trace calls: ``nearest_hit``, ``followed_color`` and ``traced_color``, with their defines
    (without ``world``, a ray that meets nothing is black: the caller tells it by its
    distance)."""
    defines = {"LEAF_SIZE": LEAF_SIZE, "EDGE_SLACK": f"{EDGE_SLACK:.9e}", "MIRROR_CODE": f"{MIRROR_CODE:.1f}",
               "GLASS_CODE": f"{GLASS_CODE:.1f}", "EMPTY": EMPTY_NODE, "SLOT_TEXELS": SLOT_TEXELS,
               "MAX_INTERFACES": MAX_INTERFACES, "TABLE_ROW": 1 << TABLE_ROW_BITS,
               "TABLE_ROW_BITS": TABLE_ROW_BITS,
               "WORLD_COLOR": "world.rgb" if world else "vec3(0.0)"}
    return shading_source() + glsl_source("scene_bvh.glsl", defines) + glsl_source("scene_colors.glsl")


def bvh_tables(vertices: np.ndarray, triangles: np.ndarray, groups: np.ndarray | None = None) -> tuple:
    """((2 n, 4) node texels, (SLOT_TEXELS slots, 4) slot texels, first leaf's node index) of the tree
    over ``triangles`` (``glsl/scene_bvh.glsl`` says what they hold: an inner node's
    highest corner carries the axis its children are ordered on, each node's lowest
    corner its parent's, :data:`EMPTY_NODE` further from 0 where it holds no triangle,
    so that a walk climbing past it need not read its parent; a slot its triangle's first
    corner and two edges from it, in float32 as the GPU would subtract them, with the
    corners' vertex indices); ``groups`` (T,): each group (an object) a subtree of its
    own (``bvh.grouped_order``)."""
    bvh = build_bvh(vertices, triangles, leaf_size=LEAF_SIZE, groups=groups)
    leaf_first = 1 << bvh.depth
    boxes = np.zeros((4 * leaf_first, 4), np.float32)
    orders = np.ones(1, np.float32)  # the root's: it has no parent
    for level, rows in enumerate(bvh.box_rows):  # one slice per level, not per node
        nodes = (1 << level) + np.arange(1 << level)
        empty = np.isnan(rows[0])
        boxes[2 * nodes, :3] = np.nan_to_num(rows[:3].T)
        boxes[2 * nodes, 3] = orders + np.sign(orders) * EMPTY_NODE * empty
        boxes[2 * nodes + 1, :3] = np.nan_to_num(rows[3:].T)
        if level < bvh.depth:  # the axis its children's boxes differ most on, signed by which is lower
            below = bvh.box_rows[level + 1]
            centres = np.nan_to_num(0.5 * (below[:3] + below[3:]).T).reshape(-1, 2, 3)
            apart = centres[:, 1] - centres[:, 0]
            axis = np.argmax(np.abs(apart), axis=1)
            boxes[2 * nodes + 1, 3] = np.where(apart[np.arange(len(axis)), axis] >= 0.0, 1.0, -1.0) * (axis + 1)
            orders = np.repeat(boxes[2 * nodes + 1, 3], 2)
    slots = np.full((len(bvh.order), SLOT_TEXELS, 4), -1.0, np.float32)
    filled = bvh.order >= 0
    held = triangles[bvh.order[filled]]
    corners = np.asarray(vertices, np.float32)[held]
    slots[filled, 0, :3] = corners[:, 0]
    slots[filled, 1:, :3] = corners[:, 1:] - corners[:, :1]
    slots[filled, :, 3] = held
    return boxes, slots.reshape(-1, 4), leaf_first


def _surface_part(surface, code: float, colour: tuple) -> tuple:
    """A mirror's or glass's part of the tables: its vertices and triangles, ``code``, one
    ``colour`` for every vertex, its smooth normals (lit) and no texture coordinates."""
    count = len(surface.vertices)
    return (surface.vertices, surface.triangles, code, np.tile(colour, (count, 1)),
            np.c_[surface.normals, np.ones(count)], np.zeros((count, 2)))


class SceneTables:
    """One renderer's scene on the GPU for traces: its diffuse ``meshes`` as given
    (``engine.scene.DiffuseMesh`` each: a trace needs no subdivision, and a wall of two
    triangles keeps its tree shallow; those named in ``scene.mirrors`` are mirrors),
    ``surfaces``, mirrors (``engine.Reflector`` each) not among them, and ``glasses``
    (``engine.glass.Glass`` each, the k-th glass index k: rays refract through them; a
    mesh of a glass's name, the solid object other renderers draw of it, is left out);
    positions relative to the renderer's ``geometry`` (``draw_geometry.DrawGeometry``:
    its shift, size and images). Uploaded on first :meth:`bind`."""

    def __init__(self, meshes, geometry, scene: TracedScene = TracedScene(), surfaces=(), glasses=()):
        self.meshes = tuple(meshes)
        self.geometry = geometry
        self.scene = scene
        self.surfaces = tuple(surfaces)
        self.glasses = tuple(glasses)
        self.world = tuple(float(c) for c in scene.world)[:3] + (1.0,)
        self._textures = None

    def _arrays(self) -> tuple:
        """(vertices relative to the shift, triangles, codes, colours, normals and lit, uvs,
        each triangle's part) of the meshes, the surfaces, then the glass; a mesh's code is
        its image's index in the geometry's images (meshes with an image, in order), -1, or
        :data:`MIRROR_CODE`; a glass vertex's colour is (index of refraction, 1 where it
        reflects, its index, 0)."""
        shift = self.geometry.shift
        glass_names = {glass.name for glass in self.glasses}
        parts, count, image = [], 0, 0
        for mesh in self.meshes:
            code = MIRROR_CODE if mesh.name in self.scene.mirrors else (-1 if mesh.image is None else image)
            image += mesh.image is not None  # the geometry's images count a glass's solid mesh too
            if mesh.name in glass_names:
                continue
            normals, uvs, lit = mesh_attributes(mesh)
            parts.append((mesh.vertices, mesh.triangles, code, mesh.colors, np.c_[normals, lit], uvs))
        parts += [_surface_part(surface, MIRROR_CODE, (0.5, 0.5, 0.5, 0.5)) for surface in self.surfaces]
        parts += [_surface_part(glass.surface, GLASS_CODE,
                                (float(glass.ior), float(glass.reflects), float(index), 0.0))
                  for index, glass in enumerate(self.glasses)]
        vertices, triangles, codes, colors, normals, uvs, groups = [], [], [], [], [], [], []
        for points, faces, code, colour, normal, uv in parts:
            vertices.append(np.asarray(points, np.float64) - shift)
            triangles.append(np.asarray(faces, np.int64).reshape(-1, 3) + count)
            codes.append(np.full(len(faces), code))
            groups.append(np.full(len(faces), len(groups)))
            colors.append(colour)
            normals.append(normal)
            uvs.append(uv)
            count += len(points)
        if not parts:
            return (np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0), np.zeros((0, 4)), np.zeros((0, 4)),
                    np.zeros((0, 2)), np.zeros(0, np.int64))
        return tuple(np.concatenate(arrays) for arrays in (vertices, triangles, codes, colors, normals, uvs, groups))

    def _ensure(self) -> None:
        if self._textures is not None:
            return
        vertices, triangles, codes, colors, normals, uvs, groups = self._arrays()
        boxes, slots, leaf_first = bvh_tables(vertices, triangles, groups)
        if len(slots) > MAX_TEXTURE_HEIGHT << TABLE_ROW_BITS:
            parts = [(part.name, len(part.triangles)) for part in self.meshes + self.surfaces]
            parts += [(glass.name, len(glass.surface.triangles)) for glass in self.glasses]
            largest = max(parts, key=lambda part: part[1])[0]
            raise SceneInputError(largest, f"the scene's {len(triangles):,} triangles need a tree of "
                                  f"{len(slots) // SLOT_TEXELS:,} slots, more than the GPU's ray trace holds "
                                  f"({(MAX_TEXTURE_HEIGHT << TABLE_ROW_BITS) // SLOT_TEXELS:,}); lower this mesh's "
                                  "resolution (e.g. its subdivision levels), or hide objects the mirrors and glass "
                                  "need not show")
        vertex_codes = np.zeros(len(vertices))
        vertex_codes[triangles] = codes[:, None]  # a vertex is one mesh's: its code
        atlas, rects = image_atlas.image_atlas(self.geometry.images)
        self._textures = ([data_texture(table, 1 << TABLE_ROW_BITS)
                           for table in (boxes, slots, vertices, colors, normals, np.c_[uvs, vertex_codes], rects)]
                          + [data_texture(atlas)], leaf_first)

    def bind(self, shader, bounces: int | None = None, world: bool = True, start_share: float = START_SHARE) -> None:
        """The tables (the images' atlas among them) and the push constants of
        :func:`declare` (``world`` as there) on a bound ``shader``; a ray reflects off
        mirrors ``bounces`` times at most (default: the scene's Max Order) and meets
        triangles from ``start_share`` of the scene's diameter on."""
        self._ensure()
        textures, leaf_first = self._textures
        for name, texture in zip(TABLES, textures):
            shader.uniform_sampler(name, texture)
        if world:
            shader.uniform_float("world", self.world)
        shader.uniform_float("t_min", start_share * self.geometry.diameter)
        shader.uniform_int("leaf_first", leaf_first)
        shader.uniform_int("max_order", int(self.scene.max_order if bounces is None else bounces))
