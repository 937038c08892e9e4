# SPDX-License-Identifier: GPL-3.0-or-later
"""What the renderer draws, as numpy arrays: the pre-pass's meshes (every diffuse mesh
and reflector, with their colours, labels, normals and image textures) and the
reflected meshes (the diffuse meshes pre-subdivided where a reflection curves them,
SBC paper V-B, :mod:`..engine.geometry.subdivision`). Built once per scene change, no GPU needed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..engine.methods.sbc import sheet_bounds
from ..engine.geometry import closed_surfaces, subdivision
from ..engine.scene import vertex_normals

#: Float targets hold vertex indices exactly below 2^24.
MAX_VERTICES = 1 << 24


@dataclass(frozen=True)
class DrawGeometry:
    """What the passes draw, as arrays (no GPU needed to build it).

    Pre-pass: every diffuse mesh, then every reflector, in one indexed triangle list;
    positions relative to ``shift``; its triangles sorted by image, ``prepass_ranges``
    the (image index or -1, first triangle, count) runs. Reflected meshes: all diffuse
    meshes subdivided (:mod:`..engine.geometry.subdivision`) and concatenated, world positions, their
    triangles sorted by image likewise (``ranges``), and within an image by
    ``range_windings``: per range, the :func:`..engine.geometry.closed_surfaces.cullable_winding` of its
    meshes (+1 or -1: closed solids no mirror lies in, whose triangles facing away from
    the mirror may be culled; 0: the rest). ``images`` are the meshes' image textures,
    (H, W, 4) float32 linear, rows bottom to top.
    """

    shift: np.ndarray  # (3,) float64
    #: The pre-pass's parts (:class:`PrepassPart`), diffuse meshes first: its vertex
    #: arrays are made from them when asked for (:meth:`prepass_arrays`).
    prepass_parts: tuple
    prepass_triangles: np.ndarray  # (Tp, 3) int32
    vertices: np.ndarray  # (V, 3) float64, reflected meshes
    vertex_mesh: np.ndarray  # (V,) int32: the index of each vertex's diffuse mesh in mesh_names
    colors: np.ndarray  # (V, 4) float32
    triangles: np.ndarray  # (T, 3) int64
    diameter: float  # bounding-box diagonal of everything: bounds every reflected ray distance
    reflector_sizes: np.ndarray = None  # (R,) bounding-box diagonal of each reflector
    normals: np.ndarray = None  # (V, 3) float32 unit (zero where undefined)
    lit: np.ndarray = None  # (V,) float32: 1 lit, 0 emission (unlit)
    uvs: np.ndarray = None  # (V, 2) float32
    images: tuple = ()
    mesh_names: tuple = ()  # the diffuse meshes' names
    prepass_ranges: tuple = ()
    ranges: tuple = ()
    range_windings: tuple = ()
    stats: dict = field(default_factory=dict)

    @property
    def prepass_mirror_triangles(self) -> np.ndarray:
        """The pre-pass triangles of the reflectors (their parts come after every diffuse
        mesh's, so their vertices are the last ones)."""
        first = sum(part.size for part in self.prepass_parts if part.label[0] < 0.5)
        return self.prepass_triangles[self.prepass_triangles[:, 0] >= first]

    def prepass_arrays(self) -> dict:
        """{positions, colors, labels, normals, uvs}: the pre-pass's vertex arrays, made
        now, not kept: the GPU holds them once uploaded, and for a million-triangle
        mirror they are 46 MB (constant colours and labels, zero UVs, per vertex)."""
        return {name: self._prepass(name) for name in ("positions", "colors", "labels", "normals", "uvs")}

    def _prepass(self, name: str) -> np.ndarray:
        width = {"positions": 3, "colors": 4, "labels": 4, "normals": 4, "uvs": 2}[name]
        out = np.empty((sum(part.size for part in self.prepass_parts), width), np.float32)
        first = 0
        for part in self.prepass_parts:
            out[first:first + part.size] = part.array(name, self.shift)
            first += part.size
        return out


@dataclass(frozen=True)
class PrepassPart:
    """One diffuse mesh or reflector in the pre-pass: its world ``vertices`` (the
    capture's, not a copy), its ``color`` (per vertex, or one RGBA), its ``label``,
    its per-vertex (normal, lit) and UVs as float32 arrays, or None for a reflector:
    its unit ``mirror_normals`` with ``mirror_sealed`` (``ReflectorSet.sealed``'s
    sign) as the fourth component, and UVs 0."""

    vertices: np.ndarray
    color: np.ndarray
    label: tuple
    normal_lit: np.ndarray | None = None
    uvs: np.ndarray | None = None
    mirror_normals: np.ndarray | None = None
    mirror_sealed: float = 0.0

    @property
    def size(self) -> int:
        return len(self.vertices)

    def array(self, name: str, shift: np.ndarray) -> np.ndarray:
        """This part's rows of the pre-pass array ``name`` (float32, or broadcast to it)."""
        if name == "positions":
            return (self.vertices - shift).astype(np.float32)
        if name in ("colors", "labels"):
            value = self.color if name == "colors" else self.label
            return np.broadcast_to(np.asarray(value, np.float32), (self.size, 4))
        if name == "normals":
            if self.normal_lit is not None:
                return self.normal_lit
            return np.c_[self.mirror_normals.astype(np.float32), np.full(self.size, self.mirror_sealed, np.float32)]
        return self.uvs if self.uvs is not None else np.zeros((self.size, 2), np.float32)


def _sorted_by_image(triangles: np.ndarray, image: np.ndarray) -> tuple[np.ndarray, tuple]:
    """Triangles sorted by image index and within an image by their first vertex, and the
    (image, first, count) runs. In vertex order, a triangle's neighbours follow it, and the
    GPU finds their shared vertices already transformed: llvmpipe's vertex stage shades
    the vertices of each chunk of indices once, so neighbours in the index buffer share
    that work."""
    order = np.lexsort((triangles.min(axis=1) if len(triangles) else np.zeros(0, int), image))
    image = image[order]
    starts = np.flatnonzero(np.r_[True, image[1:] != image[:-1]]) if len(image) else np.zeros(0, int)
    counts = np.diff(np.r_[starts, len(image)])
    return triangles[order], tuple((int(image[k]), int(k), int(c)) for k, c in zip(starts, counts))


def mesh_attributes(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normals (N, 3) (the mesh's, else smooth ones from its faces), UVs (N, 2) and lit (N,)."""
    normals = mesh.normals if getattr(mesh, "normals", None) is not None else vertex_normals(
        mesh.vertices, mesh.triangles)
    uvs = mesh.uvs if mesh.uvs is not None else np.zeros((len(mesh.vertices), 2))
    lit = np.full(len(mesh.vertices), 0.0 if mesh.emissive else 1.0, np.float32)
    return np.asarray(normals, np.float64), np.asarray(uvs, np.float64), lit


def _prepass_parts(meshes, attributes, image_of_mesh, reflectors, colors, mirror, f0, fade, sense) -> list:
    """(:class:`PrepassPart`, triangles, image index) of every diffuse mesh, then every
    reflector. A mirror's part holds references to its arrays: its float32 normals and
    zero UVs are made when the pre-pass arrays are (once, to upload them), not kept
    (with its constant colour and label per vertex: 46 MB for a million-triangle
    mirror, and float64 copies of them, its shifted int64 triangles and a join of every
    vertex for the box: 135 MB at once)."""
    parts = [(PrepassPart(mesh.vertices, np.asarray(mesh.colors, np.float32), (0.0, 1.0, -1.0, 0.0),
                          normal_lit=np.asarray(np.c_[normal, lit], np.float32), uvs=np.asarray(uv, np.float32)),
              mesh.triangles, image)
             for mesh, (normal, uv, lit), image in zip(meshes, attributes, image_of_mesh)]
    parts += [(PrepassPart(r.vertices, colors[k], (k + 1.0, float(mirror[k]), float(f0[k]), float(fade[k])),
                           mirror_normals=r.normals, mirror_sealed=float(sense[k])), r.triangles, -1)
              for k, r in enumerate(reflectors)]
    return parts


def prepare_geometry(reflectors, meshes, reflector_colors=None, reflectivity=None,
                     edge_fraction: float = subdivision.EDGE_FRACTION, fresnel_f0=None,
                     attenuation_distance=None, sealed=None, transmits=None) -> DrawGeometry:
    """Arrays of one scene for :class:`.reflection_draw.ReflectionRenderer`.

    ``reflector_colors`` (R, 3 or 4) linear, default white; ``reflectivity`` (R,) in
    [0, 1], default 1 (perfect mirrors); ``fresnel_f0`` (R,) Schlick's reflectance at
    normal incidence, NaN or negative for no Fresnel (default none); ``transmits`` (R,)
    bool: the weight is 1 minus the exact dielectric reflectance of the index of
    refraction F0 stands for instead (glass, whose drawn image is the refracted one:
    encoded as -2 - F0); ``attenuation_distance``
    (R,) the distance over which reflections fade to the world (0 or default: none).
    SBC paper section V-D. ``sealed`` (R,): each reflector's ``ReflectorSet.sealed``
    (its winding where it is closed and holds nothing, else 0; default 0), the fourth
    component of its pre-pass normals, with which the pre-pass marks the pixels whose
    view ray starts inside it (``glsl/reflection_prepass_frag.glsl``). ``edge_fraction`` sets the pre-subdivision
    (:func:`subdivision.subdivide`); ``None`` draws the meshes as they are.
    """
    start = time.perf_counter()
    reflectors, meshes = list(reflectors), list(meshes)
    n_reflectors = len(reflectors)
    colors = np.ones((n_reflectors, 4), np.float32)
    if reflector_colors is not None:
        given = np.asarray(reflector_colors, dtype=np.float32).reshape(n_reflectors, -1)
        colors[:, :given.shape[1]] = given[:, :4]
    mirror = np.ones(n_reflectors, np.float32) if reflectivity is None else np.clip(
        np.asarray(reflectivity, dtype=np.float32).reshape(n_reflectors), 0.0, 1.0)
    f0 = np.full(n_reflectors, -1.0, np.float32) if fresnel_f0 is None else np.asarray(
        fresnel_f0, dtype=np.float32).reshape(n_reflectors)
    f0 = np.where(np.isfinite(f0) & (f0 >= 0), np.clip(f0, 0.0, 1.0), -1.0).astype(np.float32)
    if transmits is not None:
        f0 = np.where(np.asarray(transmits, dtype=bool).reshape(n_reflectors) & (f0 >= 0), -2.0 - f0, f0).astype(
            np.float32)
    fade = np.zeros(n_reflectors, np.float32) if attenuation_distance is None else np.maximum(
        np.asarray(attenuation_distance, dtype=np.float32).reshape(n_reflectors), 0.0)
    sense = np.zeros(n_reflectors, np.float32) if sealed is None else np.sign(
        np.asarray(sealed, dtype=np.float32).reshape(n_reflectors))

    images, image_of_mesh = [], []
    for mesh in meshes:
        image = getattr(mesh, "image", None)
        image_of_mesh.append(-1 if image is None else len(images))
        if image is not None:
            images.append(np.ascontiguousarray(image, dtype=np.float32))
    attributes = [mesh_attributes(m) for m in meshes]

    parts = _prepass_parts(meshes, attributes, image_of_mesh, reflectors, colors, mirror, f0, fade, sense)
    if parts:
        lo = np.min([part.vertices.min(axis=0) for part, _, _ in parts], axis=0)
        hi = np.max([part.vertices.max(axis=0) for part, _, _ in parts], axis=0)
    else:
        lo = hi = np.zeros(3)
    shift = 0.5 * (lo + hi)
    # Every part's triangles written once into one int32 array, shifted to its vertices.
    all_triangles = np.empty((sum(len(tris) for _, tris, _ in parts), 3), np.int32)
    tri_image, first, offset = [], 0, 0
    for part, tris, image in parts:
        block = all_triangles[first:first + len(tris)]
        block[:] = tris
        block += offset
        first += len(tris)
        tri_image.append(np.full(len(tris), image, np.int32))
        offset += part.size
    prepass_triangles, prepass_ranges = _sorted_by_image(
        all_triangles, np.concatenate(tri_image) if tri_image else np.zeros(0, np.int32))
    del all_triangles, tri_image

    centres, radii = subdivision.reflector_spheres(reflectors)
    vertices, packed, mesh_triangles, mesh_image, mesh_winding, offset = [], [], [], [], [], 0
    owners = []
    mirrors = [r.vertices for r in reflectors]
    for index, (mesh, (normal, uv, lit), image) in enumerate(zip(meshes, attributes, image_of_mesh)):
        sense = closed_surfaces.cullable_winding(mesh.vertices, mesh.triangles, mirrors)
        # Colour, normal, UV and lit are interpolated together at new midpoints.
        v, t, c = mesh.vertices, mesh.triangles, np.c_[mesh.colors, normal, uv, lit].astype(np.float32)
        if edge_fraction is not None:
            v, t, c = subdivision.subdivide(v, t, c, centres, radii, edge_fraction)
        vertices.append(v)
        owners.append(np.full(len(v), index, np.int32))
        packed.append(c)
        mesh_triangles.append(t + offset)
        mesh_image.append(np.full(len(t), image))
        mesh_winding.append(np.full(len(t), sense))
        offset += len(v)
    if offset >= MAX_VERTICES:
        raise ValueError(f"{offset} reflected vertices: float targets index below 2^24 only")
    packed = np.concatenate(packed) if packed else np.zeros((0, 10), np.float32)
    vertices = np.concatenate(vertices) if vertices else np.zeros((0, 3))
    mesh_triangles = np.concatenate(mesh_triangles) if mesh_triangles else np.zeros((0, 3), np.int64)
    # Vertices along a Morton curve: runs of them are compact chunks for per-sheet culling.
    order = sheet_bounds.morton_order(vertices)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    vertices, packed, mesh_triangles = vertices[order], packed[order], rank[mesh_triangles]
    owners = np.concatenate(owners)[order] if owners else np.zeros(0, np.int32)
    vertex_normals = packed[:, 4:7]
    length = np.linalg.norm(vertex_normals, axis=1, keepdims=True)
    vertex_normals = np.divide(vertex_normals, length, out=np.zeros_like(vertex_normals), where=length > 0)
    # One run per image and winding: (image + 1) * 3 + (winding + 1) orders both.
    keys = (np.concatenate(mesh_image) + 1) * 3 + np.concatenate(mesh_winding) + 1 if mesh_image \
        else np.zeros(0, int)
    mesh_triangles, keyed = _sorted_by_image(mesh_triangles, keys)
    ranges = tuple((key // 3 - 1, first, count) for key, first, count in keyed)
    geometry = DrawGeometry(
        shift=shift,
        prepass_parts=tuple(part for part, _, _ in parts),
        prepass_triangles=prepass_triangles,
        vertices=vertices,
        vertex_mesh=owners,
        colors=np.ascontiguousarray(packed[:, :4]),
        triangles=mesh_triangles,
        diameter=float(max(np.linalg.norm(hi - lo), 1e-9)),
        reflector_sizes=np.array([np.linalg.norm(np.subtract(*r.bounds[::-1])) for r in reflectors], np.float64),
        normals=vertex_normals.astype(np.float32),
        lit=np.ascontiguousarray(packed[:, 9]),
        uvs=np.ascontiguousarray(packed[:, 7:9]),
        images=tuple(images),
        mesh_names=tuple(mesh.name for mesh in meshes),
        prepass_ranges=prepass_ranges,
        ranges=ranges,
        range_windings=tuple(key % 3 - 1 for key, _, _ in keyed),
    )
    geometry.stats.update({
        "mesh_triangles": int(sum(len(m.triangles) for m in meshes)),
        "reflected_triangles": int(len(geometry.triangles)),
        "reflected_vertices": int(len(geometry.vertices)),
        "closed_triangles": int(sum(count for (_, _, count), w in zip(ranges, geometry.range_windings) if w)),
        "prepare_seconds": time.perf_counter() - start,
    })
    return geometry
