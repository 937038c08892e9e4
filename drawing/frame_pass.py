# SPDX-License-Identifier: GPL-3.0-or-later
"""What the renderer asks of a method that draws reflections: the pass protocol.

Every method is a :class:`FramePass`. The renderer (``reflection_draw.py``) holds them as
one tuple and never asks which method one is: for each frame it makes one
:class:`Frame` (the view, the targets, the sample-based camera's source if any), and
every pass, in order, updates for it (:meth:`FramePass.update`), claims the reflectors
whose first-order reflections it draws instead of the passes after it
(:meth:`FramePass.claims`), and draws its reflected geometry into the frame's reflection
target (:meth:`FramePass.draw`); the renderer then traces the pixels each pass says its
method cannot be trusted on.

The sample-based camera (``methods/camera_pass.py``) comes first: it draws the reflected
triangles made once per camera and claims the first orders it drew. The iterative search
(``methods/iterative_draw.py``), the morphing grids, tetrahedral and octree
(``methods/morph_pass.py``), and perturbation (``methods/perturbation_pass.py``) answer
every vertex on the GPU each frame: one answer texture per reflector (and image slot),
which :class:`.reflected_meshes.ReflectedMeshes` draws (the default :meth:`FramePass.draw`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

from ..engine.frame_settings import FrameSettings
from .reflected_meshes import REFLECTION_COSINE, SNAP_SHARE
from .screen_space import camera_position

#: Depth range of the per-frame passes' first-order reflections (as SBC V-A's g for max
#: order 1); they never share pixels with another method's, the pre-pass ids keep each
#: reflection on its own mirror.
FIRST_ORDER_RANGE = 0.5


@dataclass(frozen=True)
class PassInputs:
    """What a renderer hands each pass it makes (:meth:`FramePass.factory`): its reflected
    geometry (``draw_geometry.DrawGeometry``) and that geometry on the GPU
    (``reflected_meshes.ReflectedMeshes``), every reflector of the scene and their
    ray-tracing set when the caller keeps one, the convexity of each mirror
    (``closed_surfaces.ConvexMirrors``, tested once for every pass), and the frame's
    settings."""

    geometry: object
    meshes: object
    reflectors: tuple
    reflector_set: object
    convex_mirrors: object
    settings: FrameSettings
    #: The diffuse meshes as given (``engine.scene.DiffuseMesh`` each), before subdivision:
    #: what a trace meets rays with.
    diffuse: tuple = ()
    #: The glass among them (``engine.glass.Glass`` each): a trace's rays refract through it.
    glasses: tuple = ()


@dataclass(frozen=True)
class Frame:
    """What every pass of one frame consumes (made by ``ReflectionRenderer.draw_passes``).

    ``view``: the view drawn; ``warm``: a viewport frame, which may start from the last
    frame's answers and, with ``snap``, snaps its reflected vertices within its Accuracy
    (the camera's ``accuracy_px``, each pass's own); a render is cold, so that its image
    depends on its view alone and is placed exactly, and so is a resting viewport's.
    ``source``: the projection source of a sample-based camera (``None``: no camera this
    frame) and ``camera`` the camera itself when known. ``targets``
    (``frame_targets.FrameTargets``) hold the pre-pass; ``world_to_clip`` places world
    points (relative to the geometry's shift) on screen; ``images(k)`` is image ``k``'s
    texture (-1: none). ``claimed``: the reflectors whose first-order reflections an
    earlier pass draws this frame (:meth:`FramePass.claims`), which the later ones skip.
    """

    view: object
    targets: object
    world_to_clip: object
    images: object
    warm: bool = False
    accuracy_px: float | None = None
    snap: bool = True
    source: object = None
    camera: object = None
    claimed: frozenset = frozenset()

    def claiming(self, reflectors) -> "Frame":
        """This frame with ``reflectors`` claimed as well."""
        reflectors = frozenset(reflectors)
        return self if reflectors <= self.claimed else replace(self, claimed=self.claimed | reflectors)


class FramePass:
    """One method's per-frame GPU work for one renderer. Subclasses implement
    :meth:`of_inputs`, :meth:`update` and :meth:`answers`, hold ``geometry`` and
    ``meshes`` (the :class:`PassInputs`'), and hold ``methods`` (one per reflector, each
    with its ``index``) or override :attr:`reflector_indices`; a pass that draws other
    than answer textures overrides :meth:`draw`. The rest says how the renderer's band
    trace treats the pass's reflectors and what work it does off the drawing thread, and
    defaults to *not at all*."""

    #: The pass's name in statistics and in ``ReflectionRenderer.pass_named``.
    name = "pass"

    #: Whether the method answers by a search per vertex (see :attr:`searched_reflectors`).
    searches = False

    #: A reflected fragment whose reflector point lies farther from the eye than the mirror
    #: surface the pre-pass saw at its pixel, by more than this fraction of the reflector's
    #: bounding-box diagonal, is hidden by the mirror itself and dropped
    #: (``glsl/reflection_mesh_frag.glsl``): a per-vertex method answers without tracing
    #: the eye's ray. On a bumpy sphere, perturbation's answers hidden behind a bump lie
    #: 0.1-2.5 % of it behind the surface seen (median 1 %; this catches 63-70 % of them),
    #: its visible answers at most 0.13 % (``tests/drawing/test_reflected_meshes.py``).
    hidden_fraction = 0.003
    #: A reflected fragment is kept only where the eye's ray, reflected about the normal of
    #: the mirror the pre-pass saw at its pixel, leaves within this cosine of the direction
    #: toward the fragment's point of the mesh (``glsl/reflection_mesh_frag.glsl``; the
    #: sample-based camera's first-order triangles are held to the same).
    reflection_cosine = REFLECTION_COSINE
    #: The same test in a render (Render Image): a pass whose answers are approximate can
    #: ask for a tighter one there, where a dropped fragment is traced or shows the world
    #: rather than a wrong object.
    rendered_reflection_cosine = REFLECTION_COSINE

    #: The Accuracy (px) the pass answers to, which sets the live view's snapping grid
    #: (``reflected_meshes.SNAP_SHARE``); None: the pass's images are not that accurate
    #: (the blended grids), and are not snapped.
    accuracy_px = None

    @classmethod
    def factory(cls, methods):
        """What a renderer calls with its :class:`PassInputs` to make this pass for
        ``methods`` (the method plan's engines: ``MethodPlan.pass_factories``)."""
        return functools.partial(cls.of_inputs, tuple(methods))

    @classmethod
    def of_inputs(cls, methods: tuple, inputs: PassInputs) -> "FramePass":
        raise NotImplementedError

    @property
    def reflector_indices(self) -> list:
        """Every reflector this pass may draw."""
        return [method.index for method in self.methods]

    def update(self, frame: Frame) -> None:
        """This frame's answers for ``frame.view`` (``frame.warm``: start from the last
        frame's), leaving out the reflectors in ``frame.claimed``."""
        raise NotImplementedError

    def claims(self) -> frozenset:
        """The reflectors whose first-order reflections the last update drew for the
        passes after this one (they skip them)."""
        return frozenset()

    def answers(self) -> list:
        """The last update's answers, for ``ReflectedMeshes.draw``: ``reflected_meshes.AnswerSet``
        s, or (reflector index, answer texture) pairs, which it reads as one."""
        raise NotImplementedError

    def draw(self, frame: Frame) -> None:
        """The reflected meshes at the last update's answers into ``frame.targets``'
        reflection target (bound by the caller, depth test on)."""
        self.meshes.draw(frame.world_to_clip, frame.targets, self.reflected_setup(frame), frame.images,
                         self.answers())

    def reflected_setup(self, frame: Frame) -> dict:
        """The uniforms of this pass's reflected meshes in ``frame`` (``ReflectedMeshes.draw``):
        a warm frame's vertices snap to a grid within the pass's Accuracy
        (``reflected_meshes.SNAP_SHARE``); a render places them exactly, and tests the law
        of reflection at :attr:`rendered_reflection_cosine`."""
        view, accuracy = frame.view, self.accuracy_px if frame.warm and frame.snap else None
        return {"inverse_diameter": 1.0 / self.geometry.diameter, "order_range": FIRST_ORDER_RANGE,
                "camera": camera_position(view, self.geometry.shift), "hidden_fraction": self.hidden_fraction,
                "reflection_cosine": self.reflection_cosine if frame.warm else self.rendered_reflection_cosine,
                "mirrored": frozenset(self.mirrored_reflectors), "view_size": (float(view.width), float(view.height)),
                "snap_px": 0.0 if accuracy is None else SNAP_SHARE * float(accuracy)}

    def drawn_in(self, view) -> frozenset:
        """The reflectors whose first-order reflections this pass draws in ``view`` (a
        camera made for the view leaves them out)."""
        return frozenset(self.reflector_indices)

    @property
    def searched_reflectors(self) -> list:
        """Reflectors answered by a search per vertex: vertices go unanswered along their
        silhouette, so the band there is traced."""
        return self.reflector_indices if self.searches else []

    @property
    def folded_reflectors(self) -> list:
        """Reflectors whose images may crowd or fold (not convex, or not alone): the
        pixels next to their drawn reflections are traced too."""
        return []

    @property
    def mirrored_reflectors(self) -> list:
        """Reflectors every image of which is mirrored, as in a flat mirror (a convex
        mirror: its caustic lies behind the surface, no image is flipped): on screen a
        mirror reverses the winding of every triangle, so the far sides of closed
        solids can be culled by winding (``ReflectedMeshes.draw``)."""
        return []

    @property
    def every_order_reflectors(self) -> frozenset:
        """Reflectors whose reflections of every order the pass draws (its rays follow
        them through further mirrors): no camera is needed for them."""
        return frozenset()

    @property
    def gap_reflectors(self) -> list:
        """Reflectors the last update drew with gaps a render may trace (``trace_gaps``)."""
        return []

    @property
    def traces_band(self) -> bool:
        """Whether a render traces the band of this pass's reflectors at all."""
        return bool(self.searched_reflectors)

    def statistics(self) -> list:
        """Lines for the panel's Statistics (what the pass holds, e.g. on the GPU)."""
        return []

    def frame_stats(self) -> dict:
        """What a render reports about this pass's last frame (read back from the GPU)."""
        return {}

    def status_counts(self) -> dict:
        """{reflector index: {"found": n, "unanswered": n}} of the last frame's answers,
        read back from the GPU (the live statistics; costly: not every frame)."""
        return {}

    # Work off the drawing thread (the live view and an animation run it between frames).

    def collect(self) -> None:
        """Take up the work a worker finished since the last call (put it on the GPU)."""

    def prefetch(self, view, submit, **options) -> bool:
        """Start work ``view`` will need soon on a worker (``submit``, an executor's);
        returns whether any was started."""
        return False

    @property
    def prefetching(self) -> bool:
        """Whether work started by :meth:`prefetch` is still running."""
        return False

    @property
    def prefetched(self) -> bool:
        """Whether work landed that the next draw should show (the caller redraws)."""
        return False
