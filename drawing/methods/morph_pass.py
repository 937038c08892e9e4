# SPDX-License-Identifier: GPL-3.0-or-later
"""Reflection morphing every frame on the GPU (SBC paper VI).

Popescu, Sacks, Mei (2006), section VI: the projections of the scene's (static) vertices
by the panoramic sample-based cameras at the grid's nodes are computed once, and each
frame blends those of the four nodes of the tetrahedron holding the eye. Here that split
is literal:

- **once per node** (while the diffuse geometry and the reflector's rigid frame stay): a
  node's images of every vertex, its first :data:`SLOTS` regular ones and as many from
  its widened leaf charts (``MorphingGrid.node_slots``; the cube faces project on the
  GPU, ``morph_source.GPUFaceImages``), kept on the GPU as one texture per node
  (:class:`NodeTextures`, least recently used first out beyond a budget in MB); the
  nodes around the eye are projected ahead on a worker thread (:meth:`MorphPass.prefetch`,
  numpy) and uploaded when done (:meth:`MorphPass.collect`);
- **every frame**: where the eye is (``MorphingGrid.check_view``: a lookup in the grid),
  then one compute dispatch per grid (``glsl/morph_blend.glsl``, the float32 twin of
  ``MorphingGrid._matched_images`` and ``_blend``) matches and blends the four nodes'
  images and refines them on the local surface fitted to the images of every node of
  the tetrahedron's cube, into one answer texture per image slot,
  and the reflected meshes are drawn from those (``reflected_meshes.ReflectedMeshes``,
  as the iterative search's). Entering a tetrahedron whose nodes are on the GPU costs
  the CPU nothing but the uniforms; a node neither on the GPU nor prefetched is projected
  when first needed.
"""

from __future__ import annotations

import math
from collections import OrderedDict

import gpu
import numpy as np

from ...engine.methods.morphing import morph_grid, morph_surface, morphing
from ...engine.baking.bake_cache import CacheError
from ...engine.geometry.closed_surfaces import ConvexMirrors
from ...engine.frame_settings import DEFAULT_MORPH_BUDGET_MB
from ..frame_pass import Frame, FramePass, PassInputs
from ..gpu_data import data_texture
from ..reflected_meshes import FOUND_CODE, ReflectedMeshes
from ..shader_sources import glsl_source, normal_equations_glsl
from .polish_gpu import GPUImagePolish, polish_answers
from ..shader_cache import cached_shader

#: Image slots per vertex and grid: a convex mirror shows a point once, a concave one
#: two or three times.
SLOTS = 3
#: Invocations per work group of the blend (along x).
LOCAL_SIZE = 64
#: The float32 blend's bound on the reflection law's residual on the fitted surface (the
#: numpy twin asks 1e-8 of float64 Newton steps; float32 reaches about 1e-7).
SURFACE_RESIDUAL = 1e-5
#: A Newton step on the local surface shorter than this (in units of the nodes' images'
#: spread) ends the iteration: float32 resolves about 1e-7 of it, and the answer moves
#: by less than a millionth of the spread.
SURFACE_SETTLED = 1e-6
#: The per-frame parameters (``glsl/morph_blend.glsl``'s uniform block ``frame``), std140,
#: for a cell of NODES nodes: per node, its eye (xyz) and weight (w), then how many
#: regular (x) and widened-chart (y) image slots hold any image.
FRAME_STRUCT = """
struct MorphFrame {
  mat4 frame_from_shifted;
  mat4 shifted_from_frame;
  mat4 view_projection;
  vec4 eye_match;
  vec4 nodes[NODES];
  vec4 node_slots[NODES];
};
"""


def frame_floats(n_nodes: int) -> int:
    """Floats of one MorphFrame for cells of ``n_nodes`` nodes."""
    return 3 * 16 + 4 + 8 * n_nodes


def blend_defines(n_nodes: int = 4, regular: int = SLOTS, widened: int = SLOTS, blend_nodes: int = 4) -> dict:
    """The engine's constants, as the blend shader's ``#define`` s, for cells of
    ``n_nodes`` nodes, the first ``blend_nodes`` blended (``MorphingGrid.blend_nodes``:
    a tetrahedron of the SBC grid, 4, and up to 4 more of its cube for the surface fit; 8
    of 8: a cube of the octree grid) whose nodes fill at most ``regular`` and ``widened``
    image slots."""
    m = morph_surface
    return {"SLOTS": SLOTS, "REGULAR_SLOTS": regular, "WIDENED_SLOTS": widened, "NODES": n_nodes,
            "BLEND_NODES": min(blend_nodes, n_nodes),
            "PARTIAL_WEIGHT": f"{morphing.PARTIAL_WEIGHT:.9e}", "MATCH_SLOPE": f"{morphing.MATCH_SLOPE:.9e}",
            "SURFACE_NORMAL_MIN": f"{m.SURFACE_NORMAL_MIN:.9e}", "MIN_SURFACE_NODES": m.MIN_SURFACE_NODES,
            "SURFACE_ITERATIONS": m.SURFACE_ITERATIONS, "SURFACE_REACH": f"{m.SURFACE_REACH:.9e}",
            "SURFACE_RESIDUAL": f"{SURFACE_RESIDUAL:.9e}", "SURFACE_SETTLED": f"{SURFACE_SETTLED:.9e}",
            "FOUND_CODE": FOUND_CODE}


@cached_shader
def blend_shader(n_nodes: int = 4, regular: int = SLOTS, widened: int = SLOTS, blend_nodes: int = 4,
                 ridge: float = morph_surface.QUADRIC_RIDGE):
    """The compute shader of the blend for cells of ``n_nodes`` nodes, the first
    ``blend_nodes`` blended (:func:`blend_defines`), its surface fit held toward a sphere
    by ``ridge`` (``MorphingGrid.quadric_ridge``), that fill at most
    ``regular`` and ``widened`` image slots (1 to :data:`SLOTS`, 0 to :data:`SLOTS`),
    built on first use: llvmpipe pays for every loop iteration over slots, filled or not
    (``glsl/morph_blend.glsl``), so each pair gets its own (a convex mirror's cells use
    one or two of them)."""
    info = gpu.types.GPUShaderCreateInfo()
    info.push_constant('INT', "n_vertices")
    info.push_constant('INT', "positions_width")
    info.push_constant('INT', "slot_rows")
    info.typedef_source(FRAME_STRUCT.replace("NODES", str(n_nodes)))
    info.uniform_buf(0, "MorphFrame", "frame")
    info.sampler(0, 'FLOAT_2D', "vertex_positions")
    for n in range(n_nodes):
        info.sampler(1 + n, 'FLOAT_2D', f"node{n}")
    for k in range(SLOTS):
        info.image(k, 'RGBA32F', 'FLOAT_2D', f"result{k}", qualifiers={'WRITE'})
    info.local_group_size(LOCAL_SIZE, 1)
    info.compute_source(glsl_source("morph_blend.glsl", blend_defines(n_nodes, regular, widened, blend_nodes),
                                    normal_equations_glsl(9, morph_surface.sphere_prior(ridge))))
    return gpu.shader.create_from_info(info)


def _translation(offset) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, 3] = offset
    return matrix


def node_texels(slots: np.ndarray, width: int, rows: int) -> np.ndarray:
    """(2 SLOTS rows, width, 4) float32 image of a node's (P, 2 SLOTS, 3) images: slot s
    in rows s * rows .. (s + 1) * rows - 1, texel (x, y, z, 1) where the image exists."""
    n_points, n_slots = slots.shape[:2]
    texels = np.zeros((n_slots, rows * width, 4), np.float32)
    present = np.isfinite(slots[..., 0]).T  # (slots, P)
    texels[:, :n_points, :3] = np.nan_to_num(slots.transpose(1, 0, 2))
    texels[:, :n_points, 3] = present
    return texels.reshape(n_slots * rows, width, 4)


class NodeTextures:
    """Node images of one renderer's vertices on the GPU, for every grid of a
    :class:`MorphPass`: key (grid, node) -> texture, the least recently used dropped
    first once they pass ``budget_mb``."""

    def __init__(self, budget_mb: float = DEFAULT_MORPH_BUDGET_MB):
        self.budget_bytes = int(budget_mb * 2 ** 20)
        self._textures: OrderedDict = OrderedDict()  # key -> (texture, bytes, (regular, widened) slots used)
        self.nbytes = 0
        self.evictions = 0

    def __contains__(self, key) -> bool:
        return key in self._textures

    def __len__(self) -> int:
        return len(self._textures)

    def get(self, key) -> tuple:
        """(texture, (regular, widened) slots that hold any image) of ``key``."""
        entry = self._textures.pop(key)
        self._textures[key] = entry  # most recently used last
        return entry[0], entry[2]

    def put(self, key, slots: np.ndarray, width: int, rows: int, keep=()) -> None:
        """Upload a node's (P, 2 SLOTS, 3) images under ``key`` (:func:`node_texels`);
        drop the least recently used (but ``keep``) while over the budget."""
        texels = node_texels(slots, width, rows)
        used = np.isfinite(slots[..., 0]).any(axis=0)
        counts = tuple(int(np.max(np.flatnonzero(part), initial=-1)) + 1 for part in (used[:SLOTS], used[SLOTS:]))
        self._textures[key] = (data_texture(texels), texels.nbytes, counts)
        self.nbytes += texels.nbytes
        for old in list(self._textures):
            if self.nbytes <= self.budget_bytes:
                break
            if old == key or old in keep:
                continue
            self.nbytes -= self._textures.pop(old)[1]
            self.evictions += 1

    def drop(self, grid_index: int) -> None:
        """Forget one grid's nodes (its reflector moved: its images are stale)."""
        for key in [k for k in self._textures if k[0] == grid_index]:
            self.nbytes -= self._textures.pop(key)[1]


class MorphPass(FramePass):
    """The morphing grids' GPU side for one renderer's reflected geometry: ``grids`` are
    (``MorphingGrid``, the reflector's object matrix) pairs, ``meshes`` the renderer's
    :class:`..reflected_meshes.ReflectedMeshes` (made here when not given)."""

    #: No hidden-point test: a blended image lies on the surface fitted to the nodes'
    #: images, not on the mesh, often more than ``FramePass.hidden_fraction`` off it
    #: (the test dropped a fifth of a ball's reflection).
    hidden_fraction = float("inf")
    #: A render keeps a blended fragment only where the eye's ray, reflected about the
    #: mirror's normal at its pixel, leaves within 6 degrees of its point of the mesh
    #: (20 for any other pass, ``FramePass.reflection_cosine``): near the silhouette the
    #: four nodes' images move far apart and the fitted surface errs, and there a blended
    #: triangle makes shards (sbc_fig3's blue column along the ball's left rim, 6-20
    #: degrees off). A dropped fragment within ``reflection_draw.RIM_GAP_PX`` of the
    #: silhouette and of a drawn reflection is traced; farther in it shows the world. Label
    #: disagreement with Cycles over three frames of sbc_fig3's orbit, by tolerance: 20
    #: degrees 2.04 %, 10 degrees 1.97 %, 6 degrees 1.89 %, 3 degrees 1.85 %, the strip
    #: along the rim then growing (docs/benchmarks/morph_animation.md). The live view keeps
    #: the usual test (compiled out on a convex mirror): a dropped fragment there is a hole.
    rendered_reflection_cosine = math.cos(math.radians(6.0))
    name = "morphing"

    @classmethod
    def of_inputs(cls, methods: tuple, inputs: PassInputs) -> "MorphPass":
        settings = inputs.settings
        return cls(inputs.geometry, methods, inputs.meshes, settings.morph_budget_mb, settings.accuracy_px,
                   inputs.convex_mirrors, settings.polish_frames)

    def __init__(self, geometry, grids, meshes: ReflectedMeshes | None = None,
                 budget_mb: float = DEFAULT_MORPH_BUDGET_MB, accuracy_px: float | None = None,
                 convex_mirrors: ConvexMirrors | None = None, polish_frames: bool = False):
        self.geometry = geometry
        #: Each frame's blended answers polished on the mirror (:meth:`_polish`), where the
        #: grid has one (*Polish Node Images*): then every drawn answer lies on the mesh,
        #: and the hidden-point test applies again.
        self.polish_frames = bool(polish_frames)
        if self.polish_frames:
            self.hidden_fraction = FramePass.hidden_fraction
        self._own_polish = None  # the tables of mirrors whose grid polishes in numpy
        self._accuracy = accuracy_px
        self._convex = ConvexMirrors() if convex_mirrors is None else convex_mirrors
        self.grids = list(grids)
        self.meshes = meshes if meshes is not None else ReflectedMeshes(geometry)
        self.nodes = NodeTextures(budget_mb)
        self._frames = [None] * len(self.grids)  # the rigid frame each grid's node images were made in
        self._results: dict = {}  # grid index -> [answer texture per slot]
        self._uniforms: dict = {}  # nodes per cell -> the uniform buffer of the blend's per-frame parameters
        self._active: dict = {}  # grid index -> slots written by its last blend (the rest are empty)
        self._pending: dict = {}  # (grid index, node) -> (frame, Future of its node_slots), prefetching
        self._drawn: list = []  # grid indices blended by the last blend()
        self.counts = {"blends": 0, "node_projections": 0}

    @property
    def reflector_indices(self) -> list:
        return [grid.reflector_index for grid, _ in self.grids]

    @property
    def accuracy_px(self) -> float | None:
        """The scene's Accuracy, the live view's snapping grid (``FramePass.accuracy_px``):
        a snapped vertex moves by at most 0.71 of a cell, so the live view's blend is
        within the Accuracy plus its own error (``docs/benchmarks/morphing.md``); a
        render places every vertex exactly."""
        return self._accuracy

    @property
    def mirrored_reflectors(self) -> list:
        """The grids' mirrors that bound a convex body (``convex_mirrors``): every image a
        convex mirror shows is mirrored, blended or not."""
        return [index for index in self.reflector_indices if index in self._convex.indices]

    @property
    def drawn_reflectors(self) -> list:
        """The reflectors the last :meth:`blend` drew from their grids."""
        return [self.grids[k][0].reflector_index for k in self._drawn]

    @property
    def searched_reflectors(self) -> list:
        """The reflectors blended this frame: as a search's, the blend leaves vertices
        unanswered along the silhouette (where not every node of the cell sees the
        mirror), so a render traces that band."""
        return self.drawn_reflectors

    @property
    def gap_reflectors(self) -> list:
        """The reflectors drawn from their grids: the blend leaves pixels without an
        answer where not every node of the cell sees the mirror."""
        return self.drawn_reflectors

    def drawn_in(self, view) -> frozenset:
        """The reflectors whose grid covers ``view``."""
        return frozenset(self.grids[k][0].reflector_index for k, _ in self.covering(view))

    def update(self, frame: Frame) -> None:
        """:meth:`blend`, but not for the reflectors a camera claimed (a blend depends on
        the view alone: ``frame.warm`` changes nothing)."""
        self.blend(frame.view, frame.claimed)

    def covering(self, view) -> list:
        """(grid index, (tetrahedron, nodes, weights, frame)) of each grid whose
        reflector ``view`` can be drawn from (``MorphingGrid.check_view``), its cell's
        nodes' images on the GPU (projected now where missing). A grid whose cache turns
        out damaged records the fault (``MorphingGrid.failure``) and is left out from
        then on: its reflector is drawn in runtime mode."""
        found = []
        for k, (grid, matrix) in enumerate(self.grids):
            if grid.failure is not None:
                continue
            try:
                located = grid.check_view(view, matrix)
                keep = {(k, int(n)) for n in located[1]}
                for node in located[1]:
                    self._node_texture(k, int(node), located[3], keep)
            except morphing.ViewOutsideGrid:
                continue
            except CacheError as error:
                grid.failure = error
                continue
            found.append((k, located))
        return found

    def _points_in_frame(self, frame: np.ndarray) -> np.ndarray:
        return morph_grid.to_frame(frame, self.geometry.vertices)

    def _node_texture(self, k: int, node: int, frame: np.ndarray, keep=()):
        """Grid ``k``'s node ``node`` images on the GPU, projected now when missing:
        (texture, (regular, widened) slots used)."""
        if self._frames[k] is None or not np.array_equal(self._frames[k], frame):
            self.nodes.drop(k)
            self._frames[k] = frame
        key = (k, int(node))
        if key not in self.nodes:
            pending = self._pending.pop(key, None)
            if pending is not None and np.array_equal(pending[0], frame):
                # Being prefetched: wait for it rather than start again.
                slots = self._polished(k, node, frame, pending[1].result())
            else:
                slots = self.grids[k][0].node_slots(int(node), self._points_in_frame(frame), SLOTS)
            self.nodes.put(key, slots, self.meshes.width, self.meshes.height, keep)
            self.counts["node_projections"] += 1
        return self.nodes.get(key)

    def blend(self, view, skip=frozenset()) -> list:
        """This frame's blend for every grid covering ``view`` (one dispatch each) but
        those of the reflectors in ``skip``; returns the reflector indices drawn from a
        grid in this view."""
        self._drawn = []
        if self.meshes.n_vertices == 0 or not self.grids:
            return []
        shift = self.geometry.shift
        view_projection = (np.asarray(view.projection_matrix) @ np.asarray(view.view_matrix)
                           @ _translation(shift))
        for k, (_, nodes, weights, frame) in self.covering(view):
            grid = self.grids[k][0]
            if grid.reflector_index in skip:
                continue
            keep = {(k, int(n)) for n in nodes}
            textures, used = zip(*[self._node_texture(k, n, frame, keep) for n in nodes])
            if k not in self._results:
                self._results[k] = [self.meshes.answer_texture() for _ in range(SLOTS)]
            eye = morph_grid.to_frame(frame, view.eye[None])[0]
            matrices = [np.linalg.inv(frame) @ _translation(shift), _translation(-shift) @ frame, view_projection]
            node_rows = np.c_[grid.grid.node_positions()[np.asarray(nodes)], np.asarray(weights, np.float64)]
            slot_rows = np.c_[np.asarray(used, np.float64), np.zeros((len(nodes), 2))]
            values = np.concatenate([m.T.reshape(-1) for m in matrices] + [
                np.r_[eye, morphing.MATCH_FRACTION * grid.reflector_size], node_rows.reshape(-1),
                slot_rows.reshape(-1)]).astype(np.float32)
            self._active[k], widened = (max(u[part] for u in used) for part in (0, 1))
            self._drawn.append(k)
            if self._active[k] == 0:
                continue  # no node sees the mirror from any vertex: nothing to blend or draw
            shader = blend_shader(len(nodes), self._active[k], widened, grid.blend_nodes, grid.quadric_ridge)
            uniforms = self._frame_buffer(len(nodes))
            uniforms.update(gpu.types.Buffer('FLOAT', len(values), values))
            shader.bind()
            shader.uniform_block("frame", uniforms)
            shader.uniform_int("n_vertices", self.meshes.n_vertices)
            shader.uniform_int("positions_width", self.meshes.width)
            if self._active[k] > 1 or widened:  # slot 0 alone needs no row offset: compiled out
                shader.uniform_int("slot_rows", self.meshes.height)
            shader.uniform_sampler("vertex_positions", self.meshes.positions)
            for n, texture in enumerate(textures):
                shader.uniform_sampler(f"node{n}", texture)
            for slot, texture in enumerate(self._results[k][:self._active[k]]):
                shader.image(f"result{slot}", texture)
            gpu.compute.dispatch(shader, *self.meshes.work_groups(LOCAL_SIZE))
            if self.polish_frames and grid.mirror is not None:
                self._polish(grid, eye, matrices[0], self._results[k][:self._active[k]])
        self.counts["blends"] += 1
        return [self.grids[k][0].reflector_index for k in self._drawn]

    def _polish(self, grid, eye, frame_from_shifted: np.ndarray, answers) -> None:
        """Move this frame's blended ``answers`` of ``grid`` onto the mirror's reflection
        points (``polish_gpu.polish_answers``: Newton on the mesh from each blended image,
        as Polish Node Images does for the nodes' images), dropping those it cannot place.
        A blend on a mirror that is not a quadric errs by tens of pixels where its
        curvature changes within a cell (a rounded box), and polished lands on the exact
        solver's reflections (tests/drawing/methods/test_morph_pass.py; figures in
        docs/benchmarks/octree.md, its cost in docs/benchmarks/view_change.md)."""
        polish = grid.image_polish
        if not isinstance(polish, GPUImagePolish):
            polish = self._own_polish = self._own_polish or GPUImagePolish()
        polish_answers(polish.tables(grid.mirror()), eye, frame_from_shifted, self.meshes, answers)

    def _frame_buffer(self, n_nodes: int):
        """The uniform buffer of the blend's parameters for cells of ``n_nodes`` nodes."""
        if n_nodes not in self._uniforms:
            size = frame_floats(n_nodes)
            self._uniforms[n_nodes] = gpu.types.GPUUniformBuf(gpu.types.Buffer('FLOAT', size))
        return self._uniforms[n_nodes]

    def prefetch(self, view, submit, max_pending: int = 1, exact: bool = False, ahead=()) -> int:
        """Start projecting nodes not yet on the GPU around each covering grid's eye (the
        4 x 4 x 4 nodes of its cell and the cells beside it, nearest first), so that
        moving on rarely waits: ``submit(function, *args)`` runs the projection (in numpy,
        no GPU: on a worker thread; ``MorphingGrid.unpolished_images``) and returns a
        ``Future``; at most ``max_pending`` run at once, and a prefetch never evicts.
        :meth:`collect` polishes the finished ones (on the GPU) and uploads them.
        ``exact``: only grids whose nodes the main thread would project the same way
        (``projects_nodes_on_gpu`` false), so that a render is the same whether a node was
        prefetched or not. ``ahead``: world-space eyes the next views are expected at,
        soonest first (an animation's camera, extrapolated): the nodes of their cells go
        first. Returns how many were started."""
        started = 0
        for k, (_, _, _, frame) in self.covering(view):
            grid, matrix = self.grids[k]
            if exact and grid.projects_nodes_on_gpu:
                continue
            for node in _nodes_ahead(grid, matrix, frame, view.eye, ahead):
                key = (k, int(node))
                if len(self._pending) >= max_pending:
                    return started
                if key in self.nodes or key in self._pending or grid.node_status[node] != morph_grid.NODE_OK:
                    continue
                if self.nodes.nbytes + (len(self._pending) + 1) * self._node_bytes() > self.nodes.budget_bytes:
                    return started
                self._pending[key] = (frame, submit(grid.unpolished_images, int(node), self._points_in_frame(frame),
                                                    morphing.project_face))
                started += 1
        return started

    @property
    def prefetching(self) -> int:
        """Node projections started by :meth:`prefetch` and not yet collected."""
        return len(self._pending)

    @property
    def prefetched(self) -> bool:
        """Whether a prefetched node is ready for :meth:`collect`."""
        return any(future.done() for _, future in self._pending.values())

    def collect(self) -> int:
        """Upload the prefetched nodes that have finished (main thread); returns how many."""
        uploaded = 0
        for key, (frame, future) in list(self._pending.items()):
            if not future.done():
                continue
            del self._pending[key]
            k = key[0]
            try:
                images = future.result()
            except CacheError as error:
                self.grids[k][0].failure = error
                continue
            if self._frames[k] is not None and np.array_equal(self._frames[k], frame) and key not in self.nodes:
                slots = self._polished(k, key[1], frame, images)
                self.nodes.put(key, slots, self.meshes.width, self.meshes.height)
                self.counts["node_projections"] += 1
                uploaded += 1
        return uploaded

    def _polished(self, k: int, node: int, frame: np.ndarray, images: tuple) -> np.ndarray:
        """The node slots of a prefetched node's ``unpolished_images``, polished here, on
        the main thread (the grid's GPU polish takes milliseconds, the worker's numpy
        polish a large part of a second a node)."""
        return self.grids[k][0].polished_slots(node, self._points_in_frame(frame), images, SLOTS)

    def _node_bytes(self) -> int:
        return 2 * SLOTS * self.meshes.width * self.meshes.height * 16

    def statistics(self) -> list:
        """The node images held on the GPU, against their budget."""
        if not self.grids:
            return []
        return [f"Morphing nodes on the GPU: {len(self.nodes)} ({self.nodes.nbytes / 2 ** 20:.0f} of "
                f"{self.nodes.budget_bytes / 2 ** 20:.0f} MB)"]

    def answers(self) -> list:
        """(reflector index, answer texture) per image slot of the last blend."""
        return [(self.grids[k][0].reflector_index, texture) for k in self._drawn
                for texture in self._results[k][:self._active[k]]]

    def read(self, reflector_index: int) -> np.ndarray:
        """(SLOTS, N, 3) world points of the last blend of a reflector's grid, NaN where
        a vertex has no image in a slot (tests, benchmarks)."""
        k = next(k for k in self._drawn if self.grids[k][0].reflector_index == reflector_index)
        found = np.full((SLOTS, self.meshes.n_vertices, 3), np.nan)
        for slot, texture in enumerate(self._results[k][:self._active[k]]):
            found[slot] = self.meshes.read(texture)[0]
        return found


def _nodes_ahead(grid, matrix, frame, eye, ahead) -> list:
    """The nodes :meth:`MorphPass.prefetch` considers, in order: those of the cells holding
    the eyes ``ahead`` (soonest first; eyes outside the grid are skipped), then the nodes
    around ``eye`` (``nodes_around``, nearest first), each once."""
    order = []
    for eye_ahead in ahead:
        try:
            order.extend(int(n) for n in grid.locate_view(eye_ahead, matrix)[1])
        except morphing.ViewOutsideGrid:
            continue
    order.extend(int(n) for n in grid.grid.nodes_around(morph_grid.to_frame(frame, np.asarray(eye)[None])[0]))
    return list(dict.fromkeys(order))
