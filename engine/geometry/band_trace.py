# SPDX-License-Identifier: GPL-3.0-or-later
"""Ray tracing of the thin band along a reflector's visible edge (numpy only).

A sample-based camera projects a point only between four neighbouring rays of its
reflection group (``engine/methods/sbc/sbc.py``, after SBC paper section IV: the rays' frustums),
so no reflection can be drawn in the last ray-map cell before the reflector's
silhouette, or before an object in front of it: there the neighbour rays do not exist
(they miss the reflector). That band is up to the down-sampling factor d pixels wide,
and on small images it is a large share of a mirror (the whole rim of a sphere).

The reflected rays of those few pixels are traced instead, as the ray map itself is
traced (``engine/methods/sbc/raymap.py``, SBC section III-B), but against the diffuse meshes too:
the view ray's first hit, then reflections off the reflectors up to the highest order
drawn; the colour is the diffuse mesh's, shaded as the GPU shades it (:func:`shade`,
``drawing/glsl/reflection_shading.glsl``: interpolated vertex colour times its image
texture, lit along the true eye vector, the reversed reflected ray, SBC section V-C),
where a reflected ray meets one, and the world's where it leaves the scene (or would
need a higher order). The work is proportional to the perimeter of the footprint, not
its area.
"""

from __future__ import annotations

import dataclasses
import threading

import numpy as np

from .raytrace import RayHits, ReflectorSet, reflect, reflection_valid
from ..scene import Reflector, vertex_normals

#: Ambient share of the headlight Lambert shading (SBC V-C; drawing/glsl/reflection_shading.glsl).
SHADE_AMBIENT = 0.3
#: An eye ray started from the mirrors' cell grid (``ReflectorSet.triangle_grid``) saves
#: about 14 us of BVH descent; building the grid costs about 1.2 us a triangle (measured
#: on a 1.3M-triangle sphere): the grid pays for itself from one ray per this many
#: triangles, or at once where it is built already.
GRID_TRIANGLES_PER_RAY = 10
#: What a ray that meets a sealed mirror from inside shows (``BandTracer.trace``): black,
#: at distance 0 from the mirror (a fade distance does not turn it into the world).
NO_LIGHT = (0.0, 0.0, 0.0, 0.0)


def shade(albedo: np.ndarray, lit: np.ndarray, normals: np.ndarray, to_eye: np.ndarray) -> np.ndarray:
    """Headlight Lambert, two-sided: albedo (K, C) times AMBIENT + (1 - AMBIENT) |n . e|
    where ``lit``, the albedo itself elsewhere (emission); the GLSL ``shade`` in numpy."""
    lengths = np.linalg.norm(normals, axis=1) * np.linalg.norm(to_eye, axis=1)
    cosine = np.divide(np.abs(np.einsum("ij,ij->i", normals, to_eye)), lengths, out=np.ones(len(lengths)),
                       where=lengths > 1e-30)
    factor = np.where(np.asarray(lit) > 0.5, SHADE_AMBIENT + (1.0 - SHADE_AMBIENT) * cosine, 1.0)
    return albedo * factor[:, None]


def sample_image(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup of an (H, W, 4) image at texture coordinates (K, 2), repeating,
    texel centres at (k + 0.5) / size (as the GPU's linear filter)."""
    height, width = image.shape[:2]
    x = np.asarray(uv[:, 0]) * width - 0.5
    y = np.asarray(uv[:, 1]) * height - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    x1, y1 = (x0 + 1) % width, (y0 + 1) % height
    x0, y0 = x0 % width, y0 % height
    return ((1 - fy) * ((1 - fx) * image[y0, x0] + fx * image[y0, x1])
            + fy * ((1 - fx) * image[y1, x0] + fx * image[y1, x1]))


class BandTracer:
    """Reflectors and diffuse meshes, traced together: the mirrors' ``ReflectorSet``
    (``mirrors``, the renderer's own when given: a big mirror's tree is built once) and
    one of the diffuse meshes as pseudo-reflectors (their normals are never used: a hit
    on one ends the path). Hits are numbered as in one set, the diffuse meshes after
    the mirrors: a hit's owner below the number of reflectors is a mirror.
    """

    def __init__(self, reflectors, meshes, mirrors: ReflectorSet | None = None):
        self.n_reflectors = len(reflectors)
        pseudo = []
        for m in meshes:
            normals = m.normals if getattr(m, "normals", None) is not None else vertex_normals(m.vertices, m.triangles)
            normals = np.where((np.linalg.norm(normals, axis=1) > 1e-8)[:, None], normals, [0.0, 0.0, 1.0])
            pseudo.append(Reflector(f"{m.name} (diffuse)", m.vertices, m.triangles, normals))
        if mirrors is None and reflectors:
            mirrors = ReflectorSet(list(reflectors))
        self.mirrors = mirrors
        self.diffuse = ReflectorSet(pseudo) if pseudo else None
        self.n_mirror_triangles = 0 if mirrors is None else len(mirrors.triangles)
        self.meshes = list(meshes)
        self.mesh_colors = (np.concatenate([np.asarray(m.colors, dtype=np.float64) for m in meshes])
                            if meshes else np.zeros((0, 4)))
        self.mesh_uvs = (np.concatenate([np.zeros((len(m.vertices), 2)) if m.uvs is None else m.uvs for m in meshes])
                         if meshes else np.zeros((0, 2)))
        self.vertex_mesh = np.repeat(np.arange(len(meshes)), [len(m.vertices) for m in meshes])

    def intersect(self, origins, directions, source_triangles=None, mirrors_only: bool = False):
        """The rays' nearest hits (``raytrace.RayHits``) on a mirror or, unless
        ``mirrors_only``, a diffuse mesh nearer; ``source_triangles``: the mirror
        triangles the rays leave."""
        if self.mirrors is not None:
            hits = self.mirrors.intersect(origins, directions, source_triangles=source_triangles)
        else:
            hits = RayHits.misses(len(origins))
        if mirrors_only or self.diffuse is None:
            return hits
        nearer = self.diffuse.intersect(origins, directions, hits.t)
        rays = np.flatnonzero(nearer.hit & (nearer.t < hits.t))
        for column in dataclasses.fields(hits):
            getattr(hits, column.name)[rays] = getattr(nearer, column.name)[rays]
        hits.triangle[rays] += self.n_mirror_triangles
        hits.reflector[rays] += self.n_reflectors
        return hits

    def trace(self, view, pixels: np.ndarray, max_order: int, world_color, on_mirrors: bool = False,
              surface_points: np.ndarray | None = None) -> np.ndarray:
        """Linear RGB seen through pixel centres ``pixels`` (K, 2), mirrors included, and in
        the fourth column the distance from the last mirror to the diffuse point (0 for a
        point seen directly, inf where the world shows): (K, 4). ``on_mirrors``: the
        pixels show mirrors (the renderer's pre-pass says so), and their eye rays are
        met with the mirrors alone, a far smaller tree (the rays that miss them, on a
        pixel the pre-pass rasterised at a silhouette, with everything).
        ``surface_points`` (K, 3), NaN where unknown: where the pre-pass's depth puts the
        mirror on each pixel; the eye ray is then met with the triangles around it first
        (``ReflectorSet.triangle_grid``, ``intersect_near``), the BVH descended only by
        the rays that miss them (descents that would otherwise cost a large share of a render).

        Paths stop at the first diffuse hit, when they leave the scene (world colour), at
        an invalid reflection (a grazing ray turned into the mirror: world colour), or
        on a reflector after ``max_order`` reflections (world colour, as the drawing
        shows where no reflection group of that order exists). A ray that meets a sealed
        mirror from inside (``ReflectorSet.from_inside``: an eye ray starting inside it,
        the camera's clip start cutting into it) shows black at distance 0
        (:data:`NO_LIGHT`): inside a closed mirror that holds nothing it would bounce
        without end and meet no light, as Cycles shows it once its bounces run out.
        """
        pixels = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        origins, directions = view.pixel_rays(pixels)
        hits = self._first_hits(origins, directions, on_mirrors, surface_points) if len(pixels) else None
        return self._follow(origins, directions, hits, max_order, world_color)

    def trace_rays(self, origins, directions, max_order: int, world_color) -> np.ndarray:
        """As :meth:`trace`, for rays starting anywhere (those leaving glass,
        ``engine/glass``): (K, 4) linear RGB and the distance to the diffuse point after
        the first mirror (0 where no mirror was met, inf where the world shows)."""
        origins, directions = np.asarray(origins, dtype=np.float64), np.asarray(directions, dtype=np.float64)
        hits = self.intersect(origins, directions) if len(origins) else None
        return self._follow(origins, directions, hits, max_order, world_color)

    def _follow(self, origins, directions, hits, max_order: int, world_color) -> np.ndarray:
        """The paths of rays from their first ``hits`` on (see :meth:`trace`)."""
        out = np.tile(np.asarray(world_color, dtype=np.float64)[:4], (len(origins), 1))
        out[:, 3] = np.inf
        if len(origins) == 0:
            return out
        alive = np.arange(len(origins))
        for order in range(max_order + 1):
            hit = hits.hit
            owner = np.where(hit, hits.reflector, -1)
            diffuse = hit & (owner >= self.n_reflectors)
            if diffuse.any():
                out[alive[diffuse], :3] = self._color(hits.triangle[diffuse], hits.barycentric[diffuse],
                                                      hits.normal[diffuse], -directions[diffuse])
                out[alive[diffuse], 3] = hits.t[diffuse] if order > 0 else 0.0
            mirror = hit & (owner >= 0) & (owner < self.n_reflectors)
            inside = np.zeros_like(mirror)
            if mirror.any():
                inside[mirror] = self.mirrors.from_inside(directions[mirror], hits.triangle[mirror])
            out[alive[inside]] = NO_LIGHT
            mirror &= ~inside
            if order == max_order:
                break
            valid = mirror & reflection_valid(directions, np.nan_to_num(hits.normal), np.nan_to_num(hits.face_normal))
            keep = np.flatnonzero(valid)
            if len(keep) == 0:
                break
            alive = alive[keep]
            origins = hits.position[keep]
            directions = reflect(directions[keep], hits.normal[keep])
            hits = self.intersect(origins, directions, source_triangles=hits.triangle[keep])
        return out

    def _first_hits(self, origins, directions, on_mirrors: bool, surface_points=None):
        """The eye rays' first hits: on the mirrors alone where they meet one
        (``on_mirrors``; near ``surface_points`` first where given), else on everything."""
        if not on_mirrors:
            return self.intersect(origins, directions)
        if surface_points is not None and self._grid_pays(len(origins)):
            near = self.mirrors.triangle_grid.nearby(surface_points)
            hits = self.mirrors.intersect_near(origins, directions, near_triangles=near)
        else:
            hits = self.intersect(origins, directions, mirrors_only=True)
        missed = np.flatnonzero(~hits.hit)
        if len(missed):
            again = self.intersect(origins[missed], directions[missed])
            for column in dataclasses.fields(hits):
                getattr(hits, column.name)[missed] = getattr(again, column.name)
        return hits

    def _grid_pays(self, n_rays: int) -> bool:
        """Whether ``n_rays`` eye rays should start from the mirrors' cell grid: where it
        is built already (the renderer keeps its set between frames), or where they save
        more than building it costs (``GRID_TRIANGLES_PER_RAY``: a million-triangle
        mirror's band of a thousand pixels is cheaper in the BVH alone)."""
        if self.mirrors is None:
            return False
        return ("triangle_grid" in vars(self.mirrors)
                or n_rays * GRID_TRIANGLES_PER_RAY >= len(self.mirrors.triangles))

    def _color(self, triangles: np.ndarray, barycentric: np.ndarray, normals: np.ndarray,
               to_eye: np.ndarray) -> np.ndarray:
        """Shaded RGB of diffuse hits: barycentric mix of the triangle's vertex colours, times
        its mesh's image at the interpolated UVs, lit along ``to_eye`` (:func:`shade`)."""
        corners = self.diffuse.triangles[triangles - self.n_mirror_triangles]
        albedo = np.einsum("ij,ijk->ik", barycentric, self.mesh_colors[corners])[:, :3]
        mesh = self.vertex_mesh[corners[:, 0]]
        for index in np.unique(mesh):
            image = getattr(self.meshes[index], "image", None)
            if image is None:
                continue
            rows = mesh == index
            uv = np.einsum("ij,ijk->ik", barycentric[rows], self.mesh_uvs[corners[rows]])
            albedo[rows] *= sample_image(np.asarray(image, dtype=np.float64), uv)[:, :3]
        lit = np.array([0.0 if m.emissive else 1.0 for m in self.meshes])[mesh]
        return shade(albedo, lit, normals, to_eye)


class TracerSource:
    """A :class:`BandTracer` made on first use, from numpy alone: a worker thread may
    make and use it while holding nothing of the GPU (a renderer's textures freed on a
    thread without a GPU context stay in the driver's heap)."""

    def __init__(self, reflectors, meshes, mirrors: ReflectorSet | None = None):
        self._arguments = (list(reflectors), list(meshes), mirrors)
        self._tracer = None
        self._lock = threading.Lock()

    def get(self) -> BandTracer:
        with self._lock:  # the drawing thread and a worker may both ask first
            if self._tracer is None:
                self._tracer = BandTracer(*self._arguments)
            return self._tracer


def history_boundary(ray_map, width: int, height: int, max_order: int) -> np.ndarray:
    """(H, W) bool: pixels between ray-map cells whose deepest ray (of order <= max_order)
    has different surface histories (``RayMap.surfaces``: reflectors and their smooth
    pieces), or where one of those cells has no ray.

    A pixel is drawn from the four cells around its centre (a projection needs four rays
    of one tree's grid). Where those cells end in different histories (inside a
    footprint: the silhouette of another reflector seen in this one, where the rays go
    on to a second order; or a sharp edge of the mirror, where the trees of its two
    sides end: sbc_build.surface_sets) no tree has all four rays there, so neither side's
    reflection reaches the pixel: the same band as along a footprint's edge, inside it
    (SBC section IV).
    """
    d = ray_map.downsample
    columns, rows = ray_map.columns, ray_map.rows
    n_groups = max(1, len(ray_map.surfaces))
    keep = ray_map.order <= max_order
    key = np.full((rows, columns), -1, dtype=np.int64)
    cells = ray_map.cell[keep]
    np.maximum.at(key, (cells[:, 1], cells[:, 0]), ray_map.order[keep] * n_groups + ray_map.surface[keep])
    final = np.where(key >= 0, key % n_groups, -1)

    def brackets(n_pixels, n_cells):
        low = np.clip(np.floor((np.arange(n_pixels) + 0.5) / d - 0.5).astype(np.int64), 0, n_cells - 1)
        return low, np.minimum(low + 1, n_cells - 1)

    i0, i1 = brackets(width, columns)
    j0, j1 = brackets(height, rows)
    corners = [final[np.ix_(j, i)] for j in (j0, j1) for i in (i0, i1)]
    return ~((corners[0] == corners[1]) & (corners[0] == corners[2]) & (corners[0] == corners[3]))


def band_pixels(labels: np.ndarray, drawn: np.ndarray, radius: int, edges_of_drawn: bool = False,
                boundary: np.ndarray | None = None) -> np.ndarray:
    """(K, 2) integer pixels (x, y) of reflector pixels without a drawn reflection that lie
    within ``radius`` pixels (Chebyshev) of a pixel with another id (or the image edge),
    or in ``boundary`` (:func:`history_boundary`), and with ``edges_of_drawn`` also those
    within ``radius`` of a drawn reflection.

    ``labels`` (H, W) ids of the pre-pass (0 none or diffuse, reflector index + 1);
    ``drawn`` (H, W) bool where the reflection pass drew.
    """
    ids = np.rint(labels).astype(np.int64)
    drawn = np.asarray(drawn, dtype=bool)
    near_edge = _near_another_id(ids, radius)
    if edges_of_drawn:
        near_edge |= _near(drawn, radius)
    if boundary is not None:
        near_edge |= boundary
    return _pixels((ids > 0) & ~drawn & near_edge)


def hole_pixels(labels: np.ndarray, drawn: np.ndarray, radius: int) -> np.ndarray:
    """(K, 2) integer pixels (x, y) of reflector pixels without a drawn reflection that the
    drawn reflections enclose: within the morphological closing of ``drawn`` by a square
    of ``radius`` pixels (a hole up to about 2 ``radius`` across, not the world shown
    beyond a reflection's outer edge). ``labels`` and ``drawn`` as :func:`band_pixels`."""
    drawn = np.asarray(drawn, dtype=bool)
    closed = ~_near(~_near(drawn, radius), radius)
    return _pixels((np.rint(labels) > 0) & ~drawn & closed)


def drawn_pixels_in(labels: np.ndarray, drawn: np.ndarray, region: np.ndarray) -> np.ndarray:
    """(K, 2) integer pixels (x, y) of reflector pixels in ``region`` (H, W) bool that
    have a drawn reflection (``labels`` and ``drawn`` as :func:`band_pixels`): where the
    sample-based camera's answers are doubtful (:func:`unreliable_cells`), those drawn
    may be an image of the wrong point while the right one is missing."""
    return _pixels((np.rint(labels) > 0) & np.asarray(drawn, dtype=bool) & region)


def rim_gap_pixels(labels: np.ndarray, drawn: np.ndarray, radius: int) -> np.ndarray:
    """(K, 2) integer pixels (x, y) of reflector pixels without a drawn reflection within
    ``radius`` pixels (Chebyshev) both of their footprint's edge and of a drawn
    reflection: the strip a blended reflection leaves between itself and the mirror's
    silhouette, where not every node of the eye's cell sees the mirror (a ball's floor
    along its lower rim). The pixels of a footprint that far from every drawn reflection
    show the world (a ball's sky), and are left to the composite.

    ``labels`` and ``drawn`` as :func:`band_pixels`."""
    ids = np.rint(labels).astype(np.int64)
    drawn = np.asarray(drawn, dtype=bool)
    return _pixels((ids > 0) & ~drawn & _near_another_id(ids, radius) & _near(drawn, radius))


def _pixels(mask: np.ndarray) -> np.ndarray:
    rows, columns = np.nonzero(mask)
    return np.stack([columns, rows], axis=1)


def _window_extremes(values: np.ndarray, radius: int, beyond: int) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) of integer ``values`` (H, W) over each pixel's square of side
    2 ``radius`` + 1, ``beyond`` outside the image: one pass per axis (the square is
    separable), 2 (2 radius + 1) array operations instead of (2 radius + 1)^2."""
    radius = max(0, int(radius))
    low, high = values, values
    for axis in (0, 1):
        pad = [(radius, radius) if a == axis else (0, 0) for a in range(2)]
        padded_low, padded_high = (np.pad(v, pad, constant_values=beyond) for v in (low, high))
        length = values.shape[axis]
        windows = [tuple(slice(k, k + length) if a == axis else slice(None) for a in range(2))
                   for k in range(2 * radius + 1)]
        low, high = padded_low[windows[0]], padded_high[windows[0]]
        for window in windows[1:]:
            low, high = np.minimum(low, padded_low[window]), np.maximum(high, padded_high[window])
    return low, high


def _near_another_id(ids: np.ndarray, radius: int) -> np.ndarray:
    """Pixels within ``radius`` (Chebyshev) of a pixel with another id or of the image edge."""
    low, high = _window_extremes(ids, radius, -1)
    return (low != ids) | (high != ids)


def _near(mask: np.ndarray, radius: int) -> np.ndarray:
    """Pixels within ``radius`` (Chebyshev) of a pixel of ``mask``."""
    return _window_extremes(mask.astype(np.int8), radius, 0)[1] > 0


def unreliable_cells(ray_map, trees, mixed=None, folds=None) -> np.ndarray:
    """(rows, columns) bool: ray-map cells (by their lower-left corner ray) where the
    sample-based camera itself knows its projection is unreliable: cells of ray-list
    leaves (no plane split the rays, SBC section IV-C) and of banded camera leaves' ray
    lists (their rays focus, ``bsp._depth_bands``), fold cells (the rays cross: a
    caustic, ``sbc_cells.FoldCells``) and mixed cells (an occluder's silhouette crosses the
    cell, ``sbc_cells.MixedCells``). Reflections there may be missing although the mirror
    shows an object (thin, strongly curved parts: a teapot's spout). A ray-list leaf's
    rays (``BSPTree.list_rays``) mark the four cells around each: a leaf one ray wide
    along a sharp edge of the mirror has no complete cell of its own."""
    out = np.zeros((ray_map.rows, ray_map.columns), dtype=bool)
    for tree in trees:
        if tree.cells is not None and len(tree.cells.lo):
            corner = np.rint(tree.cells.lo).astype(np.int64)
            out[corner[:, 1], corner[:, 0]] = True
        if tree.list_rays is not None and len(tree.list_rays):
            i, j = ray_map.cell[tree.list_rays, 0], ray_map.cell[tree.list_rays, 1]
            for di in (0, 1):
                for dj in (0, 1):
                    out[np.maximum(j - dj, 0), np.maximum(i - di, 0)] = True
    for cells in list(mixed or []) + list(folds or []):
        if cells is not None:
            out |= cells.index >= 0
    return out


def unreliable_pixels(camera, width: int, height: int) -> np.ndarray:
    """(H, W) bool: the pixels of ``camera``'s :func:`unreliable_cells`."""
    cells = unreliable_cells(camera.ray_map, camera.trees, camera.mixed, camera.folds)
    return cell_pixels_mask(cells, camera.ray_map.downsample, width, height)


def cell_pixels_mask(cells: np.ndarray, downsample: int, width: int, height: int) -> np.ndarray:
    """(H, W) bool: pixels whose centre lies in a marked ray-map cell square (the four
    rays around the centre, lower-left corner marked), as :func:`history_boundary` reads them."""
    rows, columns = cells.shape

    def lower(n_pixels, n_cells):
        return np.clip(np.floor((np.arange(n_pixels) + 0.5) / downsample - 0.5).astype(np.int64), 0, n_cells - 1)

    return cells[np.ix_(lower(height, rows), lower(width, columns))]
