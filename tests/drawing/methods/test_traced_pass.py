# SPDX-License-Identifier: GPL-3.0-or-later
"""Mirrors ray traced per pixel on the GPU (drawing/methods/traced_pass.py,
glsl/mirror_trace.glsl), against the CPU's exact trace of the same pixels
(engine/geometry/band_trace.py)."""

import numpy as np
import pytest

from curved_reflections.drawing.methods.traced_pass import TracedMirror, TracedPass
from curved_reflections.drawing.reflection_draw import ReflectionRenderer
from curved_reflections.engine import Reflector
from curved_reflections.engine.geometry import shapes
from curved_reflections.engine.geometry.band_trace import BandTracer
from curved_reflections.engine.scene import DiffuseMesh
from curved_reflections.engine.view import look_at_view
from curved_reflections.tools import mirror_family

WIDTH, HEIGHT = 160, 120
WORLD = (0.3, 0.3, 0.6, 1.0)


def _solid(name, shape, colour, offset):
    return DiffuseMesh(name, shape.vertices + offset, shape.triangles,
                       np.tile((*colour, 1.0), (len(shape.vertices), 1)).astype(np.float32))


def _scene(mirror_shape):
    """``mirror_shape`` as a mirror in a room whose colour changes across it, three
    columns around the mirror."""
    room = shapes.box((12.0, 12.0, 8.0))
    colour = np.c_[0.5 + 0.06 * room.vertices, np.ones(len(room.vertices))].astype(np.float32)
    meshes = [DiffuseMesh("Room", room.vertices + (0.0, 0.0, 2.0), room.triangles, colour)]
    meshes += [_solid(f"Column{k}", shapes.box((0.3, 0.3, 2.5)), c, (2.0 * np.cos(a), 2.0 * np.sin(a), 0.0))
               for k, (c, a) in enumerate(zip(((0.1, 0.8, 0.2), (0.2, 0.3, 1.0), (0.9, 0.1, 0.9)), (0.5, 2.2, 4.0)))]
    mirror = Reflector("Mirror", mirror_shape.vertices, mirror_shape.triangles, mirror_shape.normals)
    return mirror, meshes


def _textured(meshes):
    """``meshes`` each with an image texture of its own size (none square), after three
    textured meshes out of sight: seven images, the visible ones the fourth to seventh."""
    rng = np.random.default_rng(5)
    hidden = [DiffuseMesh(f"Hidden{k}", meshes[1].vertices - (0.0, 0.0, 60.0), meshes[1].triangles, meshes[1].colors)
              for k in range(3)]
    return [DiffuseMesh(m.name, m.vertices, m.triangles, m.colors,
                        uvs=0.3 * m.vertices[:, :2] + 0.2 * m.vertices[:, 2:],
                        image=rng.uniform(0.2, 1.0, (2 + k, 5 - k % 3, 4)).astype(np.float32))
            for k, m in enumerate(hidden + meshes)]


@pytest.mark.parametrize("shape, max_order, textured", [("torus", 1, False), ("bumpy", 1, False), ("torus", 2, False),
                                                        ("bumpy", 1, True)])
def test_every_mirror_pixel_shows_what_the_exact_trace_of_its_ray_meets(gpu_ready, shape, max_order, textured):
    """A torus (not star-shaped: it sees itself, second orders at Max Order 2) and a ball
    with bumps of 15 % of its radius (its reflections fold), the room and the columns
    also with image textures (seven in the scene): every mirror pixel the GPU traces
    shows the colour the CPU's exact trace of its eye ray gives (measured: all but 0.1 %,
    on the silhouette, where the rasteriser and the ray disagree on the mirror; 94-99 %
    of the pixels show the room, the rest the world)."""
    from curved_reflections.drawing.gpu_data import read_texture
    from curved_reflections.engine.frame_settings import FrameSettings

    surface = mirror_family.torus() if shape == "torus" else mirror_family.bumpy_ball(0.15)
    mirror, meshes = _scene(surface)
    meshes = _textured(meshes) if textured else meshes
    settings = FrameSettings(max_order=max_order)
    renderer = ReflectionRenderer([mirror], meshes, settings=settings,
                                  passes=(TracedPass.factory([TracedMirror(0, "Mirror")]),))
    view = look_at_view((1.5, -4.5, 2.5), (0.0, 0.0, 0.0), fov_y_deg=40.0, width=WIDTH, height=HEIGHT)
    targets = renderer.draw_passes(view, None)
    drawn = read_texture(targets.reflection_colors, WIDTH, HEIGHT)
    labels = read_texture(targets.prepass_labels, WIDTH, HEIGHT)
    rows, columns = np.nonzero(labels[..., 0] > 0.5)
    truth = BandTracer([mirror], meshes).trace(view, np.c_[columns, rows] + 0.5, max_order, WORLD)
    shown = drawn[rows, columns]
    world = ~np.isfinite(truth[:, 3])
    colour = np.where(world[:, None], 0.0, truth[:, :3])
    wrong = np.abs(shown[:, :3] - colour).max(axis=1) > 0.02
    assert len(rows) > 3000 and wrong.mean() < 0.005, wrong.mean()
