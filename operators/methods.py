# SPDX-License-Identifier: GPL-3.0-or-later
"""Which method draws each reflector, and why: the one place that decides.

Per reflector, ``obj.curved_reflections.mode``:

- ``AUTO`` (the default): the iterative search (Roger & Holzschuch 2006) where the
  reflector is star-shaped (``addon/methods/iterative/star.py``), else Morphing where
  a baked grid exists (the live view and the renderer then check per view that the eye
  is inside it), else Runtime. The live view checks each drawn method's answers against
  exactly traced rays when the view settles (``operators/accuracy.py``); a method found
  outside the scene's Accuracy there is passed over for the next until Refresh
  (:func:`note_measured`);
- ``ITERATIVE``: the iterative search, or Runtime with the reason when the reflector is
  not star-shaped;
- ``MORPHING`` and ``RUNTIME``: the sample-based camera's modes (SBC paper VI and IV);
- ``OCTREE``: reflection morphing with ray octrees at the grid's nodes (Martin & Popescu
  2004), baked and drawn like Morphing;
- ``PERTURBATION``: Chen & Arvo (2000), on the reflector's declared exact surface
  (``analytic_shape``) when its mesh matches it, else on the mesh.

The star-shape verdict and the cube map are made once per reflector shape (compared up to a
translation with the ones kept, :data:`CACHED_MAPS` of them): a viewport orbit,
an animation frame in which the mirror did not change, or a mirror moved without
turning reuses them (the map moves with its centre). The map is baked on the GPU when
it is initialised (``gpu_shaders/methods/iterative_bake.py``, milliseconds), else traced on the
CPU. :func:`plan` is what the live view, Render Image and the panel use; its choices
say per reflector which method and why, and the last ones are kept for the panel.

Higher orders: the iterative search and perturbation draw first-order reflections;
reflections of order 2 and more, in every mode, come from the sample-based camera,
which is built for them (and for the reflectors it draws) alone. (Perturbation answers
second-order paths too, ``addon/methods/perturbation``; the renderer does not draw them
from it yet.)
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass, field

import numpy as np

from ..addon.methods.iterative import IterativeReflector, StarShape, check_star_shaped
from ..addon.methods.iterative.star import verdict
from ..addon.methods.iterative.reflector_map import bake_reflector_map
from ..addon.methods.perturbation import AnalyticSurface, PerturbationReflector
from ..addon.geometry.raytrace import ReflectorSet

#: Cube-map face size of the iterative search's reflector maps (texels along a side).
FACE_SIZE = 256
#: Reflector geometries whose verdict and map are kept.
CACHED_MAPS = 16

ITERATIVE, MORPHING, RUNTIME, PERTURBATION, OCTREE = 'ITERATIVE', 'MORPHING', 'RUNTIME', 'PERTURBATION', 'OCTREE'
#: The modes drawn from a baked grid (``morph_bake``; the renderer's ``MorphPass`` draws both).
GRID_MODES = (MORPHING, OCTREE)
#: A declared exact surface is used when the mesh's vertices lie this close to it
#: (share of its radius); farther, the mesh itself reflects and the panel says why.
ANALYTIC_TOLERANCE = 0.02


@dataclass(frozen=True)
class MethodChoice:
    """What draws one reflector, and why (one panel line)."""

    reflector: str
    method: str  # ITERATIVE, MORPHING or OCTREE (where the view allows), PERTURBATION or RUNTIME
    reason: str


@dataclass
class MethodPlan:
    """The iterative reflectors (engine objects, for the renderer) and every choice."""

    iterative: list = field(default_factory=list)
    perturbation: list = field(default_factory=list)  # PerturbationReflector each
    choices: list = field(default_factory=list)

    @property
    def iterative_indices(self) -> frozenset:
        return frozenset(m.index for m in self.iterative)

    def drawn_grids(self, grids: list) -> list:
        """The (grid, matrix) pairs of ``grids`` whose reflector the plan draws from its
        grid (Auto may have passed a loaded grid over: :func:`note_measured`)."""
        chosen = {choice.reflector: choice.method for choice in self.choices}
        return [(grid, matrix) for grid, matrix in grids if chosen.get(grid.reflector_name) in GRID_MODES]


_maps: list = []  # _Entry, most recently used last
_last_choices: dict = {}
#: {scene name: {reflector: {method: what was measured}}}: methods Auto replaced after the
#: live check measured them outside the scene's Accuracy (kept until Refresh).
_outside_accuracy: dict = {}
#: {scene name: {reflector: accuracy.Measured}}: the live view's last checks, for the panel.
_measured: dict = {}


def _bake(reflector, centre, face_size: int):
    """The full-resolution map: on the GPU when it is ready, else traced on the CPU."""
    from ..gpu_shaders.methods.iterative_bake import bake_reflector_map_gpu
    from .gpu_init import gpu_ready

    if gpu_ready():
        return bake_reflector_map_gpu(reflector, centre, face_size)
    return bake_reflector_map(ReflectorSet([reflector]), centre, face_size)


#: Vertex positions of two captures of one shape (relative to their first vertex) may
#: differ by this share of its size: Blender's float32 matrices move the float64 capture.
SHAPE_TOLERANCE = 1e-9


@dataclass(frozen=True)
class _Entry:
    """One cached verdict and map, with the shape they were made for."""

    topology: str
    face_size: int
    offsets: np.ndarray  # vertex positions relative to the first vertex
    normals: np.ndarray
    origin: np.ndarray  # the first vertex
    shape: StarShape
    reflector_map: object

    def matches(self, reflector, topology: str, face_size: int) -> bool:
        if (self.topology, self.face_size) != (topology, face_size):
            return False
        offsets = reflector.vertices - reflector.vertices[0]
        tolerance = SHAPE_TOLERANCE * max(float(np.abs(offsets).max()), 1e-300)
        return bool(np.abs(offsets - self.offsets).max() <= tolerance
                    and np.abs(reflector.normals - self.normals).max() <= 1e-9)

    def moved_to(self, reflector):
        """The verdict and map, moved with the reflector's first vertex."""
        shift = reflector.vertices[0] - self.origin
        rmap = self.reflector_map
        return (dataclasses.replace(self.shape, centre=self.shape.centre + shift),
                None if rmap is None else dataclasses.replace(rmap, centre=rmap.centre + shift))


def _topology(reflector) -> str:
    digest = hashlib.sha1(np.ascontiguousarray(reflector.triangles).tobytes())
    digest.update(str(len(reflector.vertices)).encode())
    return digest.hexdigest()


def star_map(reflector, face_size: int | None = None):
    """(StarShape, ReflectorMap or None) of one reflector, cached by its shape: a mirror
    moved without turning reuses its verdict and its map, moved with it
    (``face_size``: default :data:`FACE_SIZE`)."""
    face_size = FACE_SIZE if face_size is None else int(face_size)
    topology = _topology(reflector)
    for index, entry in enumerate(_maps):
        if entry.matches(reflector, topology, face_size):
            _maps.append(_maps.pop(index))
            return entry.moved_to(reflector)
    shape = check_star_shaped(reflector)
    rmap = None
    if shape.star_shaped:  # the full-resolution rays are checked again (a thin fold, a small hole)
        bake = _bake(reflector, shape.centre, face_size)
        shape = verdict(reflector.name, shape.centre, bake, shape.hidden_share)
        rmap = bake.reflector_map if shape.star_shaped else None
    _maps.append(_Entry(topology, face_size, reflector.vertices - reflector.vertices[0], reflector.normals.copy(),
                        reflector.vertices[0].copy(), shape, rmap))
    del _maps[:-CACHED_MAPS]
    return shape, rmap


def mode_of(scene, name: str) -> str:
    """A captured reflector's mode (Auto for an instance, which has no object of its own)."""
    obj = scene.objects.get(name)
    return 'AUTO' if obj is None else obj.curved_reflections.mode


def plan(scene, reflectors, accuracy_px: float | None = None, baked=frozenset()) -> MethodPlan:
    """Every reflector's method. ``baked``: names of the reflectors with a loaded
    morphing grid (AUTO uses it where the reflector is not star-shaped)."""
    accuracy = float(scene.curved_reflections.accuracy_px if accuracy_px is None else accuracy_px)
    result = MethodPlan()
    for index, reflector in enumerate(reflectors):
        mode = mode_of(scene, reflector.name)
        outside = _outside_accuracy.get(scene.name, {}).get(reflector.name, {}) if mode == 'AUTO' else {}
        if mode in ('AUTO', ITERATIVE):
            shape, rmap = star_map(reflector)
            if rmap is not None and ITERATIVE in outside:
                shape = dataclasses.replace(shape, reason=f"the iterative search measured {outside[ITERATIVE]} in "
                                            f"a view (Accuracy {accuracy:g} px)")
                rmap = None
            if rmap is not None:
                result.iterative.append(IterativeReflector(index, reflector.name, rmap, accuracy))
                centre = ", ".join(f"{round(float(c), 2) + 0.0:.2f}" for c in shape.centre)  # no "-0.00"
                result.choices.append(MethodChoice(reflector.name, ITERATIVE,
                                                   f"star-shaped around ({centre}): iterative search on the GPU"))
                continue
            if mode == 'AUTO' and reflector.name in baked and MORPHING not in outside:
                result.choices.append(MethodChoice(reflector.name, MORPHING,
                                                   f"{shape.reason}; its baked morphing grid draws it"))
            elif mode == 'AUTO' and reflector.name in baked:
                fallback = f"its baked grid measured {outside[MORPHING]} in a view (Accuracy {accuracy:g} px): Runtime"
                result.choices.append(MethodChoice(reflector.name, RUNTIME, f"{shape.reason}; {fallback}"))
            else:
                fallback = "no baked morphing grid, so Runtime" if mode == 'AUTO' else "drawn in Runtime mode"
                result.choices.append(MethodChoice(reflector.name, RUNTIME, f"{shape.reason}; {fallback}"))
        elif mode == PERTURBATION:
            chosen, reason = perturbation_reflector(scene, index, reflector)
            result.perturbation.append(chosen)
            result.choices.append(MethodChoice(reflector.name, PERTURBATION, reason))
        elif mode in GRID_MODES:
            label = {MORPHING: "Morphing mode", OCTREE: "Octree mode (ray octrees, Martin & Popescu 2004)"}[mode]
            result.choices.append(MethodChoice(reflector.name, mode if reflector.name in baked else RUNTIME,
                                               label if reflector.name in baked
                                               else f"{label} without a baked grid: Runtime"))
        else:
            result.choices.append(MethodChoice(reflector.name, RUNTIME, "Runtime mode: a camera per view"))
    for method in result.iterative:  # the other searched mirrors may block its reflected segments
        method.occluders = tuple(other.reflector_map for other in result.iterative if other is not method)
    _last_choices[scene.name] = result.choices
    return result


def note_measured(scene, measured: dict) -> bool:
    """Keep the live view's checks (``accuracy.measure``: {reflector: Measured}) for the
    panel; an Auto reflector whose method measured outside the scene's Accuracy (95 % of
    its checked answers within it, ``SpotCheck.within``) is drawn by the next method
    from then on (Iterative, then its baked grid, then Runtime) until Refresh. Returns
    whether that happened now (the caller plans again)."""
    _measured[scene.name] = dict(measured)
    accuracy = float(scene.curved_reflections.accuracy_px)
    replaced = False
    for name, found in measured.items():
        if mode_of(scene, name) != 'AUTO' or found.method == RUNTIME or found.check.within(accuracy):
            continue
        failed = _outside_accuracy.setdefault(scene.name, {}).setdefault(name, {})
        if found.method not in failed:
            failed[found.method] = f"p95 {found.check.percentile(95):.2f} px" if found.check.confirmed else \
                "no answer confirmed"
            replaced = True
    return replaced


def measured(scene) -> dict:
    """The live view's last checks of ``scene`` ({reflector: accuracy.Measured})."""
    return _measured.get(scene.name, {})


def forget_measurements(scene) -> None:
    """Drop the checks and give Auto's replaced methods another chance (Refresh)."""
    _measured.pop(scene.name, None)
    _outside_accuracy.pop(scene.name, None)


def perturbation_reflector(scene, index: int, reflector) -> tuple:
    """(PerturbationReflector, panel reason): with its declared exact surface where the
    object has one and its mesh lies within ANALYTIC_TOLERANCE of it."""
    obj = scene.objects.get(reflector.name)
    settings = None if obj is None else obj.curved_reflections
    if settings is None or settings.analytic_shape == 'NONE':
        return (PerturbationReflector(index, reflector.name),
                "Perturbation of traced paths on the mesh's osculating quadrics (Chen & Arvo 2000)")
    surface = AnalyticSurface(reflector.name, settings.analytic_shape, np.array(obj.matrix_world),
                              tuple(settings.analytic_radii), settings.analytic_exponent)
    deviation = surface.mesh_deviation(reflector)
    shape = settings.analytic_shape.lower()
    if deviation > ANALYTIC_TOLERANCE:
        return (PerturbationReflector(index, reflector.name),
                f"the mesh lies up to {100 * deviation:.1f} % of the radius from the declared {shape} (more than "
                f"{100 * ANALYTIC_TOLERANCE:.0f} %): Perturbation on the mesh; set Radii to match it")
    return (PerturbationReflector(index, reflector.name, surface),
            f"Perturbation on the exact {shape} (mesh within {100 * deviation:.2f} % of it)")


def wants_grid(scene, reflector) -> bool:
    """Whether a morphing grid is baked and loaded for this reflector: Morphing or Octree
    mode, or Auto mode where it is not star-shaped."""
    mode = mode_of(scene, reflector.name)
    return mode in GRID_MODES or (mode == 'AUTO' and star_map(reflector)[1] is None)


def last_choices(scene) -> list:
    """The choices of the last :func:`plan` for ``scene`` (the panel's lines)."""
    return _last_choices.get(scene.name, [])


def grid_wanted_by_last_plan(scene, obj) -> bool:
    """:func:`wants_grid` from what is known without checking any geometry (for the
    panel, which must not wait): Morphing or Octree mode, or Auto mode not planned as Iterative."""
    mode = obj.curved_reflections.mode
    if mode in GRID_MODES:
        return True
    chosen = next((c.method for c in last_choices(scene) if c.reflector == obj.name), None)
    return mode == 'AUTO' and chosen in (MORPHING, RUNTIME)


def forget() -> None:
    """Drop the cached maps and choices (another file is being loaded, or unregister)."""
    _maps.clear()
    _last_choices.clear()
    _measured.clear()
    _outside_accuracy.clear()
