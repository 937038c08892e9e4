# SPDX-License-Identifier: GPL-3.0-or-later
"""Each pixel's own path through convex glass on the GPU (drawing/methods/glass_rays.py,
glsl/glass_rays.glsl), against the glass's exact paths on its mesh (engine/glass/paths.py),
and the fragment stage's ray cast that it feeds (glsl/reflection_mesh_frag.glsl)."""

import numpy as np
import pytest

from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.engine.glass import Glass, GlassSet
from curved_reflections.engine.glass.refraction_search import refracted_glass
from curved_reflections.engine.scene import DiffuseMesh
from curved_reflections.engine.view import look_at_view
from curved_reflections.tools.surfaces import flat_box

N = 1.5
WIDTH, HEIGHT = 160, 120


def _renderer(surface, meshes, reflects=True):
    """The glass layer's renderer of one glass solid (``blender/glass_layer.py``) by the
    refraction search (a scene of more image textures than the GPU's trace samples)."""
    from curved_reflections.blender import star_maps
    from curved_reflections.blender.glass_layer import glass_renderer

    glass = Glass(surface, N, reflects)
    method, reason = refracted_glass(glass, 0, *star_maps.star_map(surface))
    assert method is not None, reason
    return glass_renderer([glass], meshes, [method], traced=False)


def _paths(renderer, view):
    """The frame's per-pixel paths read back, and the pixel centres (x, y) of each row
    and column (rows bottom up, as the view's pixels)."""
    renderer.draw_passes(view, None)
    exits, status, leaving, dark = renderer.pass_named("refraction").rays.read()
    rows, columns = np.indices(status.shape)
    return exits + renderer.geometry.shift, status, leaving, dark, np.stack([columns, rows], axis=-1) + 0.5


def _panel():
    """A square behind the glass, so that the renderer has a mesh to refract."""
    corners = np.array([[-3.0, -3.0, -3.0], [3.0, -3.0, -3.0], [3.0, 3.0, -3.0], [-3.0, 3.0, -3.0]])
    return DiffuseMesh("Panel", corners, np.array([[0, 1, 2], [0, 2, 3]]), np.ones((4, 4), np.float32))


def test_each_pixel_of_a_glass_ball_follows_its_exact_path_through_it(gpu_ready):
    """Every pixel the pre-pass saw the ball on: the exit and the leaving ray of the path
    on the ball's cube map against the path traced on its mesh (measured at the 99th
    percentile: exits 5e-5 of the radius apart, rays 0.04 degrees)."""
    surface = icosphere((0.0, 0.0, 0.0), 1.0, 5, "Ball")
    view = look_at_view((0.4, -0.3, 5.0), (0.0, 0.0, 0.0), fov_y_deg=30.0, width=WIDTH, height=HEIGHT)
    exits, status, leaving, dark, pixels = _paths(_renderer(surface, [_panel()]), view)
    seen = status == 1
    assert seen.sum() > 2500 and not dark.any()
    paths = GlassSet([Glass(surface, N)]).trace(*view.pixel_rays(pixels[seen]))
    through = paths.interfaces == 2
    assert through.mean() > 0.99
    apart = np.linalg.norm(exits[seen] - paths.exit_position, axis=1)[through]
    angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", leaving[seen], paths.direction), -1.0, 1.0)))
    assert np.percentile(apart, 99) < 1e-3 and np.percentile(angle[through], 99) < 0.1


@pytest.mark.parametrize("reflects", [False, True])
def test_where_a_box_must_reflect_totally_its_paths_reflect_inside_or_go_dark(gpu_ready, reflects):
    """A glass box seen from above its front: rays entering its top meet a side past the
    critical angle (2,407 of its 3,582 pixels). Glass that does not reflect (a Refraction
    BSDF, which Cycles shows black there) marks exactly those pixels (99.9 % agree with
    the exact paths) and they are dark; glass that reflects follows them inside and out
    (those reflected once here), as the exact paths do (measured at the 98th percentile: exits 2e-5 apart, rays 0.035
    degrees; the last 2 % pass within a texel of an edge, which the cube map rounds), and
    none is dark."""
    surface = flat_box("Box", (-0.8, -0.8, -0.8), (0.8, 0.8, 0.8))
    view = look_at_view((2.5, -5.0, 3.5), (0.0, 0.0, 0.0), fov_y_deg=35.0, width=WIDTH, height=HEIGHT)
    exits, status, leaving, dark, pixels = _paths(_renderer(surface, [_panel()], reflects), view)
    on_glass = status != 0
    paths = GlassSet([Glass(surface, N)]).trace(*view.pixel_rays(pixels[on_glass]))
    inside = paths.total_reflections > 0
    assert inside.sum() > 300 and (paths.interfaces >= 2).all()
    if not reflects:
        assert ((status[on_glass] == -5) == inside).mean() > 0.99
        assert (dark[on_glass] == (status[on_glass] == -5)).all()
        return
    once = paths.total_reflections == 1
    assert not dark.any() and once.sum() > 300 and (status[on_glass][once] == 1).mean() > 0.99
    followed = once & (status[on_glass] == 1)
    apart = np.linalg.norm(exits[on_glass][followed] - paths.exit_position[followed], axis=1)
    angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", leaving[on_glass][followed],
                                                   paths.direction[followed]), -1.0, 1.0)))
    assert np.percentile(apart, 98) < 1e-4 and np.percentile(angle, 98) < 0.05


PALETTE = {"red": (1.0, 0.1, 0.1), "yellow": (1.0, 1.0, 0.2), "blue": (0.1, 0.2, 1.0), "world": (0.0, 0.0, 0.0)}


def _lens_scene():
    """A glass ball, a red cube close behind it reaching into its focus (n = 1.5: 1.5 from
    its centre), and yellow and blue panels farther back, all of flat colour."""
    from curved_reflections.engine.geometry import shapes

    def solid(name, shape, colour, offset):
        return DiffuseMesh(name, shape.vertices + offset, shape.triangles,
                           np.tile((*PALETTE[colour], 1.0), (len(shape.vertices), 1)), emissive=True)

    panels = [solid(f"panel{k}", shapes.box((2.5, 5.0, 0.1)), colour, (2.5 * k - 1.25, 0.0, -3.5))
              for k, colour in enumerate(("yellow", "blue"))]
    cube = solid("cube", shapes.box((0.45, 0.45, 0.45)), "red", (0.1, 0.05, -1.35))
    return icosphere((0.0, 0.0, 0.0), 1.0, 5, "Ball"), [cube] + panels


def _labels(image):
    from curved_reflections.engine.srgb import linear_to_srgb
    from curved_reflections.tools import metrics

    return metrics.label_image(linear_to_srgb(np.clip(image[..., :3], 0.0, 1.0)), PALETTE)


def test_refracted_fragments_lie_on_their_pixels_rays_and_stand_ins_fill_the_rest(gpu_ready, monkeypatch):
    """The fragment stage's ray cast. With no stand-ins (a fragment kept only where its
    pixel's path through the glass hits its triangle), every pixel drawn through the ball
    shows a mesh that the exact path's ray meets (measured: all but 0.7 %, within the
    pixel's margin beside a mesh's silhouette, ``OUTSIDE_PX``), though the cube
    reaches into the focus, where a triangle's corners may be answered across the ball;
    where a nearer mesh's hit is not drawn, a farther one shows (17 % of the ball's pixels
    unlike the exact paths). Stand-ins (a fragment of a triangle whose corners were all
    answered, its ray passing near it and through its mesh's bounding box) fill most of
    those (measured: 7.3 %)."""
    from curved_reflections.drawing.shader_cache import release_shaders
    from curved_reflections.engine.geometry.band_trace import BandTracer
    from curved_reflections.engine.glass import refraction_search
    from curved_reflections.tools import metrics

    surface, meshes = _lens_scene()
    view = look_at_view((0.5, 0.3, 5.0), (0.0, 0.0, 0.0), fov_y_deg=30.0, width=WIDTH, height=HEIGHT)
    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH]
    pixels = np.c_[xs.ravel(), ys.ravel()] + 0.5
    paths = GlassSet([Glass(surface, N)]).trace(*view.pixel_rays(pixels))
    glass = (paths.interfaces == 2) & (paths.total_reflections == 0)
    rays = paths.exit_position[glass], paths.direction[glass]
    truth = np.zeros((len(pixels), 4))
    truth[glass] = BandTracer([], meshes).trace_rays(*rays, 0, (0, 0, 0, 1))
    truth = _labels(truth.reshape(HEIGHT, WIDTH, 4))
    # Which meshes each ray meets, in the palette's order of their colours.
    met = np.zeros((len(pixels), len(PALETTE)), bool)
    for mesh, colour in zip(meshes, ("red", "yellow", "blue")):
        met[glass, list(PALETTE).index(colour)] = BandTracer([], [mesh]).intersect(*rays).hit
    glass = glass.reshape(HEIGHT, WIDTH)
    drawn = {}
    for reach in (0.0, refraction_search.REFRACTION_REACH):
        monkeypatch.setattr(refraction_search, "REFRACTION_REACH", reach)
        release_shaders()
        # A Refraction BSDF's ball (no Fresnel reflection to tint the labels; a ball
        # reflects no path inside, so the search is the same).
        renderer = _renderer(surface, meshes, reflects=False)
        drawn[reach] = _labels(renderer.render(view, None, (0.0, 0.0, 0.0, 1.0), trace=False))
    release_shaders()
    hits = drawn[0.0]
    shown = glass & (hits >= 0) & (hits != list(PALETTE).index("world"))
    on_ray = met.reshape(HEIGHT, WIDTH, -1)[shown, hits[shown]]
    assert glass.sum() > 2500 and shown.sum() > 0.8 * glass.sum() and on_ray.mean() > 0.99
    without, with_stand_ins = (metrics.share_differing(drawn[reach], truth, glass) for reach in drawn)
    assert with_stand_ins < 0.09 and without > 2 * with_stand_ins, (without, with_stand_ins)
