# SPDX-License-Identifier: GPL-3.0-or-later
"""Glass: what lies behind a glass object, refracted, and what it reflects.

The layer's renderer holds the glass as its "mirrors" and every other surface as meshes.
Each glass pixel is ray traced on the GPU every frame, live and in Render Image
(``drawing/methods/glass_trace.py``): its eye ray followed through the glass's own
triangles (Snell's law at every interface, total internal reflection), any glass solid or
sheet, met with the scene (mirrors reflecting to the scene's Max Order), and mixed by the
exact dielectric Fresnel reflectance with the ray the glass reflects where the eye meets
it and the one it reflects back inside where the path leaves, as Cycles' Glass BSDF shows
them; glass of a Refraction BSDF reflects nothing (and where it should reflect totally,
shows black, as Cycles does).

Where the meshes' image textures do not fit the trace's atlas
(``drawing/methods/image_atlas.py``: some 64 million texels), the live view draws convex
glass by the refraction search instead (``drawing/methods/refraction_draw.py``: every
diffuse vertex where it appears, each fragment a ray cast along its pixel's path) with the
iterative search drawing the glass's reflections as a mirror's (:func:`glass_mirror`), and
shows other glass as a solid object; Render Image then traces each glass pixel on the CPU
(``engine/glass/paths.py``, ``band_trace.BandTracer.trace_rays``), the same model. Those
pixels replace the frame's (where the mirrors' renderer drew the glass as a solid
object); a scene of glass alone is the layer's frame. Mirrors reflect glass as a solid
object, and the panel says so. A camera inside glass (under water) sees out through it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..drawing.gpu_data import read_depth, read_texture
from ..drawing.methods.glass_trace import GlassTracePass
from ..drawing.methods.iterative_draw import IterativePass
from ..drawing.methods.refraction_draw import RefractionPass
from ..drawing.methods.scene_tables import TracedScene, samples_every_image
from ..drawing.reflection_draw import ReflectionRenderer
from ..drawing.screen_space import pixel_box
from ..engine.errors import SceneInputError
from ..engine.geometry import subdivision
from ..engine.geometry.band_trace import BandTracer
from ..engine.geometry.raytrace import reflect
from ..engine.glass import GlassSet, fresnel_dielectric
from ..engine.glass.refraction_search import refracted_glass
from ..engine.methods.iterative import IterativeReflector
from ..engine.methods.sbc.sbc_build import check_view_outside_reflectors, enclosing_reflector
from ..engine.scene import DiffuseMesh
from ..engine.view import View
from . import star_maps


@dataclass
class GlassLayer:
    """One capture's glass: its set, the renderer whose pre-pass finds where it is in
    front, and the tracer of everything else (made again when the capture changes)."""

    key: tuple
    glass: GlassSet
    renderer: ReflectionRenderer
    tracer: BandTracer
    #: Names of the glass objects the last render's rays met inside another glass (glass
    #: in glass, or overlapping): a ray leaving the inner one is taken to leave into air.
    nested: tuple = ()
    #: Whether the GPU traces every glass pixel (:mod:`..drawing.methods.glass_trace`);
    #: else the refraction search draws convex glass live and Render Image traces on the CPU.
    traced: bool = True
    #: {name: reason} of the glass neither the trace nor the search draws live (open, not
    #: convex... in a scene of more image textures than the trace samples).
    unsearched: dict = field(default_factory=dict)
    #: The live view's renderer of the glass as mirrors (:func:`glass_mirror`): what the
    #: searched glass that reflects shows by its Fresnel reflectance where the trace cannot
    #: (more image textures than it samples). None elsewhere.
    mirror: ReflectionRenderer | None = None

    def draw(self, view: View, world, accuracy_px: float, exact: bool) -> None:
        """The live view's glass over the bound framebuffer (an overlay, as
        ``ReflectionRenderer.draw`` with ``reflectors_only``): the traced glass pixels, or
        the refracted images over the glass's own reflections by the Fresnel reflectance
        (drawn first offscreen by :attr:`mirror`). ``exact``: nothing snaps."""
        self._place_eye(view)
        beneath = None
        if self.mirror is not None:
            targets = self.mirror.targets(view.width, view.height)
            rect = self.mirror.mirrors_rect(view, targets)
            targets = self.mirror.draw_passes(view, None, warm=True, mirrors_only=True, accuracy_px=accuracy_px,
                                              scissor=pixel_box(rect, targets.width, targets.height, 1),
                                              snap=not exact)
            beneath, framebuffer = targets.output
            with framebuffer.bind():
                self.mirror.composite(targets, world, reflectors_only=True, rect=rect)
        self.renderer.draw(view, None, world, reflectors_only=True, accuracy_px=accuracy_px, exact=exact,
                           beneath=beneath)

    def render(self, view: View, world, max_order: int) -> tuple[np.ndarray, np.ndarray]:
        """((H, W, 4) linear RGBA rows bottom to top, (H, W) bool where a glass object is
        in front) of ``view``; the image holds the traced colours there (on the GPU, or on
        the CPU without :attr:`traced`), the renderer's frame (the scene without the
        glass) elsewhere. A view from inside glass is traced from there on the GPU; the
        CPU's trace refuses it, naming the glass."""
        if not self.traced:
            try:
                check_view_outside_reflectors(self.glass.surfaces, view)
            except SceneInputError as error:
                raise SceneInputError(error.object_name, "the view is inside this glass object; move the camera "
                                      "outside it (the CPU's trace of glass, in a scene of more image "
                                      f"textures than the GPU's trace holds, starts in air)") from None
        self._place_eye(view)
        image = self.renderer.render(view, None, world, trace=False)
        targets = self.renderer.targets(view.width, view.height)
        labels = read_texture(targets.prepass_labels, view.width, view.height)
        in_front = labels[..., 0] >= 0.5
        if self.traced:
            self.nested = self.renderer.pass_named(GlassTracePass.name).nested(labels)
            return image, in_front
        rows, columns = np.nonzero(in_front)
        depth = read_depth(targets.prepass, view.width, view.height)
        pixels = np.stack([columns, rows], axis=1) + 0.5
        colors = self.trace(view, pixels, world, max_order, view.window_points(pixels, depth[rows, columns]))
        image[rows, columns, :3] = colors
        image[rows, columns, 3] = 1.0
        return image, in_front

    def _place_eye(self, view: View) -> None:
        """Tell the GPU's trace which glass the (perspective) eye of ``view`` is inside."""
        if self.traced:
            inside = enclosing_reflector(self.glass.surfaces, view.eye, -view.backward) if view.is_perspective else None
            self.renderer.pass_named(GlassTracePass.name).eye_glass = -1 if inside is None else inside

    def trace(self, view: View, pixels: np.ndarray, world, max_order: int, surface=None) -> np.ndarray:
        """(K, 3) linear RGB of the glass seen through ``pixels`` (K, 2): the refracted
        path's colour with, by the Fresnel reflectance, the ray reflected at the first
        interface and the one reflected back inside at the last (see the module).
        ``surface`` (K, 3): where the pre-pass saw the glass on each (``GlassSet.trace``)."""
        origins, directions = view.pixel_rays(pixels)
        world = np.asarray(world, dtype=np.float64)[:4]
        paths = self.glass.trace(origins, directions, near_surface=surface)
        self.nested = tuple(self.glass.glasses[k].name for k in np.unique(paths.history[paths.nested, 0]))
        color = self.leaving_colors(paths, world, max_order)
        met = np.flatnonzero(self.glass.reflecting(paths.history[:, 0]))
        if len(met):
            normal = paths.first_normal[met]
            share = fresnel_dielectric(-np.einsum("ij,ij->i", directions[met], normal),
                                       1.0 / self.glass.iors[paths.history[met, 0]])
            mirrored = reflect(directions[met], normal)
            reflected = self._through_glass(paths.first_position[met] + self._nudge * mirrored, mirrored, max_order,
                                            world)
            color[met] = share[:, None] * reflected + (1.0 - share[:, None]) * color[met]
        return color

    @property
    def _nudge(self) -> float:
        """How far a reflected ray starts off the glass, so as not to meet it again."""
        return 1e-9 * self.glass.surfaces.scale

    def leaving_colors(self, paths, world, max_order: int) -> np.ndarray:
        """(K, 3) what the rays of ``paths`` show once they leave the glass, with the ray
        reflected back inside at their last interface mixed in by its Fresnel
        reflectance (followed until it leaves in turn, once)."""
        color = self._met(paths, max_order, world)
        out = np.flatnonzero(self.glass.reflecting(paths.exit_glass) & ~paths.trapped)
        if len(out):
            incoming, normal, glass = paths.exit_incoming[out], paths.exit_normal[out], paths.exit_glass[out]
            share = fresnel_dielectric(-np.einsum("ij,ij->i", incoming, normal), self.glass.iors[glass])
            inside = reflect(incoming, normal)
            back = self._through_glass(paths.exit_position[out] + self._nudge * inside, inside, max_order, world,
                                       media=glass)
            color[out] = share[:, None] * back + (1.0 - share[:, None]) * color[out]
        return color

    def _through_glass(self, origins, directions, max_order: int, world, media=None) -> np.ndarray:
        """(K, 3) what rays show followed through the glass (starting in ``media``, as
        ``GlassSet.trace``) and then met with the scene; black where a ray stays in glass,
        or, starting in it, never leaves it."""
        paths = self.glass.trace(origins, directions, media=media)
        color = self._met(paths, max_order, world)
        if media is not None:
            color[paths.exit_glass < 0] = 0.0
        return color

    def _met(self, paths, max_order: int, world) -> np.ndarray:
        """(K, 3) what the last segments of ``paths`` meet in the scene, black where the
        path is trapped in glass or reflected totally inside glass that does not reflect
        (a Refraction BSDF: that light is lost, as Cycles renders it)."""
        color = self.tracer.trace_rays(paths.origin, paths.direction, max_order, world)[:, :3]
        lost = (paths.total_reflections > 0) & ~self.glass.reflecting(paths.history[:, 0])
        color[lost | paths.trapped] = 0.0
        return color


def glass_layer(previous: GlassLayer | None, captured, key: tuple, world=(0.0, 0.0, 0.0, 1.0),
                accuracy_px: float = 1.0, searched: bool = True, max_order: int = 1) -> GlassLayer | None:
    """The glass of ``captured`` (``None`` without any): ``previous`` while its ``key``
    holds (the capture's, ``frame_pipeline.captured_key``, with each glass's name, index
    of refraction and whether it reflects, the ``world`` colour, the Accuracy and the
    scene's Max Order, the mirror reflections a ray through glass follows).

    Its renderer holds the glass as its reflectors and every other surface as meshes, and
    traces every glass pixel on the GPU (:func:`glass_renderer`). Where the meshes have
    more image textures than the trace samples, it draws each convex glass solid by the
    refraction search instead, with ``searched`` (the live view; Render Image traces that
    glass on the CPU, and the renderer only finds it on screen)."""
    if not captured.glass:
        return None
    world = tuple(float(c) for c in world)[:3]
    key = key + tuple((glass.name, glass.ior, glass.reflects) for glass in captured.glass) + (
        world, accuracy_px, searched, max_order)
    if previous is not None and previous.key == key:
        return previous
    names = {glass.name for glass in captured.glass}
    meshes = [mesh for mesh in captured.meshes if mesh.name not in names]
    traced = samples_every_image(meshes)
    searches = ([prepared_search(glass, index, accuracy_px) for index, glass in enumerate(captured.glass)]
                if searched and not traced else [])
    methods = [method for method, _ in searches if method is not None]
    renderer = glass_renderer(captured.glass, meshes, methods, world, traced=traced, mirrors=captured.reflectors,
                              max_order=max_order)
    unsearched = {glass.name: reason for glass, (method, reason) in zip(captured.glass, searches) if method is None}
    return GlassLayer(key, GlassSet(list(captured.glass)), renderer, BandTracer(captured.reflectors, meshes),
                      traced=traced, unsearched=unsearched,
                      mirror=glass_mirror(captured.glass, meshes + _solids(captured.reflectors), methods, world))


def glass_mirror(glasses, meshes, methods, world=(0.0, 0.0, 0.0)) -> ReflectionRenderer | None:
    """The renderer of ``glasses`` as perfect mirrors reflecting ``meshes``, each searched
    one (``methods``) that reflects (a Glass BSDF) by the iterative search on its cube
    map (Roger & Holzschuch 2006: convex glass is star-shaped), the others showing the
    ``world`` colour: what the live view shows beneath the refraction search's images,
    weighed by the Fresnel reflectance (:meth:`GlassLayer.draw`). None without such glass."""
    searched = [IterativeReflector(method.index, method.name, method.reflector_map, method.accuracy_px)
                for method in methods if method.reflects]
    if not searched:
        return None
    count = len(glasses)
    return ReflectionRenderer([glass.surface for glass in glasses], meshes,
                              reflector_colors=np.tile(world, (count, 1)).astype(np.float32),
                              reflectivity=np.ones(count, np.float32), passes=(IterativePass.factory(searched),))


def glass_renderer(glasses, meshes, methods=(), world=(0.0, 0.0, 0.0),
                   edge_fraction: float | None = subdivision.EDGE_FRACTION, traced: bool = True, mirrors=(),
                   max_order: int = 1) -> ReflectionRenderer:
    """The renderer of ``glasses`` (``engine.glass.Glass`` each) as its reflectors and
    ``meshes``: with ``traced``, each glass pixel ray traced on the GPU
    (``drawing/methods/glass_trace.py``, mirrors reflecting ``max_order`` times at most); else
    through the searched glass (``methods``, ``refraction_search.RefractedGlass`` each)
    the refraction search's images, weighed by 1 minus each glass's exact Fresnel
    reflectance (from its IOR; none for glass that does not reflect) over the ``world``
    colour, or over what its :class:`GlassLayer.draw` puts beneath. ``edge_fraction`` as
    ``ReflectionRenderer``'s. ``mirrors`` (``engine.Reflector`` each) are drawn as solid
    meshes (in front of glass they hide it)."""
    count = len(glasses)
    iors = np.array([glass.ior for glass in glasses], dtype=np.float64)
    f0 = np.where([glass.reflects for glass in glasses], ((iors - 1.0) / (iors + 1.0)) ** 2, np.nan)
    if traced:
        passes = (GlassTracePass.factory(glasses, TracedScene(world, frozenset(m.name for m in mirrors), max_order)),)
    else:
        passes = (RefractionPass.factory(methods),) if methods else ()
    return ReflectionRenderer([glass.surface for glass in glasses], list(meshes) + _solids(mirrors),
                              edge_fraction=edge_fraction,
                              reflector_colors=np.tile(world, (count, 1)).astype(np.float32),
                              reflectivity=np.ones(count, np.float32), fresnel_f0=f0.astype(np.float32),
                              transmits=np.ones(count, bool), attenuation_distance=np.zeros(count, np.float32),
                              passes=passes)


def prepared_search(glass, index: int, accuracy_px: float) -> tuple:
    """(``refraction_search.RefractedGlass`` or None, the reason it has none) of one
    glass object, the ``index``-th of the scene's glass: its map from the cache the
    mirrors' searches use (made once per shape, on the GPU when it is ready)."""
    shape, reflector_map = star_maps.star_map(glass.surface)
    return refracted_glass(glass, index, shape, reflector_map, accuracy_px)


def _solids(mirrors) -> list:
    """Mirrors as grey solid meshes (what the glass's pre-pass needs of them: their depth;
    the trace reflects off them by name)."""
    return [DiffuseMesh(mirror.name, mirror.vertices, mirror.triangles,
                        np.full((len(mirror.vertices), 4), 0.5, np.float32), normals=mirror.normals)
            for mirror in mirrors]


def over(image: np.ndarray | None, glass_image: np.ndarray, in_front: np.ndarray) -> np.ndarray:
    """The frame with the glass's pixels from ``glass_image`` (the glass's frame alone
    where there is no other)."""
    if image is None:
        return glass_image
    return np.where(in_front[..., None], glass_image, image)
