# SPDX-License-Identifier: GPL-3.0-or-later
"""Mixed triangles, shading and reflector properties of the reflection renderer.

SBC paper (Popescu, Sacks, Mei 2006) section V: a mixed triangle (some corners project,
some not) is subdivided so its reflection ends where projection ends (V-B); reflected
objects keep their colour, emission unlit, otherwise lit, textures through their UVs
(V-C); the reflector blends its reflection by Fresnel and distance (V-D). A flat mirror
makes every expected pixel exact: the reflection of p in the plane z = 0 is p mirrored.
"""

import numpy as np

from curved_reflections.engine import DiffuseMesh, Reflector, look_at_view, scene_bounds
from curved_reflections.engine.methods.sbc import build_sample_based_camera
from curved_reflections.engine.geometry.band_trace import SHADE_AMBIENT

SIZE = 64
HALF = 1.5  # the mirror is the square [-HALF, HALF]^2 in z = 0
WORLD = np.array([0.0, 0.0, 1.0])


def _mirror():
    v = np.array([[-HALF, -HALF, 0.0], [HALF, -HALF, 0.0], [HALF, HALF, 0.0], [-HALF, HALF, 0.0]])
    return Reflector("Mirror", v, np.array([[0, 1, 2], [0, 2, 3]]), np.tile([0.0, 0.0, 1.0], (4, 1)))


def _view(fov=30.0):
    """Looking down at the mirror at 45 degrees; objects 2 or 3 above it with y >= 0.8 are
    out of its direct sight (and, with fov 30, inside the mirror's reflection)."""
    return look_at_view((0.0, -4.0, 4.0), (0.0, 0.0, 0.0), fov_y_deg=fov, width=SIZE, height=SIZE)


def _render(meshes, trace=True, fov=30.0, view=None, edge_fraction=None, **kwargs):
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    mirror, view = _mirror(), view or _view(fov)
    sbc = build_sample_based_camera([mirror], view, scene_bounds([mirror], meshes, margin=1.0), downsample=2)
    renderer = ReflectionRenderer([mirror], meshes, edge_fraction=edge_fraction, **kwargs)
    return renderer.render(view, sbc, world_color=(*WORLD, 1.0), trace=trace, fill_radius=0), renderer


def _mirror_hits(view):
    """Per pixel centre: on the mirror, the mirror point, the reflected direction, cos of incidence."""
    ys, xs = np.mgrid[0:SIZE, 0:SIZE]
    origins, directions = view.pixel_rays(np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], axis=1))
    t = -origins[:, 2] / directions[:, 2]
    points = origins + t[:, None] * directions
    on = (np.abs(points[:, :2]) <= HALF).all(axis=1) & (t > 0)
    reflected = directions * np.array([1.0, 1.0, -1.0])
    return on.reshape(SIZE, SIZE), points, reflected, np.abs(directions[:, 2])


def _triangle(name, corners, colour, emissive=True, **kwargs):
    return DiffuseMesh(name, np.asarray(corners, float), np.array([[0, 1, 2]]),
                       np.tile([*colour, 1.0], (3, 1)), emissive=emissive, **kwargs)


def _in_triangle(points2, corners2):
    a, b, c = corners2
    def side(p, q, r):
        return (q[0] - p[0]) * (r[:, 1] - p[1]) - (q[1] - p[1]) * (r[:, 0] - p[0])
    s1, s2, s3 = side(a, b, points2), side(b, c, points2), side(c, a, points2)
    return ((s1 >= 0) & (s2 >= 0) & (s3 >= 0)) | ((s1 <= 0) & (s2 <= 0) & (s3 <= 0))


def test_mixed_triangle_edge_follows_the_true_boundary(gpu_ready):
    """One large triangle 2 above the mirror, out of the camera's sight: only corner A's
    reflection lies on the mirror, so the triangle is mixed. Dropped (the paper's
    baseline, mixed_subdivisions=0) nothing of it is drawn; subdivided, its reflection
    matches the exact one (ray cast per pixel) except within 1 px of its boundary."""
    corners = np.array([[0.0, 1.5, 2.0], [4.0, 5.0, 2.0], [-4.0, 5.0, 2.0]])
    mesh = _triangle("Big", corners, (1.0, 0.0, 0.0))
    view = _view(40.0)
    on, points, reflected, _ = _mirror_hits(view)
    to_plane = (2.0 - points[:, 2]) / reflected[:, 2]
    hit = points + to_plane[:, None] * reflected
    truth = (on.ravel() & _in_triangle(hit[:, :2], corners[:, :2])).reshape(SIZE, SIZE)
    assert 100 < truth.sum() < on.sum() - 100  # the reflection covers part of the mirror

    image, renderer = _render([mesh], fov=40.0)
    assert renderer.stats["mixed_triangles"] == 1
    red = np.abs(image[..., :3] - (1.0, 0.0, 0.0)).max(axis=2) < 1e-5
    wrong = (red != truth) & on
    boundary = np.zeros_like(truth)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            boundary |= np.roll(np.roll(truth, dy, axis=0), dx, axis=1) != truth
    assert not (wrong & ~boundary).any(), f"{int((wrong & ~boundary).sum())} px wrong away from the edge"
    print(f"\nmixed triangle: {int(wrong.sum())} of {int(truth.sum())} px differ, all within 1 px of the edge")

    dropped, _ = _render([mesh], trace=False, fov=40.0, mixed_subdivisions=0)
    drawn = np.abs(dropped[..., :3] - (1.0, 0.0, 0.0)).max(axis=2) < 1e-5
    assert drawn.sum() == 0


def test_emission_is_unlit_and_other_colours_are_lit_with_the_true_eye_vector(gpu_ready):
    """A horizontal triangle 2 above the mirror, seen in it along the reflected ray r:
    lit, it shows colour (AMBIENT + (1 - AMBIENT) |n . r|) (the true eye vector, not the
    camera's), emissive its colour exactly."""
    corners = np.array([[-1.6, 0.8, 2.0], [1.6, 0.8, 2.0], [0.0, 2.6, 2.0]])
    view = _view()
    on, points, reflected, _ = _mirror_hits(view)
    hit = points + ((2.0 - points[:, 2]) / reflected[:, 2])[:, None] * reflected
    inside = (on.ravel() & _in_triangle(hit[:, :2], corners[:, :2])).reshape(SIZE, SIZE)
    colour = np.array([0.8, 0.6, 0.2])
    # Interior pixels only (the edges are rasterised): erode by 2 px.
    core = inside.copy()
    for dy in (-2, -1, 0, 1, 2):
        for dx in (-2, -1, 0, 1, 2):
            core &= np.roll(np.roll(inside, dy, axis=0), dx, axis=1)
    assert core.sum() > 200
    emitted, _ = _render([_triangle("Glow", corners, colour, emissive=True)])
    np.testing.assert_allclose(emitted[core][:, :3], np.broadcast_to(colour, (int(core.sum()), 3)), atol=1e-5)

    lit, _ = _render([_triangle("Lit", corners, colour, emissive=False)])
    cosine = np.abs(reflected[:, 2]).reshape(SIZE, SIZE)[core]  # n = (0, 0, +-1)
    expected = colour[None, :] * (SHADE_AMBIENT + (1 - SHADE_AMBIENT) * cosine)[:, None]
    np.testing.assert_allclose(lit[core][:, :3], expected, atol=2e-3)
    # The desired view's eye vector would light it differently: what is checked is the true one.
    camera = np.array([0.0, -4.0, 4.0]) - hit.reshape(SIZE, SIZE, 3)[core]
    seen_from_camera = np.abs(camera[:, 2]) / np.linalg.norm(camera, axis=1)
    assert np.abs(seen_from_camera - cosine).mean() > 0.05


def test_textured_plane_reflection_shows_its_texture(gpu_ready):
    """A checker image of four quarters (red, green / blue, white) on a quad through its
    UVs: each quarter of the reflected quad shows its colour (emissive: unlit)."""
    quarters = np.array([[[1, 0, 0, 1], [0, 1, 0, 1]], [[0, 0, 1, 1], [1, 1, 1, 1]]], np.float32)
    texels = np.repeat(np.repeat(quarters, 4, axis=0), 4, axis=1)  # 8 x 8: pure inside each quarter
    corners = np.array([[-2.0, 0.8, 2.0], [2.0, 0.8, 2.0], [2.0, 4.0, 2.0], [-2.0, 4.0, 2.0]])
    uvs = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    quad = DiffuseMesh("Textured", corners, np.array([[0, 1, 2], [0, 2, 3]]), np.ones((4, 4)), emissive=True,
                       uvs=uvs, image=texels)
    image, _ = _render([quad])
    view = _view()
    on, points, reflected, _ = _mirror_hits(view)
    hit = points + ((2.0 - points[:, 2]) / reflected[:, 2])[:, None] * reflected
    u = (hit[:, 0] + 2.0) / 4.0
    v = (hit[:, 1] - 0.8) / 3.2
    shown = image[..., :3].reshape(-1, 3)
    found = set()
    # Pixels well inside one quarter (away from the bilinear blend across texel borders).
    for (i, j) in ((0, 0), (1, 0), (0, 1), (1, 1)):
        quarter = on.ravel() & (np.abs(u - (0.25 + 0.5 * i)) < 0.1) & (np.abs(v - (0.25 + 0.5 * j)) < 0.1)
        if quarter.sum() < 3:
            continue
        np.testing.assert_allclose(shown[quarter], np.broadcast_to(quarters[j, i, :3], (int(quarter.sum()), 3)),
                                   atol=0.02)
        found.add((i, j))
    assert len(found) == 4


def test_fresnel_raises_the_reflected_share_at_grazing_angles(gpu_ready):
    """Nothing to reflect: the mirror shows mix(own colour, world, w), w = Schlick's
    F0 + (1 - F0)(1 - cos t)^5 with cos t from the exact view ray per pixel."""
    far = _triangle("Away", [[20.0, 20.0, -5.0], [21.0, 20.0, -5.0], [20.0, 21.0, -5.0]], (1.0, 0.0, 0.0))
    own = np.array([1.0, 1.0, 0.0])
    f0 = 0.2
    grazing = look_at_view((0.0, -5.0, 1.2), (0.0, 0.0, 0.0), fov_y_deg=30.0, width=SIZE, height=SIZE)
    image, _ = _render([far], view=grazing, reflector_colors=[own], fresnel_f0=[f0])
    on, _, _, cosine = _mirror_hits(grazing)
    weight = f0 + (1 - f0) * (1 - cosine.reshape(SIZE, SIZE)[on]) ** 5
    expected = (1 - weight)[:, None] * own + weight[:, None] * WORLD
    np.testing.assert_allclose(image[on][:, :3], expected, atol=2e-3)
    assert weight.max() - weight.min() > 0.1  # the share rises toward the grazing top of the image
    plain, _ = _render([far], view=grazing, reflector_colors=[own])
    np.testing.assert_allclose(plain[on][:, :3], np.broadcast_to(WORLD, (int(on.sum()), 3)), atol=1e-6)


def test_attenuation_fades_reflections_with_distance(gpu_ready):
    """A horizontal emissive triangle at height 2, then 3, above the mirror, seen in it:
    with fade distance A each shows mix(colour, world, min(1, (d / A)^2)) for its
    reflected-ray distance d from the mirror."""
    colour = np.array([1.0, 0.0, 0.0])
    corners = np.array([[-1.6, 0.8, 1.0], [1.6, 0.8, 1.0], [0.0, 2.6, 1.0]])
    attenuation = 3.0
    view = _view()
    on, points, reflected, _ = _mirror_hits(view)
    for height in (2.0, 3.0):
        tri = _triangle("Strip", corners * [1, 1, height], colour)
        # Pre-subdivided: distances are interpolated linearly in the image across a triangle.
        image, _ = _render([tri], attenuation_distance=[attenuation], edge_fraction=0.02)
        distance = (height - points[:, 2]) / reflected[:, 2]
        hit = points + distance[:, None] * reflected
        inside = (on.ravel() & _in_triangle(hit[:, :2], corners[:, :2])).reshape(SIZE, SIZE)
        core = inside & np.roll(inside, 2, 0) & np.roll(inside, -2, 0) & np.roll(inside, 2, 1) & np.roll(inside, -2, 1)
        assert core.sum() > 100
        fade = np.minimum(1.0, (distance.reshape(SIZE, SIZE)[core] / attenuation) ** 2)
        expected = (1 - fade)[:, None] * colour + fade[:, None] * WORLD
        np.testing.assert_allclose(image[core][:, :3], expected, atol=1e-2)
