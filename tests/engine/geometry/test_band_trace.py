# SPDX-License-Identifier: GPL-3.0-or-later
"""The band tracer (``engine/geometry/band_trace.py``): pixels the pre-pass says show a
mirror have their eye rays met with the mirrors alone, and see what tracing the whole
scene sees."""

import numpy as np

from curved_reflections.engine import DiffuseMesh, look_at_view
from curved_reflections.engine.geometry.band_trace import NO_LIGHT, BandTracer
from curved_reflections.engine.geometry.sphere import icosphere


def _scene():
    ball = icosphere(np.zeros(3), 1.0, 3, "Ball")
    n = 6
    xs, ys = np.meshgrid(np.linspace(-4.0, 4.0, n), np.linspace(-4.0, 4.0, n))
    floor = np.c_[xs.ravel(), ys.ravel(), np.full(n * n, -1.2)]
    quads = [(j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i) for j in range(n - 1) for i in range(n - 1)]
    colours = np.c_[np.linspace(0.0, 1.0, n * n), np.linspace(1.0, 0.0, n * n), np.full(n * n, 0.5), np.ones(n * n)]
    box = icosphere((1.8, 0.4, 0.3), 0.4, 1, "Box")
    meshes = [DiffuseMesh("Floor", floor, np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]),
                          colours),
              DiffuseMesh("Blob", box.vertices, box.triangles, np.tile([0.9, 0.2, 0.1, 1.0], (len(box.vertices), 1)))]
    return [ball], meshes


def test_mirror_pixels_traced_with_the_mirrors_first_see_what_the_whole_scene_shows():
    """Every pixel inside the ball's silhouette (and a few just outside, which miss it and
    fall back to the whole scene) gets the same colour and distance either way."""
    reflectors, meshes = _scene()
    tracer = BandTracer(reflectors, meshes)
    view = look_at_view((0.5, -4.0, 1.5), (0.0, 0.0, 0.0), fov_y_deg=40.0, width=64, height=48)
    ys, xs = np.mgrid[0:48, 0:64]
    pixels = np.c_[xs.ravel(), ys.ravel()] + 0.5
    origins, directions = view.pixel_rays(pixels)
    on_ball = tracer.intersect(origins, directions).reflector == 0
    assert 100 < on_ball.sum() < len(pixels)
    chosen = pixels[on_ball | (np.arange(len(pixels)) % 7 == 0)]
    world = (0.05, 0.1, 0.2, 1.0)
    whole = tracer.trace(view, chosen, 1, world)
    first = tracer.trace(view, chosen, 1, world, on_mirrors=True)
    np.testing.assert_allclose(first, whole)
    assert np.isfinite(whole[:, 3]).sum() > 50  # reflections of the floor and the blob among them


def test_eye_rays_started_near_the_pre_pass_surface_see_what_the_bvh_finds():
    """Given where the pre-pass's depth puts the mirror on each pixel (here the exact hit,
    moved as float32 depth would move it, and unknown on some), the traced colours are
    those of the BVH's first hits."""
    reflectors, meshes = _scene()
    tracer = BandTracer(reflectors, meshes)
    view = look_at_view((0.5, -4.0, 1.5), (0.0, 0.0, 0.0), fov_y_deg=40.0, width=64, height=48)
    ys, xs = np.mgrid[0:48, 0:64]
    pixels = np.c_[xs.ravel(), ys.ravel()] + 0.5
    hits = tracer.intersect(*view.pixel_rays(pixels), mirrors_only=True)
    pixels, surface = pixels[hits.hit], hits.position[hits.hit]
    surface = surface + np.random.default_rng(3).normal(scale=1e-4, size=surface.shape)
    surface[::5] = np.nan
    world = (0.05, 0.1, 0.2, 1.0)
    np.testing.assert_allclose(tracer.trace(view, pixels, 2, world, on_mirrors=True, surface_points=surface),
                               tracer.trace(view, pixels, 2, world, on_mirrors=True))


def test_a_few_eye_rays_on_a_big_mirror_skip_building_its_cell_grid():
    """The grid costs a pass over every triangle: a handful of rays descend the BVH
    instead (the same hits), and the grid is built only once the rays make up for it."""
    reflectors, meshes = _scene()
    tracer = BandTracer(reflectors, meshes)
    view = look_at_view((0.5, -4.0, 1.5), (0.0, 0.0, 0.0), fov_y_deg=40.0, width=64, height=48)
    pixels = np.array([[32.5, 24.5], [30.5, 22.5]])
    surface = tracer.intersect(*view.pixel_rays(pixels), mirrors_only=True).position
    world = (0.05, 0.1, 0.2, 1.0)
    few = tracer.trace(view, pixels, 1, world, on_mirrors=True, surface_points=surface)
    assert "triangle_grid" not in vars(tracer.mirrors)  # 2 rays, 1,280 triangles
    np.testing.assert_allclose(few, tracer.trace(view, pixels, 1, world, on_mirrors=True))
    many = np.repeat(pixels, 70, axis=0)
    tracer.trace(view, many, 1, world, on_mirrors=True, surface_points=np.repeat(surface, 70, axis=0))
    assert "triangle_grid" in vars(tracer.mirrors)


def test_mirrors_and_diffuse_meshes_traced_apart_hit_as_one_set_would():
    """The tracer keeps the mirrors' set (shared with the caller's when given, so a big
    mirror's tree is built once) and the diffuse meshes' apart; their nearest hits are
    those of one set holding both, numbered the same way (diffuse after the mirrors)."""
    from curved_reflections.engine import Reflector
    from curved_reflections.engine.geometry.raytrace import ReflectorSet

    reflectors, meshes = _scene()
    mirrors = ReflectorSet(reflectors)
    tracer = BandTracer(reflectors, meshes, mirrors)
    assert tracer.mirrors is mirrors
    one = ReflectorSet(list(reflectors) + [Reflector(m.name, m.vertices, m.triangles, np.tile([0.0, 0.0, 1.0],
                                                                                             (len(m.vertices), 1)))
                                          for m in meshes])
    rng = np.random.default_rng(3)
    origins = rng.uniform(-3.0, 3.0, (2000, 3)) + (0.0, -4.0, 1.5)
    directions = rng.normal(size=(2000, 3)) + (0.0, 3.0, -1.0)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    ours, expected = tracer.intersect(origins, directions), one.intersect(origins, directions)
    assert (expected.reflector == 0).sum() > 50 and (expected.reflector > 0).sum() > 50
    np.testing.assert_array_equal(ours.triangle, expected.triangle)
    np.testing.assert_array_equal(ours.reflector, expected.reflector)
    np.testing.assert_allclose(ours.t[ours.hit], expected.t[expected.hit], rtol=1e-12)


def test_rim_gap_pixels_are_the_strip_between_a_reflection_and_the_silhouette():
    """A round footprint whose reflection covers its lower part but stops 3 pixels short
    of the silhouette (a blend's strip along a ball's rim), and shows the world above (a
    ball's sky): the strip is traced, the sky beside the silhouette is not, and of two holes
    in the reflection the one 4 pixels from the silhouette is, the one 8 pixels in is not."""
    from curved_reflections.engine.geometry.band_trace import band_pixels, rim_gap_pixels

    size = 41
    y, x = np.mgrid[0:size, 0:size]
    distance = np.hypot(x - 20, y - 20)
    labels = np.where(distance <= 18, 1.0, 0.0)
    drawn = (distance <= 15) & (y >= 20)
    drawn[20, 5] = False  # 4 pixels inside the silhouette
    drawn[30, 20] = False  # 8 pixels inside
    pixels = {tuple(p) for p in rim_gap_pixels(labels, drawn, 4).tolist()}
    strip = {(int(i), int(j)) for j, i in zip(*np.nonzero((labels > 0) & ~drawn & (distance > 15) & (y >= 21)))}
    assert strip <= pixels  # the whole strip below the reflection's rim
    assert (5, 20) in pixels and (20, 30) not in pixels
    assert not any(j < 14 for _, j in pixels)  # nothing of the sky more than 4 above the reflection
    assert (20, 10) not in pixels  # the sky next to nothing drawn
    # The same strip with band_pixels needs its radius (and takes the sky's rim with it).
    ring = {tuple(p) for p in band_pixels(labels, drawn, 4).tolist()}
    assert strip <= ring and any(j < 10 for _, j in ring)


def test_hole_pixels_are_the_undrawn_pixels_the_drawn_reflections_enclose():
    """A 40 x 40 mirror drawn but for a 10-pixel hole, a 30-pixel hole and its lower
    quarter (the world beyond the reflection's edge): the small hole is traced, the wide
    one and the quarter are not."""
    from curved_reflections.engine.geometry.band_trace import hole_pixels

    labels = np.zeros((50, 50))
    labels[5:45, 5:45] = 1.0
    drawn = labels > 0
    drawn[35:45] = False  # the lower quarter shows the world
    drawn[10:20, 10:20] = False
    wide = np.zeros_like(drawn)
    wide[12:32, 22:44] = True  # 20 x 22, wider than twice the radius
    drawn &= ~wide
    traced = {tuple(p) for p in hole_pixels(labels, drawn, 8).tolist()}
    assert {(x, y) for y in range(10, 20) for x in range(10, 20)} <= traced
    assert not any(y >= 35 for _, y in traced)
    assert sum(wide[y, x] for x, y in traced) < 0.5 * wide.sum()


def test_eye_rays_that_start_inside_a_sealed_mirror_see_no_light():
    """A view whose near plane cuts into the ball: rays starting inside it meet it from
    inside. Sealed (nothing inside), they show black at distance 0 (``NO_LIGHT``), as
    Cycles shows a closed mirror from inside once its bounces run out; the rays that
    start outside see what they saw. Held open (not sealed), they bounce on."""
    reflectors, meshes = _scene()
    tracer = BandTracer(reflectors, meshes)
    view = look_at_view((0.0, -4.0, 0.0), (0.0, 0.0, 0.0), fov_y_deg=40.0, width=64, height=48, near=3.5)
    ys, xs = np.mgrid[0:48, 0:64]
    pixels = np.c_[xs.ravel(), ys.ravel()] + 0.5
    origins, directions = view.pixel_rays(pixels)
    radius = np.linalg.norm(origins, axis=1)
    # The icosphere lies within the unit sphere, its faces down to 0.95 from the centre.
    starts_inside, starts_outside = radius < 0.95, radius > 1.0
    assert 100 < starts_inside.sum() < 0.5 * len(pixels)
    world = (0.05, 0.1, 0.2, 1.0)
    open_ball = tracer.trace(view, pixels, 2, world)
    tracer.mirrors.seal_empty_interiors(meshes)
    sealed = tracer.trace(view, pixels, 2, world)
    np.testing.assert_array_equal(sealed[starts_inside], np.tile(NO_LIGHT, (starts_inside.sum(), 1)))
    np.testing.assert_array_equal(sealed[starts_outside], open_ball[starts_outside])
    assert not np.any(np.all(open_ball[starts_inside] == NO_LIGHT, axis=1))


def test_rays_from_anywhere_see_what_pixel_rays_see_and_glass_rays_end_on_the_scene():
    """``trace_rays`` follows given rays as ``trace`` follows pixels' (the same colours
    for the same rays), also with no mirror at all: what a ray leaving glass meets."""
    reflectors, meshes = _scene()
    tracer = BandTracer(reflectors, meshes)
    view = look_at_view((0.5, -4.0, 1.5), (0.0, 0.0, 0.0), fov_y_deg=40.0, width=64, height=48)
    ys, xs = np.mgrid[0:48:3, 0:64:3]
    pixels = np.c_[xs.ravel(), ys.ravel()] + 0.5
    world = (0.05, 0.1, 0.2, 1.0)
    from_pixels = tracer.trace(view, pixels, 2, world)
    np.testing.assert_allclose(tracer.trace_rays(*view.pixel_rays(pixels), 2, world), from_pixels)
    alone = BandTracer([], meshes).trace_rays(*view.pixel_rays(pixels), 2, world)
    on_ball = tracer.intersect(*view.pixel_rays(pixels), mirrors_only=True).hit
    assert 20 < on_ball.sum() < len(pixels)
    np.testing.assert_allclose(alone[~on_ball], from_pixels[~on_ball])  # the same meshes and world
    assert (alone[on_ball] != from_pixels[on_ball]).any(axis=1).mean() > 0.5  # behind the ball, not in it
