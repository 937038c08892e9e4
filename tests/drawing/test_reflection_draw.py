# SPDX-License-Identifier: GPL-3.0-or-later
"""The offscreen reflection renderer draws what Cycles shows in curved mirrors.

``drawing/reflection_draw.py`` (SBC paper, Popescu, Sacks, Mei 2006, section V)
renders a demo scene at a small size; its labels (which object each pixel shows, the
demo scenes' flat colours, ``tools/metrics.py``) are compared with a Cycles render on
the reflector pixels (Workbench mask). A synthetic scene checks the depth order of
reflections (SBC V-A, case 2: within a reflection group the point nearer the mirror
hides the farther one). The numpy helpers (pre-subdivision, SBC V-B; the band of
pixels along a footprint's edge) are checked without a GPU.
"""

import time

import numpy as np
import pytest

from curved_reflections.engine import DiffuseMesh, look_at_view, scene_bounds
from curved_reflections.engine.methods.sbc import build_sample_based_camera
from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.engine.geometry import band_trace, subdivision
from curved_reflections.drawing.gpu_data import read_texture

WIDTH, HEIGHT = 128, 96
#: Measured on sbc_fig3 at 128x96 (d = 2, accuracy 1 px, max order 1): 1.6 % of the
#: 1801 reflector pixels disagree with Cycles (on tile edges, and on the rim where
#: floor tiles are a pixel wide). Bound with margin:
MAX_DISAGREEMENT = 0.03


# --- numpy helpers ------------------------------------------------------------------


def _edges(triangles):
    pairs = np.sort(np.stack([triangles, np.roll(triangles, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    return np.unique(pairs, axis=0, return_counts=True)


def test_subdivision_is_conforming_and_bounds_edges():
    """A closed mesh stays closed (every edge in two triangles: no T-junction), keeps its
    area and orientation, and meets each edge's limit fraction * max(radius, distance)."""
    sphere = icosphere((0.0, 0.0, 0.0), 1.0, 1)
    colors = np.random.default_rng(1).random((len(sphere.vertices), 4)).astype(np.float32)
    centres, radii = np.array([[3.0, 0.0, 0.0]]), np.array([0.5])
    vertices, triangles, new_colors = subdivision.subdivide(sphere.vertices, sphere.triangles, colors,
                                                           centres, radii, fraction=0.1)
    edges, counts = _edges(triangles)
    assert set(counts.tolist()) == {2}
    length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    middle = 0.5 * (vertices[edges[:, 0]] + vertices[edges[:, 1]])
    assert np.all(length <= subdivision.edge_limits(middle, centres, radii, 0.1) + 1e-12)
    # Uneven refinement: edges near the reflector are much shorter than far ones.
    near = np.linalg.norm(middle - centres[0], axis=1) < 2.3
    assert length[near].max() < 0.6 * length[~near].max()

    def signed_volume(v, t):
        return np.einsum("ij,ij->i", v[t[:, 0]], np.cross(v[t[:, 1]], v[t[:, 2]])).sum() / 6

    np.testing.assert_allclose(signed_volume(vertices, triangles),
                               signed_volume(sphere.vertices, sphere.triangles), rtol=1e-12)
    np.testing.assert_array_equal(vertices[:len(sphere.vertices)], sphere.vertices)  # originals kept
    # Midpoint colours are the mean of their edge's ends: colours stay in the hull.
    assert new_colors.min() >= colors.min() and new_colors.max() <= colors.max()
    assert len(triangles) > 4 * len(sphere.triangles)


def test_subdivision_leaves_short_edges_alone():
    sphere = icosphere((0.0, 0.0, 0.0), 1.0, 1)
    colors = np.ones((len(sphere.vertices), 4), np.float32)
    vertices, triangles, _ = subdivision.subdivide(sphere.vertices, sphere.triangles, colors,
                                                   np.zeros((1, 3)), np.array([100.0]), fraction=0.1)
    np.testing.assert_array_equal(triangles, sphere.triangles)
    assert len(vertices) == len(sphere.vertices)


def test_band_pixels_are_missing_reflections_along_the_footprint_edge():
    labels = np.zeros((12, 12))
    labels[2:10, 2:10] = 1.0  # a reflector's footprint
    drawn = np.zeros((12, 12), bool)
    drawn[3:9, 3:9] = True  # reflection everywhere but the footprint's outer ring...
    drawn[5, 5] = False  # ...and one hole in the middle, which is not in the band
    pixels = band_trace.band_pixels(labels, drawn, radius=1)
    ring = {(x, y) for y in range(2, 10) for x in range(2, 10) if x in (2, 9) or y in (2, 9)}
    assert {tuple(p) for p in pixels.tolist()} == ring
    # With the edges of drawn reflections, the hole beside them is traced too.
    pixels = band_trace.band_pixels(labels, drawn, radius=1, edges_of_drawn=True)
    assert {tuple(p) for p in pixels.tolist()} == ring | {(5, 5)}


def test_history_boundary_marks_pixels_between_cells_of_different_histories():
    """Cells 0-1 of a 4 x 2 ray map end in history 0, cells 2-3 go on to history 1
    (second order): at d = 2 the pixels x = 3, 4 lie between cells 1 and 2. So do they
    where cells 2-3 reflect off another smooth piece of the same mirror (a sharp edge)."""
    from types import SimpleNamespace

    cells = np.array([(i, j) for j in range(2) for i in range(4)])
    second = cells[cells[:, 0] >= 2]
    group = np.r_[np.zeros(len(cells), int), np.ones(len(second), int)]
    ray_map = SimpleNamespace(downsample=2, columns=4, rows=2, histories=[(0,), (0, 1)],
                              surfaces=[(0,), (0, 1)], cell=np.concatenate([cells, second]),
                              order=np.r_[np.ones(len(cells), int), np.full(len(second), 2)], group=group,
                              surface=group)
    edge = SimpleNamespace(downsample=2, columns=4, rows=2, histories=[(0,)], surfaces=[(0,), (1,)], cell=cells,
                           order=np.ones(len(cells), int), group=np.zeros(len(cells), int),
                           surface=(cells[:, 0] >= 2).astype(int))
    np.testing.assert_array_equal(band_trace.history_boundary(edge, 8, 4, max_order=1),
                                  band_trace.history_boundary(ray_map, 8, 4, max_order=2))
    boundary = band_trace.history_boundary(ray_map, 8, 4, max_order=2)
    assert set(np.flatnonzero(boundary.any(axis=0)).tolist()) == {3, 4}
    assert boundary[:, [3, 4]].all()
    assert not band_trace.history_boundary(ray_map, 8, 4, max_order=1).any()  # one history at order 1
    labels, drawn = np.ones((4, 8)), np.zeros((4, 8), bool)
    drawn[:, 4] = True  # a pixel with a reflection is not traced
    pixels = band_trace.band_pixels(labels, drawn, radius=0, boundary=boundary)
    assert {tuple(p) for p in pixels.tolist()} == {(3, y) for y in range(4)}


def test_barycentric_grid_tiles_the_triangle():
    points, triangles = subdivision.barycentric_grid(4)
    assert len(points) == 15 and len(triangles) == 16
    corners = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    xy = points[:, :1] * corners[0] + points[:, 1:2] * corners[1] + (1 - points.sum(axis=1))[:, None] * corners[2]
    a, b, c = xy[triangles[:, 0]], xy[triangles[:, 1]], xy[triangles[:, 2]]
    areas = 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    np.testing.assert_allclose(areas, 0.5 / 16)  # equal, same winding as the triangle, covering it


def test_push_constants_stay_small():
    from curved_reflections.drawing import draw_shaders

    assert max(draw_shaders.PUSH_CONSTANT_BYTES.values()) <= 128


# --- on the GPU ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def fig3(gpu_ready, tmp_path_factory):
    """sbc_fig3 at 128x96: our render, Cycles, the reflector mask and the palette."""
    import bpy

    import curved_reflections
    from curved_reflections.blender import demo_scenes, render_image
    from curved_reflections.blender.png import write_png
    from curved_reflections.tools import reference_render

    out = tmp_path_factory.mktemp("reflection_draw")
    curved_reflections.register()
    try:
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        scene = demo_scenes.build("sbc_fig3", bpy.context.scene, WIDTH, HEIGHT)
        bpy.data.objects["MirrorSphere"].curved_reflections.mode = 'RUNTIME'  # the sample-based camera's draw
        start = time.perf_counter()
        ours = render_image.render_scene(scene, bpy.context.evaluated_depsgraph_get(), max_order=1)
        seconds = time.perf_counter() - start
        write_png(out / "ours.png", ours.display)
        image = reference_render.read_png(out / "ours.png")  # 8-bit, as the references
        reflectors = demo_scenes.reflectors(scene)
        mask, _ = reference_render.render_mask(scene, out / "mask.png", reflectors)
        cycles = reference_render.render_cycles(scene, out / "cycles.png", samples=4, bounces=4)
        palette = demo_scenes.palette(scene)
    finally:
        curved_reflections.unregister()
    print(f"\nsbc_fig3 {WIDTH}x{HEIGHT}: ours {seconds:.2f} s ({ours.seconds}), Cycles {cycles.seconds:.2f} s")
    return {"ours": image, "result": ours, "cycles": cycles.image, "mask": mask, "palette": palette}


def _labels(image, palette):
    from curved_reflections.tools import metrics

    return metrics.label_image(image, palette)


def test_reflections_agree_with_cycles_on_the_mirror(fig3):
    from curved_reflections.tools import metrics

    ours, cycles = _labels(fig3["ours"], fig3["palette"]), _labels(fig3["cycles"], fig3["palette"])
    mask = fig3["mask"]
    share = metrics.share_differing(ours, cycles, mask)
    print(f"label disagreement on {int(mask.sum())} reflector px: {100 * share:.2f} %")
    assert share <= MAX_DISAGREEMENT


def test_mirror_shows_the_columns_and_the_cube(fig3):
    names = list(fig3["palette"])
    ours = _labels(fig3["ours"], fig3["palette"])[fig3["mask"]]
    shown = {names[k] for k in np.unique(ours)}
    assert {"Cube", "FloorA", "FloorB", "(world)"} <= shown
    assert sum(name.startswith("Column") for name in shown) >= 4
    cube = (ours == names.index("Cube")).sum()
    assert cube >= 20  # the cube's reflection, beside the cube itself


def test_pixels_off_the_mirror_show_the_objects_themselves(fig3):
    """Outside the reflectors' footprint the image is the diffuse scene (and the world),
    as Cycles shows it; the cube in front of the sphere stays in front of it."""
    from curved_reflections.tools import metrics

    ours, cycles = _labels(fig3["ours"], fig3["palette"]), _labels(fig3["cycles"], fig3["palette"])
    off = ~fig3["mask"]
    assert metrics.share_differing(ours, cycles, off) <= 0.002
    names = list(fig3["palette"])
    cube_in_front = (cycles == names.index("Cube")) & off
    assert cube_in_front.sum() > 20 and (ours[cube_in_front] == names.index("Cube")).all()


def test_timings_are_reported(fig3):
    seconds, stats = fig3["result"].seconds, fig3["result"].stats
    assert set(seconds) >= {"capture", "sbc", "draw", "total"}
    assert stats["reflected_triangles"] > stats["mesh_triangles"]  # pre-subdivided
    assert stats["traced_pixels"] > 0  # the rim was traced


def _square(name, x, size, colour):
    """A square in the plane x = ``x``, centred on the x axis, one flat colour."""
    h = size / 2
    vertices = np.array([[x, -h, -h], [x, h, -h], [x, h, h], [x, -h, h]])
    return DiffuseMesh(name, vertices, np.array([[0, 1, 2], [0, 2, 3]]), np.tile([*colour, 1.0], (4, 1)),
                       emissive=True)


def _render_squares(meshes):
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    mirror = icosphere((0.0, 0.0, 0.0), 1.0, 4, name="Mirror")
    view = look_at_view((0.0, -6.0, 0.3), (0.0, 0.0, 0.0), fov_y_deg=25.0, width=96, height=96)
    bounds = scene_bounds([mirror], meshes, margin=1.0)
    sbc = build_sample_based_camera([mirror], view, bounds, downsample=2)
    image = ReflectionRenderer([mirror], meshes).render(view, sbc, world_color=(0.0, 0.0, 1.0, 1.0))
    return image, sbc


def test_reflection_nearer_the_mirror_hides_the_farther(gpu_ready):
    """Two squares beside a mirror sphere (out of the camera's sight), a small one 2.5 from
    its centre and a large one behind it at 4: in the mirror the near square's reflection
    covers the far one's centre (SBC V-A, case 2: the point nearer the mirror along the
    reflected ray wins), and the far square shows around it. Drawing the meshes in the
    other order gives the same image: the depth test decides, not the order."""
    red, green = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    near = _square("Near", 2.5, 1.0, red)
    far = _square("Far", 4.0, 4.0, green)
    image, sbc = _render_squares([near, far])
    swapped, _ = _render_squares([far, near])
    np.testing.assert_array_equal(image, swapped)

    projected = sbc.project(np.array([[2.5, 0.0, 0.0], [4.0, 0.0, 0.0]]))
    assert projected.valid[0].all()
    for pixel in projected.pixels[0]:
        x, y = np.floor(pixel).astype(int)
        np.testing.assert_allclose(image[y, x, :3], red, atol=1e-6)
    shown = image[..., :3].reshape(-1, 3)
    assert (np.abs(shown - red).max(axis=1) < 1e-6).sum() > 10
    assert (np.abs(shown - green).max(axis=1) < 1e-6).sum() > 2 * (np.abs(shown - red).max(axis=1) < 1e-6).sum()


def test_mirror_colour_and_reflectivity_blend_with_the_world(gpu_ready):
    """A half-reflective grey mirror with nothing to reflect shows the mix of its own colour
    and the world (SBC V-D); with no reflection group in view the image is the world."""
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    mirror = icosphere((0.0, 0.0, 0.0), 1.0, 3, name="Mirror")
    square = _square("Square", -3.0, 0.5, (1.0, 0.0, 0.0))  # reflected on the left, not at the centre
    view = look_at_view((0.0, -5.0, 0.0), (0.0, 0.0, 0.0), width=48, height=48)
    bounds = scene_bounds([mirror], [square], margin=1.0)
    sbc = build_sample_based_camera([mirror], view, bounds, downsample=2)
    world = np.array([0.0, 0.0, 1.0])
    renderer = ReflectionRenderer([mirror], [square], reflector_colors=[(0.5, 0.5, 0.5)], reflectivity=[0.25])
    image = renderer.render(view, sbc, world_color=(*world, 1.0))
    centre = image[24, 24, :3]
    np.testing.assert_allclose(centre, 0.75 * 0.5 + 0.25 * world, atol=1e-6)
    np.testing.assert_allclose(image[1, 1, :3], world, atol=1e-6)  # background

    away = look_at_view((0.0, -5.0, 0.0), (0.0, -10.0, 0.0), width=32, height=32)
    empty = build_sample_based_camera([mirror], away, bounds, downsample=2)
    assert empty.groups == []
    np.testing.assert_allclose(renderer.render(away, empty, world_color=(*world, 1.0))[..., :3],
                               np.broadcast_to(world, (32, 32, 3)), atol=1e-6)


def test_draw_into_a_bound_offscreen_as_a_draw_handler_would(gpu_ready):
    """``draw`` composites into whatever framebuffer is bound (no read-back): the same
    image as ``render`` without band tracing; with ``reflectors_only`` it leaves every
    pixel off the mirrors as it was (an overlay over Blender's own viewport drawing)."""
    import gpu

    from curved_reflections.drawing.methods.sbc_gpu import SBCTextures
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    meshes = [_square("Near", 2.5, 1.0, (1.0, 0.0, 0.0)), _square("Far", 4.0, 4.0, (0.0, 1.0, 0.0))]
    mirror = icosphere((0.0, 0.0, 0.0), 1.0, 3, name="Mirror")
    view = look_at_view((0.0, -6.0, 0.3), (0.0, 0.0, 0.0), fov_y_deg=25.0, width=64, height=48)
    sbc = build_sample_based_camera([mirror], view, scene_bounds([mirror], meshes, margin=1.0), downsample=2)
    renderer = ReflectionRenderer([mirror], meshes)
    world = (0.0, 0.0, 1.0, 1.0)
    expected = renderer.render(view, sbc, world_color=world, trace=False)
    textures = SBCTextures(sbc)
    offscreen = gpu.types.GPUOffScreen(view.width, view.height, format='RGBA32F')
    try:
        images = []
        for overlay in (False, True):
            with offscreen.bind():
                framebuffer = gpu.state.active_framebuffer_get()
                framebuffer.clear(color=(0.25, 0.5, 0.75, 1.0), depth=1.0)
                renderer.draw(view, textures, world, reflectors_only=overlay)
                pixels = framebuffer.read_color(0, 0, view.width, view.height, 4, 0, 'FLOAT')
            pixels.dimensions = view.width * view.height * 4
            images.append(np.array(pixels, dtype=np.float32).reshape(view.height, view.width, 4))
    finally:
        offscreen.free()
    np.testing.assert_allclose(images[0], expected, atol=1e-6)
    on_mirror = np.any(np.abs(expected[..., :3] - world[:3]) > 1e-6, axis=2)  # the reflections
    np.testing.assert_allclose(images[1][on_mirror], expected[on_mirror], atol=1e-6)
    np.testing.assert_allclose(images[1][0, 0], (0.25, 0.5, 0.75, 1.0), atol=1e-6)  # untouched


def _draw_scene_as_blender_would(view, meshes, color):
    """Every mesh in one colour with the depth test into the bound framebuffer: the
    scene's depth that a viewport's draw handler finds there."""
    import gpu
    from gpu_extras.batch import batch_for_shader
    from mathutils import Matrix

    shader = gpu.shader.from_builtin('UNIFORM_COLOR')
    gpu.state.depth_test_set('LESS_EQUAL')
    gpu.state.depth_mask_set(True)
    with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
        gpu.matrix.load_matrix(Matrix(np.asarray(view.view_matrix).tolist()))
        gpu.matrix.load_projection_matrix(Matrix(np.asarray(view.projection_matrix).tolist()))
        shader.bind()
        shader.uniform_float("color", color)
        for mesh in meshes:
            batch_for_shader(shader, 'TRIS', {"pos": mesh.vertices.astype(np.float32)},
                             indices=mesh.triangles.astype(np.int32)).draw(shader)
    gpu.state.depth_test_set('NONE')
    gpu.state.depth_mask_set(False)


@pytest.mark.parametrize("orthographic", [False, True])
def test_the_overlay_is_hidden_where_the_scene_depth_has_an_object_in_front(gpu_ready, orthographic):
    """The viewport's pre-pass draws the mirrors alone; what stands in front of a
    mirror hides the reflection through the depth test against the scene's depth that
    Blender drew. Over a scene drawn in grey (mirror and meshes), the overlay shows the
    render's pixels wherever the mirror is the nearest surface, keeps the grey where a
    square in front of the mirror hides it, and leaves the rest untouched; no mirror
    pixel of the render is lost to the scene's own depth of the mirror (the bias)."""
    import gpu

    from curved_reflections.engine.view import View
    from curved_reflections.drawing.methods.sbc_gpu import SBCTextures
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    blocker = _square("Blocker", 0.0, 0.5, (1.0, 0.0, 1.0))
    blocker = DiffuseMesh("Blocker", blocker.vertices[:, [1, 0, 2]] + (0.3, -2.0, 0.1), blocker.triangles,
                          blocker.colors, emissive=True)
    meshes = [_square("Near", 2.5, 1.0, (1.0, 0.0, 0.0)), _square("Far", 4.0, 4.0, (0.0, 1.0, 0.0)), blocker]
    mirror = icosphere((0.0, 0.0, 0.0), 1.0, 3, name="Mirror")
    view = look_at_view((0.0, -6.0, 0.3), (0.0, 0.0, 0.0), fov_y_deg=25.0, width=64, height=48)
    if orthographic:
        projection = np.diag([1.0 / 1.8, 1.0 / 1.35, -2.0 / 19.9, 1.0])
        projection[2, 3] = -20.1 / 19.9  # clipping from 0.1 to 20
        view = View(view.view_matrix, projection, view.width, view.height)
    sbc = build_sample_based_camera([mirror], view, scene_bounds([mirror], meshes, margin=1.0), downsample=2)
    renderer = ReflectionRenderer([mirror], meshes)
    world, grey, untouched = (0.0, 0.0, 1.0, 1.0), (0.5, 0.5, 0.5, 1.0), (0.25, 0.5, 0.75, 1.0)
    expected = renderer.render(view, sbc, world_color=world, trace=False)
    labels = read_texture(renderer.draw_passes(view, SBCTextures(sbc), sbc).prepass_labels, view.width, view.height)
    shows_mirror = labels[..., 0] > 0.5
    mirror_only = read_texture(renderer.draw_passes(view, SBCTextures(sbc), sbc, mirrors_only=True).prepass_labels,
                               view.width, view.height)[..., 0] > 0.5
    hidden = mirror_only & ~shows_mirror  # the blocker in front of the mirror
    offscreen = gpu.types.GPUOffScreen(view.width, view.height, format='RGBA32F')
    try:
        with offscreen.bind():
            framebuffer = gpu.state.active_framebuffer_get()
            framebuffer.clear(color=untouched, depth=1.0)
            _draw_scene_as_blender_would(view, [mirror, *meshes], grey)
            renderer.draw(view, SBCTextures(sbc), world, reflectors_only=True)
            pixels = framebuffer.read_color(0, 0, view.width, view.height, 4, 0, 'FLOAT')
    finally:
        offscreen.free()
    pixels.dimensions = view.width * view.height * 4
    image = np.array(pixels, dtype=np.float32).reshape(view.height, view.width, 4)
    assert hidden.sum() >= 40 and shows_mirror.sum() >= 400
    # Along the blocker's outline the render's pre-pass ends the mirror's footprint: its
    # triangles with a corner there are dropped and the composite fills d pixels from
    # the nearest reflection; the overlay's footprint goes on behind the blocker.
    rows, columns = np.nonzero(hidden)
    y, x = np.mgrid[:view.height, :view.width]
    near_blocker = np.min(np.hypot(y[..., None] - rows, x[..., None] - columns), axis=2) <= 3.0
    away = shows_mirror & ~near_blocker
    np.testing.assert_allclose(image[away], expected[away], atol=1e-6)
    np.testing.assert_allclose(image[hidden], np.broadcast_to(grey, (int(hidden.sum()), 4)), atol=1e-6)
    elsewhere = ~mirror_only
    assert np.all(np.isclose(image[elsewhere], grey, atol=1e-6).all(axis=1)
                  | np.isclose(image[elsewhere], untouched, atol=1e-6).all(axis=1))
    # The composite draws the mirror's projected bounding box only: every mirror pixel,
    # under three quarters of the view here (the ball fills half of it).
    x0, y0, x1, y1 = renderer.mirrors_rect(view, renderer.targets(view.width, view.height))
    rows, columns = np.nonzero(mirror_only)
    centre_x, centre_y = 2.0 * (columns + 0.5) / view.width - 1.0, 2.0 * (rows + 0.5) / view.height - 1.0
    assert x0 < centre_x.min() and centre_x.max() < x1 and y0 < centre_y.min() and centre_y.max() < y1
    assert (x1 - x0) * (y1 - y0) < 0.75 * 4.0



# --- the cached projection ----------------------------------------------------------


def _red_pixels(targets):
    """Pixels (x, y) of the reflection target that show the red square."""
    from curved_reflections.drawing.gpu_data import read_texture

    colors = read_texture(targets.reflection_colors, targets.width, targets.height)
    red = (colors[..., 3] > 0.5) & (colors[..., 0] > 0.5) & (colors[..., 1] < 0.1) & (colors[..., 2] < 0.1)
    return np.argwhere(red)[:, ::-1]


def test_redraws_reuse_the_projection_and_a_moved_view_places_the_world_reflector_points(gpu_ready):
    """The projection runs once per camera: redraws, from the camera's view or another,
    run no projection pass. From a moved view, with the old camera, the reflection is
    drawn where the moved view sees the *first reflector points* (world space) of the
    reflected geometry: the red square's centre reflects at the moved view's pixel of
    its reflector point, not at its pixel in the old view."""
    from curved_reflections.drawing.methods.sbc_gpu import SBCTextures
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    mirror = icosphere((0.0, 0.0, 0.0), 1.0, 4, name="Mirror")
    square = _square("Near", 2.5, 1.0, (1.0, 0.0, 0.0))
    view = look_at_view((0.0, -6.0, 0.3), (0.0, 0.0, 0.0), fov_y_deg=25.0, width=96, height=96)
    moved = look_at_view((0.9, -6.0, 0.6), (0.1, 0.0, 0.0), fov_y_deg=25.0, width=96, height=96)
    sbc = build_sample_based_camera([mirror], view, scene_bounds([mirror], [square], margin=1.0), downsample=2)
    renderer = ReflectionRenderer([mirror], [square])
    textures = SBCTextures(sbc)
    first = _red_pixels(renderer.draw_passes(view, textures, sbc))
    _red_pixels(renderer.draw_passes(view, textures, sbc))
    assert renderer.counts == {"projections": 1, "frames": 2}
    shown = _red_pixels(renderer.draw_passes(moved, textures, sbc))
    assert renderer.counts == {"projections": 1, "frames": 3}  # the old camera, no new projection

    reflector_point = sbc.project(np.array([[2.5, 0.0, 0.0]])).reflector_points[0]
    expected = moved.to_pixels(reflector_point)[0][0]
    old = view.to_pixels(reflector_point)[0][0]
    assert np.linalg.norm(expected - old) > 5.0  # the view moved enough to tell them apart
    assert len(first) > 10 and len(shown) > 10
    np.testing.assert_allclose(first.mean(axis=0) + 0.5, old, atol=1.5)
    np.testing.assert_allclose(shown.mean(axis=0) + 0.5, expected, atol=1.5)

    # A new camera's textures project once more; the old one is still cached.
    other = SBCTextures(sbc)
    renderer.draw_passes(view, other, sbc)
    renderer.draw_passes(view, textures, sbc)
    assert renderer.counts["projections"] == 2


def test_the_viewport_snaps_the_cameras_reflected_triangles_within_its_accuracy(gpu_ready):
    """With the camera's Accuracy (a viewport frame, ``warm``), every reflected vertex is
    drawn at the centre of its cell of a grid that many pixels apart: the red square's
    reflection moves, by at most half a cell (and a pixel of rasterisation) on each axis;
    a render (not warm) places it exactly."""
    from curved_reflections.drawing.methods.sbc_gpu import SBCTextures
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    mirror = icosphere((0.0, 0.0, 0.0), 1.0, 4, name="Mirror")
    square = _square("Near", 2.5, 1.0, (1.0, 0.0, 0.0))
    view = look_at_view((0.0, -6.0, 0.3), (0.0, 0.0, 0.0), fov_y_deg=25.0, width=96, height=96)
    sbc = build_sample_based_camera([mirror], view, scene_bounds([mirror], [square], margin=1.0), downsample=2)
    renderer = ReflectionRenderer([mirror], [square])
    textures = SBCTextures(sbc)
    exact = _red_pixels(renderer.draw_passes(view, textures, sbc))
    np.testing.assert_array_equal(_red_pixels(renderer.draw_passes(view, textures, sbc, accuracy_px=8.0)), exact)
    snapped = _red_pixels(renderer.draw_passes(view, textures, sbc, warm=True, accuracy_px=8.0))
    assert len(exact) > 20 and len(snapped) > 20
    assert len(snapped) != len(exact) or np.any(snapped != exact)
    offsets = np.abs(snapped[:, None, :] - exact[None, :, :]).max(axis=2)  # Chebyshev, pixels
    assert offsets.min(axis=1).max() <= 5 and offsets.min(axis=0).max() <= 5


def test_per_sheet_culling_leaves_the_image_identical(gpu_ready):
    """The teapot at 320 x 240 splits its reflection into sheets (per smooth piece, and
    where rays cross); projecting in each
    sheet only the vertex chunks that meet its bounds (engine/methods/sbc/sheet_bounds.py) skips
    vertices (about 3 %: the floor is seen by most sheets) and changes no pixel."""
    import bpy

    import curved_reflections
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer
    from curved_reflections.blender import demo_scenes
    from curved_reflections.blender.capture import capture_scene, view_from_camera
    from curved_reflections.blender.render_inputs import BOUNDS_MARGIN

    curved_reflections.register()
    try:
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        scene = demo_scenes.build("teapot", bpy.context.scene, 320, 240)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        captured = capture_scene(depsgraph)
        view = view_from_camera(scene.camera, scene, depsgraph)
    finally:
        curved_reflections.unregister()
    lo, hi = scene_bounds(captured.reflectors, captured.meshes)
    bounds = scene_bounds(captured.reflectors, captured.meshes, BOUNDS_MARGIN * float(np.linalg.norm(hi - lo)))
    sbc = build_sample_based_camera(captured.reflectors, view, bounds, downsample=2)
    assert len(sbc.groups) > 4
    images, projected = [], []
    for cull in (True, False):
        renderer = ReflectionRenderer(captured.reflectors, captured.meshes, cull=cull)
        images.append(renderer.render(view, sbc, trace=False))
        projected.append(renderer.stats["projected_vertices"])
    np.testing.assert_array_equal(images[0], images[1])
    assert projected[1] == len(sbc.groups) * len(renderer.geometry.vertices)
    assert projected[0] < projected[1]


def test_unreliable_cells_mark_ray_list_fold_and_mixed_cells_and_their_pixels():
    """A pixel without a drawn reflection inside a ray-list, fold or mixed cell is traced
    (band_trace.unreliable_cells), and so is one in the four cells around a ray of a
    ray-list leaf with no complete cell; one in a camera-leaf cell far from any edge is not."""
    from types import SimpleNamespace

    ray_map = SimpleNamespace(rows=6, columns=6, downsample=2, cell=np.array([[0, 0], [5, 0], [5, 5]]))
    tree = SimpleNamespace(cells=SimpleNamespace(lo=np.array([[1.0, 1.0]])), list_rays=np.zeros(0, np.int64))
    no_cells = SimpleNamespace(cells=None, list_rays=np.array([2]))  # one ray, at cell (5, 5)
    fold_index = np.full((6, 6), -1)
    fold_index[3, 4] = 0
    mixed_index = np.full((6, 6), -1)
    mixed_index[4, 2] = 0
    cells = band_trace.unreliable_cells(ray_map, [tree, no_cells], [SimpleNamespace(index=mixed_index)],
                                        [SimpleNamespace(index=fold_index)])
    assert cells.sum() == 7 and cells[1, 1] and cells[3, 4] and cells[4, 2] and cells[4:, 4:].all()
    pixels = band_trace.cell_pixels_mask(cells, 2, 12, 12)
    # Cell (1, 1) is the square between ray centres 3 and 5 px: pixels 3 and 4 on each axis.
    np.testing.assert_array_equal(np.argwhere(pixels[:6, :6]), [[3, 3], [3, 4], [4, 3], [4, 4]])
    labels = np.zeros((12, 12))
    labels[1:11, 1:11] = 1.0
    drawn = np.zeros((12, 12), bool)
    drawn[2:10, 2:10] = True
    drawn[3, 3] = drawn[6, 6] = False  # a hole in the ray-list cell, one in a camera-leaf cell
    traced = {tuple(p) for p in band_trace.band_pixels(labels, drawn, radius=0, boundary=pixels).tolist()}
    assert (3, 3) in traced and (6, 6) not in traced
    assert all(pixels[y, x] for x, y in traced)  # only pixels of unreliable cells (radius 0)
    # The drawn pixels there too (band_trace.drawn_pixels_in): the other three of the cell.
    doubtful = {tuple(p) for p in band_trace.drawn_pixels_in(labels, drawn, pixels).tolist()}
    assert {(4, 3), (3, 4), (4, 4)} <= doubtful and not doubtful & traced
    assert all(pixels[y, x] and drawn[y, x] for x, y in doubtful)


def test_a_traced_colour_replaces_a_drawn_reflection_in_unreliable_cells(gpu_ready, monkeypatch):
    """Where the camera knows its answers are doubtful (here: every cell), each mirror
    pixel is traced, drawn or not, while the image's budget allows, and the composite shows
    the traced colour: a crumpled mirror's drawn images may be of the wrong point.
    Elsewhere the drawn reflection stays."""
    from curved_reflections.drawing import reflection_draw

    meshes = [_square("Red", -3.0, 4.0, (1.0, 0.0, 0.0)), _square("Green", 3.0, 4.0, (0.0, 1.0, 0.0))]
    sentinel = np.array([1.0, 0.0, 1.0])  # what the stubbed tracer sees: no square is magenta

    def magenta(self, view, pixels, *args, **kwargs):
        out = np.zeros((len(pixels), 4))
        out[:, :3] = sentinel
        return out

    monkeypatch.setattr(band_trace.BandTracer, "trace", magenta)
    image, _ = _render_squares(meshes)
    is_magenta = np.all(np.abs(image[..., :3] - sentinel) < 1e-4, axis=2)
    reflected = np.any(np.abs(image[..., :3] - [1.0, 0.0, 0.0]) < 1e-3, axis=2)
    assert reflected.sum() > 50 and is_magenta.sum() < 0.5 * reflected.sum()  # the band only

    def every_cell(ray_map, *args, **kwargs):
        return np.ones((ray_map.rows, ray_map.columns), dtype=bool)

    monkeypatch.setattr(band_trace, "unreliable_cells", every_cell)
    # The mirror is 40 % of this image: over the budget the drawn pixels are not traced.
    over_budget, _ = _render_squares(meshes)
    assert np.all(np.abs(over_budget[..., :3] - [1.0, 0.0, 0.0]) < 1e-3, axis=2).sum() > 50
    monkeypatch.setattr(reflection_draw, "MAX_TRACED_FRACTION", 1.0)
    image, sbc = _render_squares(meshes)
    rows, columns = np.mgrid[0:image.shape[0], 0:image.shape[1]]
    origins, directions = sbc.ray_map.view.pixel_rays(np.stack([columns.ravel(), rows.ravel()], axis=1) + 0.5)
    along = -np.einsum("ij,ij->i", origins, directions)  # the unit sphere at the origin, well inside
    on_mirror = (np.linalg.norm(origins + along[:, None] * directions, axis=1) < 0.95).reshape(image.shape[:2])
    shown = np.all(np.abs(image[..., :3] - [1.0, 0.0, 0.0]) < 1e-3, axis=2)
    assert on_mirror.sum() > 500 and not (shown & on_mirror).any()  # every red reflection traced over
    assert np.all(np.abs(image[..., :3] - sentinel) < 1e-4, axis=2).sum() > is_magenta.sum() + 50
