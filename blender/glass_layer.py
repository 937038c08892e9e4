# SPDX-License-Identifier: GPL-3.0-or-later
"""Render Image's glass: what lies behind a glass object, drawn refracted through it.

The glass objects (``capture.CapturedScene.glass``) get a renderer of their own, the
reflected-mesh renderer with the glass as its "mirrors" and every other surface as its
meshes: a sample-based camera on the view's refracted rays (``engine/glass/glass_camera``,
SBC paper VII, Fig. 20b) places each mesh vertex on the glass where the eye sees it
through, the pre-pass keeps it to the pixels where that glass is in front, and the
reflected-mesh pass draws it there. Those pixels replace the frame's (where the mirrors'
renderer drew the glass as a solid object); a scene of glass alone is that renderer's
frame.

Left out for now, and said so in the panel: the live view (it shows glass as a solid
object), the glass's own reflection (Fresnel), mirrors seen through glass (drawn as grey
objects, without their reflections), glass in mirrors (a solid object), and the band
along the glass's silhouette, which the composite fills instead of tracing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..drawing.gpu_data import read_texture
from ..drawing.reflection_draw import ReflectionRenderer
from ..engine.errors import SceneInputError
from ..engine.frame_settings import FrameSettings
from ..engine.glass import GlassSet
from ..engine.glass.glass_camera import build_glass_camera
from ..engine.methods.sbc.sbc_build import check_view_outside_reflectors
from ..engine.scene import DiffuseMesh, scene_bounds
from ..engine.view import View
from .render_inputs import BOUNDS_MARGIN

#: The colour of a mirror seen through glass (its reflections are left out there).
MIRROR_GREY = (0.5, 0.5, 0.5, 1.0)


@dataclass
class GlassLayer:
    """One capture's glass, with its renderer (made again when the capture changes)."""

    key: tuple
    glass: GlassSet
    renderer: ReflectionRenderer
    bounds: tuple

    def render(self, view: View, world, settings: FrameSettings) -> tuple[np.ndarray, np.ndarray, dict]:
        """(image (H, W, 4) linear RGBA rows bottom to top, (H, W) bool the pixels where
        a glass object is in front, the camera's stats) of ``view``."""
        try:
            check_view_outside_reflectors(self.glass.surfaces, view)
        except SceneInputError as error:
            raise SceneInputError(error.object_name, "the view is inside this glass object; move the camera outside "
                                  "it (the inside of glass is not drawn)") from None
        lo, hi = self.bounds
        margin = BOUNDS_MARGIN * float(np.linalg.norm(hi - lo))
        camera = build_glass_camera(self.glass, view, (lo - margin, hi + margin), settings.downsample,
                                    settings.accuracy_px)
        image = self.renderer.render(view, camera, world, trace=False)
        labels = read_texture(self.renderer.targets(view.width, view.height).prepass_labels, view.width, view.height)
        return image, labels[..., 0] >= 0.5, camera.stats


def glass_layer(previous: GlassLayer | None, captured, key: tuple) -> GlassLayer | None:
    """The glass of ``captured`` (``None`` without any): ``previous`` while its ``key``
    (the capture's, ``frame_pipeline.captured_key``, and the glasses' indices) holds."""
    if not captured.glass:
        return None
    key = key + tuple((glass.name, glass.ior) for glass in captured.glass)
    if previous is not None and previous.key == key:
        return previous
    names = {glass.name for glass in captured.glass}
    meshes = [mesh for mesh in captured.meshes if mesh.name not in names]
    meshes += [DiffuseMesh(mirror.name, mirror.vertices, mirror.triangles,
                           np.tile(np.array(MIRROR_GREY, np.float32), (len(mirror.vertices), 1)),
                           normals=mirror.normals) for mirror in captured.reflectors]
    surfaces = [glass.surface for glass in captured.glass]
    count = len(surfaces)
    renderer = ReflectionRenderer(surfaces, meshes, reflector_colors=np.ones((count, 4), np.float32),
                                  reflectivity=np.ones(count, np.float32),
                                  fresnel_f0=np.full(count, np.nan, np.float32),
                                  attenuation_distance=np.zeros(count, np.float32),
                                  # Seen through glass an image is not mirrored, and the
                                  # law of reflection does not hold.
                                  cull=False, law_of_reflection=False)
    return GlassLayer(key, GlassSet(list(captured.glass)), renderer, scene_bounds(surfaces, meshes))


def over(image: np.ndarray | None, glass_image: np.ndarray, in_front: np.ndarray) -> np.ndarray:
    """The frame with the glass's pixels from ``glass_image`` (the glass's frame alone
    where there is no other)."""
    if image is None:
        return glass_image
    return np.where(in_front[..., None], glass_image, image)
