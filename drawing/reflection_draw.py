# SPDX-License-Identifier: GPL-3.0-or-later
"""Drawing curved reflections: the scene, its reflected meshes, and their composite.

SBC paper (Popescu, Sacks, Mei 2006), section V: a reflection is drawn for every
diffuse mesh in every reflection group by projecting the mesh's vertices with the
sample-based camera on the GPU and rasterising the reflected ("virtual") triangles.
Three passes, all into float targets of the view's size:

1. **Pre-pass** (visibility case 1 of SBC V-A): every diffuse mesh and every reflector
   with the depth test, into a colour target (diffuse meshes shaded as their
   reflections are, below, with the desired view's eye vector; reflectors at their own
   colour) and a label target (id, reflection weight, attenuation distance): id 0 for
   diffuse meshes (and nothing), reflector index + 1 for reflectors. Blender's Python
   ``gpu`` module has no stencil, so the id texture plays the stencil of Roger &
   Holzschuch 2006, section 3.3.6. The weight is the reflectivity, times Schlick's
   Fresnel term where the reflector asks for it (SBC V-D). A viewport overlay
   (:meth:`ReflectionRenderer.draw` with ``reflectors_only``) draws the reflectors alone:
   Blender has drawn the scene already, and its depth, in the framebuffer the overlay is
   drawn into, hides the composite where an object stands in front of a mirror.
2. **Reflections**: the reflected ("virtual") meshes, each vertex placed where the view
   sees its first reflector point, with the depth of SBC V-A (k - 1 + z / D) g for
   order k and distance z along the reflected ray (lower orders before higher ones, the
   nearer point within an order). Every method is a pass (:mod:`.frame_pass`), any mix
   of them per reflector, drawn in order:

   a. the *sample-based camera* (SBC IV, :mod:`.methods.camera_pass`): its reflected
      triangles are made **once per camera** (:mod:`.methods.sbc_triangles`, kept) and
      drawn every frame with ``glsl/reflection_mesh_vert.glsl``; in the camera's own
      view exactly at its projected pixels. From a moved view (a new camera still
      building) the reflection stays on the mirror in world space, nearly right,
      instead of lagging as pixels of the old view;
   b. the *per-frame passes*: the iterative search (:mod:`.methods.iterative_draw`), the
      morphing grids (:mod:`.methods.morph_pass`) and perturbation
      (:mod:`.methods.perturbation_pass`) answer every vertex on the GPU each frame, and
      :mod:`.reflected_meshes` draws the meshes at their answers.

   The fragment stage keeps only pixels whose pre-pass id is the vertex's first
   reflector (history[0] + 1): reflections stay inside the visible footprint of their
   reflector, and real objects in front of a mirror stay in front.

   Shading (SBC V-C, ``glsl/reflection_shading.glsl``): a reflected vertex keeps its
   mesh's colour, normal and UVs (times the mesh's image texture, if any); emission
   is shown unlit, anything else is lit by a headlight along the *true* eye vector,
   from the vertex toward its reflector point: ambient + Lambert, two-sided.
3. **Composite** (SBC V-D): on reflector pixels, the traced or else the drawn reflection,
   faded toward the world colour by min(1, (d / A)^2) for its distance d from the mirror
   along the reflected ray when the reflector has a fade distance A, else the world
   colour; black where the pre-pass saw a sealed mirror's inner side (the view ray starts
   inside a closed mirror that holds nothing, the clip start cutting into it, and meets
   no light: as Cycles renders it; such pixels are never traced); mixed with the
   reflector's own colour by the reflection weight (1 = perfect mirror); elsewhere the
   pre-pass colour (or nothing, for a viewport overlay: ``reflectors_only``, whose mirror
   pixels are depth-tested against the scene's depth at their own,
   :func:`screen_space.depth_bias`).

The sample-based camera cannot place a reflection in the last ray-map cell before a
footprint's edge (the silhouette, or an object in front of the mirror), nor between
ray-map cells of different reflection histories inside a footprint (where another
mirror's reflection begins): a projection needs four neighbouring rays of one group.
:meth:`ReflectionRenderer.render` ray traces those pixels on the CPU (:mod:`..engine.geometry.band_trace`,
shaded alike), and every pixel where the camera knows it is unreliable (a traced colour
wins); :meth:`ReflectionRenderer.draw` (for a viewport) fills the band from the nearest
reflected pixel instead. ``trace_edges`` traces every pixel next to a drawn reflection too.

Drawn from a view other than the camera's, the cached reflection is exact only at the
reflector points: a reflected triangle is interpolated affinely between them (as in the
camera's view), the reflection does not slide over the mirror as a new camera would
make it (until that camera lands), and a triangle with a reflector point behind the
view is dropped.

Not done: creases of a reflector (a lid's rim) can leave a line of pixels without (or
with a wrong) reflection, where the engine's rays straddle the crease; for reflections of
order k > 1 the eye vector of lighting runs to the first reflector point, not the last.

:class:`ReflectionRenderer` holds one scene's geometry (subdivided once), its GPU
batches and its passes (the last cameras' reflected triangles kept); :meth:`ReflectionRenderer.draw`
draws any view with any sample-based camera of it and composites into the framebuffer
that is bound, so a viewport draw handler can call it with the region's matrices
(``blender.capture.view_from_region``); :meth:`ReflectionRenderer.render` draws
offscreen and reads the image back.

Shaders: :mod:`.draw_shaders`; the arrays drawn: :mod:`.draw_geometry`.
"""

from __future__ import annotations

import functools
import time

import gpu
import numpy as np

from ..engine.geometry import band_trace, subdivision
from ..engine.frame_settings import FrameSettings
from ..engine.geometry.closed_surfaces import ConvexMirrors
from ..engine.heap import release_freed_memory
from . import draw_shaders
from .draw_geometry import prepare_geometry
from .frame_pass import Frame, PassInputs
from .frame_targets import FrameTargets
from .gpu_data import data_texture, read_depth, read_texture, saved_state, vertex_buffer
from .reflected_meshes import AnswerSet, ReflectedMeshes
from .traced_pixels import traced_rgba, traced_texture
from .screen_space import (FULL_SCREEN, box_corners, box_on_screen, camera_position, depth_bias, pixel_box,
                           view_projection)
from .methods.camera_pass import CameraPass
from .methods.sbc_triangles import MIXED_SUBDIVISIONS, CameraTriangleMaker

#: A bare renderer's settings (tests, benchmarks): the per-frame passes to half a pixel,
#: a camera's answers polished, each frame's blend not.
PLAIN_SETTINGS = FrameSettings(accuracy_px=0.5, polish_frames=False)
#: A render traces the band along the mirrors' edges that no reflection reached; where
#: that "band" is more than this share of the image (the camera's near plane cutting a
#: mirror, the eye on its surface), it is filled by the composite instead of traced, so
#: that no view costs many times an ordinary one (the demo scenes trace 1-9 %).
MAX_TRACED_FRACTION = 0.25
#: A render traces the pixels of a searched mirror (the iterative search) that got no
#: reflection within this many pixels of its silhouette or, on a non-convex mirror or
#: with other mirrors in the scene, of a drawn reflection.
SEARCHED_BAND_PX = 2
#: A render traces the pixels of a searched mirror that folds its reflections which got
#: no reflection but lie inside its drawn reflections (``band_trace.hole_pixels``): a hole
#: up to twice this across, where a fold dropped the triangles of an image (a corner's
#: image missed, or the law of reflection failing across the fold).
FOLD_HOLE_PX = 8
#: A render also traces the pixels of a mirror drawn from its morphing grid that got no
#: reflection within this many pixels both of its silhouette and of a drawn reflection
#: (``band_trace.rim_gap_pixels``): near the silhouette not every node of the eye's cell
#: sees the mirror, and the blend leaves a strip there (sbc_fig3's floor along the ball's
#: lower rim at 480x320, up to 6 pixels wide: 1 % of the mirror's pixels on frame 12 of
#: docs/benchmarks/morph_animation.md).
RIM_GAP_PX = 6


def _showing(labels: np.ndarray, reflectors) -> np.ndarray:
    """(H, W) bool: the pixels whose pre-pass id (``labels``: reflector index + 1, 0 for
    none) is one of ``reflectors``."""
    return np.isin(np.rint(labels) - 1, list(reflectors))


def _scissor_set(box: tuple | None) -> None:
    """The bound framebuffer's scissor (Blender keeps it per framebuffer): ``box`` (x, y,
    width, height), or none."""
    gpu.state.scissor_test_set(box is not None)
    if box is not None:
        gpu.state.scissor_set(*box)


def _rgba(color) -> tuple:
    values = tuple(float(c) for c in color)[:4]
    return values + (1.0,) * (4 - len(values))



class ReflectionRenderer:
    """One scene's reflected geometry and GPU batches; draws it for any view and camera.

    Build it once per scene change (subdivision runs here, once per mesh). Its
    :attr:`passes` draw the reflections (:mod:`.frame_pass`'s protocol): first the
    sample-based camera's (:attr:`camera_pass`, whose reflected triangles are made once
    per camera and kept), then the per-frame passes'. :meth:`draw` or :meth:`render`
    draws any view with any camera of it. ``cull``: project in each
    sheet only the vertex chunks that meet the sheet's k-DOP
    (``engine/methods/sbc/sheet_bounds.py``; needs the camera itself, not only its
    textures). ``settings`` (:class:`~..engine.frame_settings.FrameSettings`): with
    ``polish_camera`` the GPU's ray-list and fold-cell answers are polished on the true
    rays on the CPU (needs the camera too; exact, but the numpy BVH makes it seconds per
    camera: the live viewport turns it off); the passes read the rest. ``passes``: the
    factories of the per-frame passes (``MethodPlan.pass_factories``: the iterative
    search, the baked grids, perturbation, any registered method), each called once with
    the renderer's :class:`.frame_pass.PassInputs`; a camera's sheets of the first-order
    reflections they draw in its view are not projected, and where they draw every
    reflector the renderer draws with no camera at all. ``transmits`` (R,) bool: the
    reflector is glass, its drawn image the refracted one, weighed by 1 minus its
    Fresnel term (``draw_geometry.prepare_geometry``). ``glasses``: the scene's glass
    among ``meshes`` (``engine.glass.Glass`` each), which a trace's rays refract through.
    """

    def __init__(self, reflectors, meshes, reflector_colors=None, reflectivity=None,
                 edge_fraction: float | None = subdivision.EDGE_FRACTION, *, fresnel_f0=None,
                 attenuation_distance=None, mixed_subdivisions: int = MIXED_SUBDIVISIONS, cull: bool = True,
                 passes=(), settings: FrameSettings = PLAIN_SETTINGS, reflector_set=None, transmits=None, glasses=()):
        self.geometry = prepare_geometry(reflectors, meshes, reflector_colors, reflectivity, edge_fraction,
                                         fresnel_f0, attenuation_distance,
                                         None if reflector_set is None else reflector_set.sealed, transmits)
        self.settings = settings
        #: The diffuse meshes on the GPU, placed by the per-frame passes' answers.
        self.meshes = ReflectedMeshes(self.geometry)
        self.convex_mirrors = convex = ConvexMirrors(reflectors)  # tested once, for every pass
        inputs = PassInputs(self.geometry, self.meshes, tuple(reflectors), reflector_set, convex, settings,
                            tuple(meshes), tuple(glasses))
        per_frame = tuple(make(inputs) for make in passes)
        self.stats = dict(self.geometry.stats)
        self.counts = {"projections": 0, "frames": 0}
        # The per-frame passes, not a bound method: no reference cycle keeps a finished
        # render (a gigabyte for a million-triangle mirror) alive until a full collection.
        maker = CameraTriangleMaker(self.geometry, functools.partial(_drawn_by, per_frame), self.counts,
                                    mixed_subdivisions, cull, settings.polish_camera, convex)
        #: The sample-based camera's pass: its reflected triangles, made once per camera.
        self.camera_pass = CameraPass(maker, len(reflectors))
        #: Every pass (:class:`.frame_pass.FramePass`), in drawing order: the camera's,
        #: then those the factories ``passes`` made (``MethodPlan.pass_factories``).
        self.passes = (self.camera_pass,) + per_frame
        self._batches = None
        self._targets = None
        #: The reflectors and meshes ray traced together, made on first use (with the
        #: mirrors' ray-tracing set when the caller has one: the tracer shares it).
        self.tracer_source = band_trace.TracerSource(reflectors, meshes, reflector_set)

    def _make_batches(self) -> dict:
        """Vertex buffers of the pre-pass and of the full-screen triangle, and the images."""
        g = self.geometry
        batches = {}
        if len(g.prepass_triangles):
            # Made for the upload and let go: the GPU keeps the vertex buffer's copy.
            arrays = g.prepass_arrays()
            positions = arrays["positions"]
            buffer = vertex_buffer({"position": (positions, 'F32', 'FLOAT'),
                                     "color": (arrays.pop("colors"), 'F32', 'FLOAT'),
                                     "label": (arrays.pop("labels"), 'F32', 'FLOAT'),
                                     "normal_lit": (arrays.pop("normals"), 'F32', 'FLOAT'),
                                     "uv": (arrays.pop("uvs"), 'F32', 'FLOAT')})
            del arrays
            batches["prepass"] = [
                (image, gpu.types.GPUBatch(type='TRIS', buf=buffer, elem=gpu.types.GPUIndexBuf(
                    type='TRIS', seq=g.prepass_triangles[first:first + count])))
                for image, first, count in g.prepass_ranges]
            # The reflectors alone (label id > 0, no image): a viewport's pre-pass, its
            # index buffer made on first use (:meth:`_mirror_batches`; Render Image never
            # draws it: a million-triangle mirror's second copy of its triangles).
            batches["prepass_buffer"] = buffer
            # Their box: of the vertices their triangles use (not a (3T, 3) gather of corners).
            used = np.zeros(len(positions), dtype=bool)
            used[g.prepass_mirror_triangles.reshape(-1)] = True
            batches["mirror_box"] = box_corners(positions[used])
        batches["images"] = [data_texture(image, image.shape[1]) for image in g.images]
        batches["no_image"] = data_texture(np.ones((1, 4)))
        square = np.array([[0, 0], [1, 0], [1, 1], [0, 0], [1, 1], [0, 1]], np.float32)
        batches["screen"] = gpu.types.GPUBatch(type='TRIS', buf=vertex_buffer({"position": (square, 'F32', 'FLOAT')}))
        release_freed_memory()  # the pre-pass arrays, now on the GPU
        return batches

    def _mirror_batches(self) -> list:
        """The pre-pass's reflectors alone, as (image, batch) pairs (made on first use)."""
        batches, g = self._batches, self.geometry
        if "prepass_mirrors" not in batches:
            mirrors = g.prepass_mirror_triangles
            batches["prepass_mirrors"] = [(-1, gpu.types.GPUBatch(
                type='TRIS', buf=batches["prepass_buffer"], elem=gpu.types.GPUIndexBuf(type='TRIS', seq=mirrors)))
            ] if len(mirrors) else []
        return batches["prepass_mirrors"]

    def _image(self, index: int):
        return self._batches["images"][index] if index >= 0 else self._batches["no_image"]

    def targets(self, width: int, height: int) -> FrameTargets:
        """The frame targets for this size, reused while they fit."""
        if self._targets is None or not self._targets.fits(width, height):
            self._targets = FrameTargets(width, height)
        return self._targets

    def pass_named(self, name: str):
        """The per-frame pass called ``name`` (``FramePass.name``), or None."""
        return next((frame_pass for frame_pass in self.passes if frame_pass.name == name), None)

    def per_frame_reflectors(self, view) -> frozenset:
        """The reflectors whose first-order reflections of ``view`` the per-frame passes
        draw: the searched ones, and those whose grid covers the view."""
        return _drawn_by(self.passes, view)

    @property
    def band_tracer(self) -> band_trace.BandTracer:
        """The reflectors and meshes ray traced together (made on first use)."""
        return self.tracer_source.get()

    def invalidate(self) -> None:
        """Forget the cameras' reflected triangles: the next draw projects again."""
        self.camera_pass.invalidate()

    def draw(self, view, textures, world_color=(0.0, 0.0, 0.0, 1.0), reflectors_only: bool = False,
             fill_radius: int | None = None, camera=None, accuracy_px: float | None = None,
             traced=None, exact: bool = False, beneath=None) -> FrameTargets:
        """Pre-pass and reflections of ``view`` into the frame targets
        (:meth:`draw_passes`), then the composite into the framebuffer bound by the
        caller (:meth:`composite`). What a viewport draw handler calls, with the
        region's view (``blender.capture.view_from_region``); nothing is read back.

        ``textures`` is a sample-based camera as ``sbc_gpu.SBCTextures``, ``camera``
        the camera itself (optional; see :meth:`draw_passes`), ``accuracy_px`` the
        Accuracy it was built to (the viewport snaps its reflected triangles within it,
        see :meth:`draw_passes`; ``None``: placed exactly); ``world_color`` the
        linear RGB(A) that reflected rays leaving the scene show; ``fill_radius`` the
        composite's cheap fill of the band along a footprint's edge (``None``: the
        camera's down-sampling), where :meth:`render` traces instead; ``traced``
        (:class:`.traced_pixels.TracedPixels`) are drawn over the reflections where
        they were traced for this very view. ``exact``: nothing snaps (a resting view's
        draw, placed as a render places it). ``beneath``: a texture of the view's size
        whose colours the reflector pixels show beneath their reflections instead of the
        reflectors' own (what glass reflects beneath its refraction,
        ``blender/glass_layer.py``); default: a pass's (``targets.beneath``).

        ``reflectors_only`` (the viewport overlay): the pre-pass draws the reflectors
        alone, and the composite is depth-tested against the bound framebuffer's depth,
        which holds the scene as Blender drew it: what stands in front of a mirror hides
        its reflection there, and the scene is not drawn a second time.
        """
        if fill_radius is None:
            fill_radius = 0 if textures is None else textures.downsample
        targets = self.targets(view.width, view.height)
        rect = self.mirrors_rect(view, targets) if reflectors_only else FULL_SCREEN
        # The composite reads the targets up to fill_radius beyond its rectangle.
        scissor = pixel_box(rect, targets.width, targets.height, fill_radius + 1) if reflectors_only else None
        targets = self.draw_passes(view, textures, camera, warm=True, mirrors_only=reflectors_only,
                                   accuracy_px=accuracy_px, scissor=scissor, snap=not exact)
        targets.traced = traced.texture() if traced is not None and traced.view.same_as(view) else None
        x, y, width, height = gpu.state.viewport_get()
        # A viewport of the view's size is drawn into where it is; otherwise from (0, 0).
        origin = (x, y) if (width, height) == (targets.width, targets.height) else None
        self.composite(targets, world_color, reflectors_only, fill_radius, origin,
                       scene_depth=view if reflectors_only else None, rect=rect, beneath=beneath)
        return targets

    def mirrors_rect(self, view, targets: FrameTargets) -> tuple:
        """Where the mirrors can be on ``view``'s screen (:func:`screen_space.box_on_screen`
        of their bounding box): an overlay's composite draws nothing elsewhere, and on
        llvmpipe its full-screen pass cost as much as the plain draw of the scene."""
        if self._batches is None:
            self._batches = self._make_batches()
        return box_on_screen(self._batches.get("mirror_box", np.zeros((0, 4))), view, self.geometry.shift,
                             targets.width, targets.height)

    def draw_passes(self, view, textures, camera=None, warm: bool = False,
                    mirrors_only: bool = False, accuracy_px: float | None = None,
                    scissor: tuple | None = None, snap: bool = True) -> FrameTargets:
        """The pre-pass and every pass's reflections of ``view`` into its frame targets.

        One :class:`.frame_pass.Frame` goes to every pass in order. The camera's pass
        draws the reflected triangles of ``textures`` (a projection source; ``None``: no
        camera), made the first time these textures are drawn, in the camera's own view:
        ``camera.ray_map.view`` when the camera is given, else the source's. A ``view``
        other than the camera's (the viewport moved, a new camera is being built) draws
        their first reflector points where ``view`` sees them. The per-frame passes
        answer for ``view`` itself; ``warm`` starts each vertex from its last answer and
        snaps the passes' reflected vertices to a grid within their Accuracy unless not
        ``snap`` (the viewport's :meth:`draw` does; a render does not, so that its image
        depends on its view alone and is placed exactly).
        ``mirrors_only``: the pre-pass draws the reflectors alone, not the diffuse meshes
        (a viewport overlay, whose composite the scene's own depth hides where something
        stands in front of a mirror); their pixels then keep the reflectors' labels
        there, and the reflections drawn behind an object are hidden by that test.
        ``accuracy_px`` with ``warm``: the camera's reflected triangles snap to a grid
        of :data:`.reflected_meshes.SNAP_SHARE` times it, as the per-frame passes' do (a
        triangle within one cell has no area and is dropped before set-up: on sbc_fig3,
        whose 57k reflected triangles fill about 22k pixels, that halves their cost).
        ``scissor``: (x, y, width, height), the only pixels cleared and drawn (an
        overlay's, around its mirrors; the rest of the targets keeps old values).
        """
        if self._batches is None:
            self._batches = self._make_batches()
        batches, g = self._batches, self.geometry
        targets = self.targets(view.width, view.height)
        width, height = targets.width, targets.height
        targets.beneath = None  # until a pass makes this frame's
        frame = Frame(view, targets, view_projection(view, g.shift), self._image, warm, accuracy_px, snap,
                      textures, camera)
        with saved_state():
            gpu.state.blend_set('NONE')
            gpu.state.face_culling_set('NONE')  # mirrors are two-sided; reflections flip winding
            with targets.prepass.bind():
                gpu.state.viewport_set(0, 0, width, height)
                _scissor_set(scissor)
                targets.prepass.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
                if "prepass" in batches:
                    gpu.state.depth_test_set('LESS_EQUAL')
                    gpu.state.depth_mask_set(True)
                    shader = draw_shaders.shader("prepass")
                    shader.bind()
                    shader.uniform_float("view_projection", frame.world_to_clip)
                    shader.uniform_float("camera", camera_position(view, g.shift))
                    for image, batch in self._mirror_batches() if mirrors_only else batches["prepass"]:
                        shader.uniform_int("use_image", int(image >= 0))
                        shader.uniform_sampler("image", self._image(image))
                        batch.draw(shader)
            for frame_pass in self.passes:  # each skips the reflectors an earlier one claimed
                frame_pass.update(frame)
                frame = frame.claiming(frame_pass.claims())
            self.stats.update(self.camera_pass.frame_stats())
            with targets.reflection.bind():
                gpu.state.viewport_set(0, 0, width, height)
                _scissor_set(scissor)
                targets.reflection.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
                gpu.state.depth_test_set('LESS')
                gpu.state.depth_mask_set(True)
                for frame_pass in self.passes:
                    frame_pass.draw(frame)
        self.counts["frames"] += 1
        targets.traced, targets.box = None, scissor
        return targets

    def answered(self) -> dict:
        """{reflector index: (K, N, 3)}: the first reflector points (world space, NaN where
        none) of every vertex in the last frame's per-frame passes (iterative search,
        baked grids, perturbation), one row per image slot, read back from the GPU: what
        the live view's accuracy check (``engine/spot_check.py``) measures."""
        found: dict = {}
        for answer in self._answers():
            answer = AnswerSet(*answer)
            found.setdefault(answer.reflector_index, []).extend(
                points for points, _ in self.meshes.read_slots(answer.texture))
        return {index: np.stack(slots) for index, slots in found.items()}

    def _answers(self) -> list:
        return [answer for frame_pass in self.passes for answer in frame_pass.answers()]

    def _reflectors_of(self, kind) -> list:
        """The union over the passes of one of their :class:`.frame_pass.FramePass` lists
        (``kind``: the pass -> its list)."""
        return [index for frame_pass in self.passes for index in kind(frame_pass)]

    def composite(self, targets: FrameTargets, world_color=(0.0, 0.0, 0.0, 1.0), reflectors_only: bool = False,
                  fill_radius: int = 0, origin=None, scene_depth=None, rect=None, beneath=None) -> None:
        """The composite of the frame targets into the framebuffer bound by the caller;
        traced band colours (``targets.traced``, see :meth:`trace_band`) when present.

        ``origin``: the framebuffer pixel of the view's corner when the caller's viewport
        (left as it is) already covers the view; ``None`` draws at (0, 0).
        ``scene_depth``: the view whose scene the bound framebuffer's depth holds (a
        viewport's, as Blender drew it); each mirror pixel is then drawn at its pre-pass
        depth, brought nearer by :data:`screen_space.SCENE_DEPTH_BIAS` of its distance
        (:func:`depth_bias`), with the depth test (depth writes off): hidden where the
        scene has a nearer surface. ``rect``: the part of the view drawn (normalised
        device coordinates, :meth:`mirrors_rect`; ``None``: all of it). ``beneath``: the
        colours the reflector pixels show beneath their reflections (:meth:`draw`);
        default: a pass's (``targets.beneath``), else the pre-pass's."""
        if beneath is None:
            beneath = targets.prepass_colors if targets.beneath is None else targets.beneath
        if self._batches is None:
            self._batches = self._make_batches()
        with saved_state():
            gpu.state.blend_set('NONE')
            gpu.state.depth_test_set('LESS_EQUAL' if scene_depth is not None else 'NONE')
            gpu.state.depth_mask_set(False)
            if origin is None:
                gpu.state.viewport_set(0, 0, targets.width, targets.height)
                origin = (0, 0)
            shader = draw_shaders.shader("composite")
            shader.bind()
            world = tuple(float(c) for c in world_color)[:4]
            shader.uniform_float("world_color", world + (1.0,) * (4 - len(world)))
            shader.uniform_float("rect", tuple(float(v) for v in (FULL_SCREEN if rect is None else rect)))
            shader.uniform_int("reflectors_only", int(bool(reflectors_only)))
            shader.uniform_int("fill_radius", max(0, int(fill_radius)))
            shader.uniform_int("origin", (int(origin[0]), int(origin[1])))
            shader.uniform_sampler("prepass_colors", targets.prepass_colors)
            shader.uniform_sampler("beneath_colors", beneath)
            shader.uniform_sampler("prepass_labels", targets.prepass_labels)
            shader.uniform_sampler("reflection_colors", targets.reflection_colors)
            shader.uniform_sampler("traced_colors", targets.traced if targets.traced is not None else targets.no_trace)
            shader.uniform_sampler("prepass_depth", targets.prepass_depth)
            shader.uniform_sampler("prepass_normals", targets.prepass_normals)
            shader.uniform_float("depth_bias", (0.0, 0.0) if scene_depth is None else depth_bias(scene_depth))
            self._batches["screen"].draw(shader)

    def trace_band(self, view, targets: FrameTargets, max_order: int, world_color, radius: int,
                   edges_of_drawn: bool = False, ray_map=None, camera=None, holes_of=()) -> int:
        """Trace the pixels :meth:`band_selection` picks on the CPU and upload their
        colours for the composite (``targets.traced``; it stays None where the selection
        is not a band). Returns how many pixels were traced."""
        selection = self.band_selection(view, targets, max_order, radius, edges_of_drawn, ray_map, camera, holes_of)
        if selection is None:
            targets.traced = None
            return 0
        pixels, surface = selection
        rgba = traced_rgba(self.band_tracer, view, pixels, max_order, _rgba(world_color), surface)
        targets.traced = traced_texture(targets.width, targets.height, pixels, rgba)
        return int(len(pixels))

    def band_selection(self, view, targets: FrameTargets, max_order: int, radius: int, edges_of_drawn: bool = False,
                       ray_map=None, camera=None, holes_of=()) -> tuple | None:
        """The reflector pixels of the last frame drawn into ``targets`` that are traced
        (:mod:`..engine.geometry.band_trace`), and where the pre-pass saw the mirror on
        each: ((K, 2) int x, y, (K, 3) world points), or None. Reads the pre-pass ids and
        the reflection coverage back (GPU, main thread); the tracing itself is numpy.

        The band along each footprint's edge that got no reflection. With the camera's
        ``ray_map``, also the pixels between ray-map cells of different histories
        (:func:`band_trace.history_boundary`: the edge of a second-order reflection inside
        a footprint). With the ``camera`` itself, also every pixel in cells where its
        projection is unreliable (:func:`band_trace.unreliable_cells`), drawn ones only
        while the budget allows (:func:`band_trace.drawn_pixels_in`). ``holes_of``:
        reflector indices (drawn from morphing grids) every pixel of which without a
        drawn reflection is traced: where the blend has no answer, but also where the
        mirror shows the world, so it costs many rays.
        More than :data:`MAX_TRACED_FRACTION` of the image is not a band: then None
        (``stats["untraced_pixels"]``: the composite fills), except for ``holes_of``,
        which the caller asked for. Pixels outside the frame's box (an overlay's
        scissor, :attr:`FrameTargets.box`) hold an older frame and are never picked."""
        size = (targets.width, targets.height)
        labels = np.where(targets.outside_box(), 0.0, read_texture(targets.prepass_labels, *size)[..., 0])
        searched = _showing(labels, self._reflectors_of(lambda p: p.searched_reflectors))
        drawn = read_texture(targets.reflection_colors, *size)[..., 3] > 0.5
        # The searched reflectors' pixels are traced by their own rule, below.
        searched_labels, labels = np.where(searched, labels, 0.0), np.where(searched, 0.0, labels)
        boundary = None if ray_map is None else band_trace.history_boundary(ray_map, *size, max_order)
        doubtful = np.zeros((0, 2), np.int64)  # drawn pixels where the camera's answers are doubtful
        if camera is not None:
            # Cells where the camera knows it may not project (ray lists, folds, mixed).
            unreliable = band_trace.unreliable_pixels(camera, *size)
            boundary = unreliable if boundary is None else boundary | unreliable
            doubtful = band_trace.drawn_pixels_in(labels, drawn, unreliable)
        pixels = band_trace.band_pixels(labels, drawn, radius, edges_of_drawn, boundary)
        if len(holes_of):  # every pixel of these mirrors without a reflection, searched ones too
            rows, columns = np.nonzero(_showing(labels + searched_labels, holes_of) & ~drawn)
            pixels = np.unique(np.concatenate([pixels, np.stack([columns, rows], axis=1)]), axis=0)
        if searched.any():
            # The search reaches a mirror's silhouette, but vertices go unanswered there;
            # on a non-convex mirror also where a fold crowds several images (and triangles
            # across a fold are dropped), and with other mirrors where their reflection (a
            # higher order) begins. The pixels without a reflection next to the
            # silhouette, and in those two cases next to a drawn reflection or enclosed by
            # drawn reflections, are traced (the others show the world).
            # A blended mirror's reflection also stops short of the silhouette where not
            # every node of the eye's cell sees the mirror: the strip between the two is
            # traced, wider (the pixels farther from a drawn reflection show the world).
            reach = max(radius, SEARCHED_BAND_PX)
            folded = _showing(searched_labels, self._reflectors_of(lambda p: p.folded_reflectors))
            blended = _showing(searched_labels, self._reflectors_of(lambda p: p.gap_reflectors))
            pixels = np.unique(np.concatenate([
                pixels, band_trace.band_pixels(searched_labels, drawn, reach),
                band_trace.band_pixels(np.where(folded, searched_labels, 0.0), drawn, reach, edges_of_drawn=True),
                band_trace.hole_pixels(np.where(folded, searched_labels, 0.0), drawn, FOLD_HOLE_PX),
                band_trace.rim_gap_pixels(np.where(blended, searched_labels, 0.0), drawn, max(radius, RIM_GAP_PX))]),
                axis=0)
        # Pixels whose view ray starts inside a sealed mirror are black (the composite), not traced.
        inside = read_texture(targets.prepass_normals, *size)[..., 3] > 0.5
        pixels, doubtful = (p[~inside[p[:, 1], p[:, 0]]] for p in (pixels, doubtful))
        self.stats["untraced_pixels"] = 0
        if not len(holes_of) and len(pixels) > MAX_TRACED_FRACTION * targets.width * targets.height:
            # Not a band but most of the mirror (the near plane cutting it, the eye on it):
            # tracing it would cost many frames' time; the composite fills it instead.
            self.stats["untraced_pixels"] = int(len(pixels))
            return None
        if len(pixels) + len(doubtful) <= MAX_TRACED_FRACTION * targets.width * targets.height:
            pixels = np.concatenate([pixels, doubtful])  # distinct: band pixels have no reflection
        surface = view.window_points(pixels + 0.5, read_depth(targets.prepass, *size)[pixels[:, 1], pixels[:, 0]])
        return pixels, surface

    def render(self, view, camera=None, world_color=(0.0, 0.0, 0.0, 1.0), trace: bool = True,
               fill_radius: int | None = None, trace_edges: bool = False, trace_gaps: bool = False,
               source=None) -> np.ndarray:
        """Draw ``view`` offscreen and read it back: (H, W, 4) float32 linear RGBA, rows bottom to top.

        ``camera``: a ``SampleBasedCamera`` built for this view, or ``None`` when the
        per-frame passes draw every reflector; or, instead of a camera, ``source``:
        another projection source of this view (its GPU textures without the camera, the
        benchmarks' numpy morphing blend). With ``trace`` the band along each footprint's
        edge that the camera cannot reach (d pixels wide) is ray traced
        (:meth:`trace_band`; on a searched mirror, the pixels without a reflection within
        :data:`SEARCHED_BAND_PX` of its silhouette or, if it is not convex or not alone, of
        a drawn reflection), and with ``trace_gaps`` every pixel of a mirror drawn from its
        grid that the blend left without a reflection (exact there, but tens of thousands
        of rays a frame: the sky's pixels too); without, it gets the composite's fill
        (``fill_radius``, ``None``: d). With ``trace_edges`` also the reflector pixels
        within d of a drawn reflection that got none: seams and creases; exact there, but
        no longer a purely feed-forward image (15-18 % of the mirror pixels of the demo
        scenes are traced). With the ``camera``, the pixels between ray-map cells of
        different histories are traced too (:func:`band_trace.history_boundary`).
        """
        start = time.perf_counter()
        textures = source if camera is None else self.camera_pass.source_for(camera)
        uploaded = time.perf_counter()
        downsample = 0 if textures is None else textures.downsample
        targets = self.draw_passes(view, textures, camera)
        drawn = time.perf_counter()
        traced = 0
        morphed = self._reflectors_of(lambda p: p.gap_reflectors) if trace_gaps else []
        if trace and ((textures is not None and textures.groups) or morphed
                      or any(frame_pass.traces_band for frame_pass in self.passes)):
            max_order = max((len(h) for h in textures.groups), default=1) if textures is not None else 1
            traced = self.trace_band(view, targets, max_order, world_color, downsample, trace_edges,
                                     None if camera is None else camera.ray_map, camera, holes_of=morphed)
            fill_radius = 0 if targets.traced is not None else downsample
        elif fill_radius is None:
            fill_radius = downsample
        band = time.perf_counter()
        texture, framebuffer = targets.output
        with framebuffer.bind():
            self.composite(targets, world_color, False, fill_radius)
        image = read_texture(texture, targets.width, targets.height)
        end = time.perf_counter()
        for frame_pass in self.passes:
            self.stats.update(frame_pass.frame_stats())
        self.stats.update({"upload_seconds": uploaded - start, "pass_seconds": drawn - uploaded,
                           "band_seconds": band - drawn, "composite_seconds": end - band,
                           "draw_seconds": end - start, "traced_pixels": traced})
        return image


def _drawn_by(passes, view) -> frozenset:
    return frozenset().union(*(frame_pass.drawn_in(view) for frame_pass in passes))
