# SPDX-License-Identifier: GPL-3.0-or-later
"""Glass ray traced per pixel on the GPU (drawing/methods/glass_trace.py, glsl/scene_bvh.glsl,
glsl/scene_colors.glsl, glsl/glass_trace.glsl), against the same model on the CPU: the exact
paths through the glass (engine/glass/paths.py) met with the scene by the CPU's ray tracer
(engine/geometry/band_trace.py), mixed by Fresnel as Render Image mixes them without the GPU
(``GlassLayer.trace``)."""

import numpy as np

from curved_reflections.drawing.methods.scene_tables import EMPTY_NODE, LEAF_SIZE, SLOT_TEXELS, bvh_tables
from curved_reflections.engine.geometry import shapes
from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.engine.glass import Glass, GlassSet
from curved_reflections.engine.scene import DiffuseMesh
from curved_reflections.engine.view import look_at_view
from curved_reflections.tools.surfaces import flat_box, torus

N = 1.5
WIDTH, HEIGHT = 160, 120
#: What the GPU's colour may differ from the CPU's by (float32 against float64 paths).
CLOSE = 0.02


def test_the_packed_tree_holds_every_triangle_once_within_its_nodes_boxes():
    """Each triangle in one slot, as its first corner and two edges (float32) with its
    corners' indices; each slot's corners inside its leaf's box, and each node's box
    inside its parent's; empty nodes and slots marked; each node carries the order its
    parent visits its children in."""
    ball = icosphere((0.3, -0.2, 1.0), 1.0, 2, "Ball")
    triangles = ball.triangles[: len(ball.triangles) - 7]  # not a power of two: empty slots
    boxes, slots, leaf_first = bvh_tables(ball.vertices, triangles)
    slots = slots.reshape(-1, SLOT_TEXELS, 4)
    filled = slots[:, 0, 3] >= 0
    held = slots[filled, :, 3].astype(int)
    assert filled.sum() == len(triangles) and len(slots) == leaf_first * LEAF_SIZE
    assert (slots[~filled] == -1.0).all()
    index = {tuple(t): k for k, t in enumerate(triangles.tolist())}
    assert len({index[tuple(t)] for t in held.tolist()}) == len(triangles)
    corners = ball.vertices[held].astype(np.float32)
    assert (slots[filled, 0, :3] == corners[:, 0]).all()
    assert (slots[filled, 1:, :3] == corners[:, 1:] - corners[:, :1]).all()
    leaves = leaf_first + np.flatnonzero(filled) // LEAF_SIZE
    eps = 1e-6
    assert (corners >= boxes[2 * leaves, None, :3] - eps).all()
    assert (corners <= boxes[2 * leaves + 1, None, :3] + eps).all()
    nodes = np.arange(2, 2 * leaf_first)
    used = np.abs(boxes[2 * nodes, 3]) < EMPTY_NODE
    parents = nodes[used] // 2
    assert (np.abs(boxes[2 * parents, 3]) < EMPTY_NODE).all() and (~used).any()
    orders = boxes[2 * (nodes // 2) + 1, 3]
    assert np.isin(np.abs(orders), (1, 2, 3)).all()
    assert (boxes[2 * nodes, 3] == np.where(used, orders, orders + np.sign(orders) * EMPTY_NODE)).all()
    assert (boxes[2 * nodes[used], :3] >= boxes[2 * parents, :3] - eps).all()
    assert (boxes[2 * nodes[used] + 1, :3] <= boxes[2 * parents + 1, :3] + eps).all()


def test_each_object_fills_a_subtree_of_its_own():
    """A floor of two big triangles and a ball of 320 beside it, grouped: the ball's
    triangles fill one subtree (its node's box is the ball's), the floor's another, so a
    ray inside the ball never meets a node the floor's triangles swell."""
    ball = icosphere((0.0, 0.0, 1.0), 1.0, 2, "Ball")
    floor = np.array([[-9.0, -9.0, 0.0], [9.0, -9.0, 0.0], [9.0, 9.0, 0.0], [-9.0, 9.0, 0.0]])
    vertices = np.concatenate([ball.vertices, floor])
    triangles = np.concatenate([ball.triangles, len(ball.vertices) + np.array([[0, 1, 2], [0, 2, 3]])])
    groups = np.r_[np.zeros(len(ball.triangles), int), np.ones(2, int)]
    boxes, slots, leaf_first = bvh_tables(vertices, triangles, groups)
    ball_leaves = 1 << int(np.ceil(np.log2(len(ball.triangles) / LEAF_SIZE)))
    node = leaf_first // ball_leaves  # the ball's subtree: the first node of its level
    assert np.allclose(boxes[2 * node, :3], ball.vertices.min(axis=0), atol=1e-6)
    assert np.allclose(boxes[2 * node + 1, :3], ball.vertices.max(axis=0), atol=1e-6)
    held = slots.reshape(-1, SLOT_TEXELS, 4)[: ball_leaves * LEAF_SIZE, 0, 3]
    assert ((held >= 0) == (np.arange(len(held)) < len(ball.triangles))).all()


def _floor_and_panel():
    """A floor of two colours under the glass and a panel of a third behind it."""
    floor = shapes.box((8.0, 8.0, 0.1))
    panel = shapes.box((6.0, 0.1, 4.0))
    colour = np.where(floor.vertices[:, :1] > 0.0, [[0.9, 0.2, 0.1, 1.0]], [[0.1, 0.7, 0.2, 1.0]])
    return [DiffuseMesh("Floor", floor.vertices + (0.0, 0.0, -1.2), floor.triangles, colour.astype(np.float32)),
            DiffuseMesh("Panel", panel.vertices + (0.0, 2.5, 0.5), panel.triangles,
                        np.tile((0.2, 0.3, 1.0, 1.0), (len(panel.vertices), 1)).astype(np.float32))]


def _against_the_cpu(glasses, meshes, view, world=(0.3, 0.3, 0.6), mirrors=(), max_order=1):
    """The glass of ``glasses`` before ``meshes`` traced on the GPU and on the CPU: (the
    pixels the pre-pass saw glass on, which of them differ by more than :data:`CLOSE`, the
    renderer)."""
    from curved_reflections.blender.glass_layer import GlassLayer, glass_renderer
    from curved_reflections.drawing.gpu_data import read_texture
    from curved_reflections.engine.geometry.band_trace import BandTracer

    renderer = glass_renderer(glasses, meshes, world=world, mirrors=mirrors, max_order=max_order)
    image = renderer.render(view, None, world + (1.0,), trace=False)
    labels = read_texture(renderer.targets(WIDTH, HEIGHT).prepass_labels, WIDTH, HEIGHT)
    rows, columns = np.nonzero(labels[..., 0] >= 0.5)
    layer = GlassLayer((), GlassSet(list(glasses)), renderer, BandTracer(list(mirrors), meshes), traced=False)
    truth = layer.trace(view, np.stack([columns, rows], axis=1) + 0.5, np.array(world + (1.0,)), max_order)
    wrong = np.abs(image[rows, columns, :3] - truth).max(axis=1) > CLOSE
    return (rows, columns), wrong, renderer


def test_a_glass_box_shows_what_render_image_traces_reflected_inside_and_out(gpu_ready):
    """A glass box seen from above its front (2,407 of its pixels' paths reflect totally
    inside its sides), a Glass BSDF: every pixel as the CPU traces it, the Fresnel mix of
    the front reflection, the refracted path and the ray reflected back inside where it
    leaves (measured: every one); no vertex is searched."""
    from curved_reflections.drawing.methods.glass_trace import GlassTracePass

    view = look_at_view((2.5, -5.0, 3.5), (0.0, 0.0, 0.0), fov_y_deg=35.0, width=WIDTH, height=HEIGHT)
    box = Glass(flat_box("Box", (-0.8, -0.8, -0.8), (0.8, 0.8, 0.8)), N, True)
    (rows, _), wrong, renderer = _against_the_cpu([box], _floor_and_panel(), view)
    assert [p.name for p in renderer.passes][1:] == [GlassTracePass.name]
    assert len(rows) > 3000 and wrong.mean() < 0.005, wrong.mean()


def test_glass_that_is_not_convex_and_glass_seen_through_glass_are_traced_as_render_image_traces_them(gpu_ready):
    """A glass torus (its rays leave and enter it again) with a glass ball seen through
    its hole, behind it: the GPU follows every interface of both, as the CPU does
    (measured: all but 0.5 % of their pixels, 1.7 % of those whose paths cross both,
    along silhouettes, where float32 and float64 rays part)."""
    view = look_at_view((0.3, -5.0, 1.2), (0.0, 0.0, 0.0), fov_y_deg=35.0, width=WIDTH, height=HEIGHT)
    ring = Glass(torus((0.0, 0.0, 0.0), 1.0, 0.35, 48, 24, "Ring"), N, True)
    ball = Glass(icosphere((0.2, 1.6, 0.0), 0.5, 4, "Ball"), 1.33, True)
    rows_columns, wrong, _ = _against_the_cpu([ring, ball], _floor_and_panel(), view)
    paths = GlassSet([ring, ball]).trace(*view.pixel_rays(np.stack(rows_columns[::-1], axis=1) + 0.5))
    both = (paths.history == 0).any(axis=1) & (paths.history == 1).any(axis=1)
    assert (paths.interfaces >= 4).sum() > 1000 and both.sum() > 100
    assert wrong.mean() < 0.01 and wrong[both].mean() < 0.03, (wrong.mean(), wrong[both].mean())


def _textured(mesh, image):
    return DiffuseMesh(mesh.name, mesh.vertices, mesh.triangles, mesh.colors,
                       uvs=0.25 * mesh.vertices[:, :2], image=image)


def test_every_image_texture_is_sampled_and_past_the_atlas_left_to_the_search(gpu_ready, monkeypatch):
    """The floor and the panel behind the box with image textures of other sizes, after
    five other textured meshes out of sight (their images the seventh and sixth of the
    scene's, in the atlas beside five others): traced as the CPU samples them. Where the
    images do not fit the atlas (its rows cut to one here), the layer draws the glass by
    the refraction search (and Render Image traces it on the CPU)."""
    from curved_reflections.blender.glass_layer import glass_layer
    from curved_reflections.drawing.methods import image_atlas
    from types import SimpleNamespace

    floor, panel = _floor_and_panel()
    checker = np.ones((2, 3, 4), np.float32)
    checker[0, 0, :3] = checker[1, 1, :3] = checker[0, 2, :3] = (0.2, 0.2, 0.9)
    stripes = np.ones((5, 1, 4), np.float32)
    stripes[::2, 0, :3] = (0.9, 0.6, 0.1)
    hidden = [_textured(DiffuseMesh(f"Hidden{k}", panel.vertices - (0.0, 0.0, 50.0), panel.triangles, panel.colors),
                        np.full((k + 1, 4, 4), 0.5, np.float32)) for k in range(5)]
    meshes = hidden + [_textured(floor, checker), _textured(panel, stripes)]
    view = look_at_view((2.5, -5.0, 3.5), (0.0, 0.0, 0.0), fov_y_deg=35.0, width=WIDTH, height=HEIGHT)
    box = Glass(flat_box("Box", (-0.8, -0.8, -0.8), (0.8, 0.8, 0.8)), N, True)
    (rows, _), wrong, _ = _against_the_cpu([box], meshes, view)
    assert len(rows) > 3000 and wrong.mean() < 0.005, wrong.mean()
    for limit, traced in ((image_atlas.MAX_TEXTURE_HEIGHT, True), (1, False)):
        monkeypatch.setattr(image_atlas, "MAX_TEXTURE_HEIGHT", limit)
        layer = glass_layer(None, SimpleNamespace(glass=[box], meshes=meshes, reflectors=[]), ())
        assert layer.traced == traced and [p.name for p in layer.renderer.passes][1:] == (
            ["glass trace"] if traced else ["refraction"])


def test_a_mirror_behind_glass_shows_what_it_reflects_as_render_image_traces_it(gpu_ready):
    """A glass ball before a mirror tilted to reflect a panel of two colours above it:
    the pixels whose paths through the ball meet the mirror show the panel the mirror
    reflects, as the CPU traces it to Max Order 1 (measured: every one of the ball's
    pixels within 0.02); at Max Order 0 the mirror shows the world, as the CPU's does."""
    from curved_reflections.engine import Reflector
    from curved_reflections.engine.geometry.band_trace import BandTracer

    ball = Glass(icosphere((0.0, 0.0, 0.0), 1.0, 5, "Ball"), N, False)
    across, up = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, -1.0]) / np.sqrt(2.0)
    corners = (0.0, 0.0, -2.5) + 3.0 * np.array([-across - up, across - up, across + up, -across + up])
    mirror = Reflector("Mirror", corners, np.array([[0, 1, 2], [0, 2, 3]]), np.tile([0.0, 1.0, 1.0], (4, 1)))
    panel = shapes.box((8.0, 0.1, 8.0))
    colour = np.where(panel.vertices[:, :1] > 0.0, [[0.9, 0.8, 0.1, 1.0]], [[0.6, 0.1, 0.8, 1.0]])
    meshes = [DiffuseMesh("Panel", panel.vertices + (0.0, 4.0, -2.5), panel.triangles, colour.astype(np.float32))]
    view = look_at_view((0.3, 0.2, 5.0), (0.0, 0.0, 0.0), fov_y_deg=30.0, width=WIDTH, height=HEIGHT)
    for order in (1, 0):
        (rows, columns), wrong, _ = _against_the_cpu([ball], meshes, view, (0.2, 0.2, 0.2), [mirror], order)
        paths = GlassSet([ball]).trace(*view.pixel_rays(np.stack([columns, rows], axis=1) + 0.5))
        reflected = BandTracer([mirror], meshes).trace_rays(paths.origin, paths.direction, 1, (0.2, 0.2, 0.2, 1.0))
        mirrored = np.isfinite(reflected[:, 3]) & (reflected[:, 3] > 0.0)
        assert len(rows) > 2500 and mirrored.sum() > 1000 and wrong.mean() < 0.01, (order, wrong.mean())


def test_glass_inside_glass_is_traced_and_named(gpu_ready):
    """A bubble of water inside a glass ball: the trace goes on from the bubble as if
    into air, as the CPU does (measured: all but 0.04 % of the pixels), and names the
    outer ball as the glass whose pixels met it."""
    view = look_at_view((0.3, -4.0, 0.5), (0.0, 0.0, 0.0), fov_y_deg=35.0, width=WIDTH, height=HEIGHT)
    ball = Glass(icosphere((0.0, 0.0, 0.0), 1.0, 4, "Ball"), N, True)
    bubble = Glass(icosphere((0.1, 0.0, 0.0), 0.4, 3, "Bubble"), 1.33, True)
    (rows, _), wrong, renderer = _against_the_cpu([ball, bubble], _floor_and_panel(), view)
    assert len(rows) > 2000 and wrong.mean() < 0.01, wrong.mean()
    from curved_reflections.drawing.gpu_data import read_texture

    labels = read_texture(renderer.targets(WIDTH, HEIGHT).prepass_labels, WIDTH, HEIGHT)
    assert renderer.pass_named("glass trace").nested(labels) == ("Ball",)


def test_a_glass_objects_solid_mesh_is_left_out_of_the_tables_and_the_image_indices_kept():
    """A renderer of mirrors draws glass as a solid mesh too (its geometry's images count
    that mesh's texture); the trace's tables hold the glass's own triangles instead, and
    the meshes after it keep their images' indices."""
    from types import SimpleNamespace

    from curved_reflections.drawing.methods.scene_tables import GLASS_CODE, SceneTables

    ball = icosphere((0.0, 0.0, 0.0), 1.0, 2, "Ball")
    panel = flat_box("Panel", (-1.0, 3.0, -1.0), (1.0, 3.1, 1.0))
    image = np.ones((2, 2, 4), np.float32)

    def mesh(name, shape):
        count = len(shape.vertices)
        return DiffuseMesh(name, shape.vertices, shape.triangles, np.ones((count, 4), np.float32),
                           uvs=np.zeros((count, 2)), image=image)

    tables = SceneTables([mesh("Ball", ball), mesh("Panel", panel)], SimpleNamespace(shift=np.zeros(3)),
                         glasses=[Glass(ball, 1.5, True)])
    _, triangles, codes, *_ = tables._arrays()
    assert len(triangles) == len(panel.triangles) + len(ball.triangles)
    assert set(codes[:len(panel.triangles)]) == {1.0}  # the panel's image is the geometry's second
    assert set(codes[len(panel.triangles):]) == {GLASS_CODE}


def test_a_scene_too_large_for_the_tables_is_refused_naming_its_largest_mesh(monkeypatch):
    """Tables taller than a texture may be are refused naming the largest object to
    simplify (a mesh, a mirror or glass), before any texture is made (rows cut to one
    here: 4096 texels, fewer than the slots)."""
    from types import SimpleNamespace

    import pytest

    from curved_reflections.drawing.methods import scene_tables
    from curved_reflections.engine.errors import SceneInputError

    monkeypatch.setattr(scene_tables, "MAX_TEXTURE_HEIGHT", 1)
    ball = icosphere((0.0, 0.0, 0.0), 1.0, 4, "Ball")  # 5,120 triangles: 15,360 slot texels
    meshes = [DiffuseMesh(name, shape.vertices, shape.triangles, np.ones((len(shape.vertices), 4), np.float32))
              for name, shape in (("Panel", flat_box("Panel", (-1.0, 3.0, -1.0), (1.0, 3.1, 1.0))), ("Ball", ball))]
    tables = scene_tables.SceneTables(meshes, SimpleNamespace(shift=np.zeros(3)))
    with pytest.raises(SceneInputError, match="more than the GPU's ray trace holds") as error:
        tables._ensure()
    assert error.value.object_name == "Ball"
    # Glass alone, no diffuse mesh: the glass is named.
    tables = scene_tables.SceneTables([], SimpleNamespace(shift=np.zeros(3)), glasses=[Glass(ball, N, True)])
    with pytest.raises(SceneInputError, match="more than the GPU's ray trace holds") as error:
        tables._ensure()
    assert error.value.object_name == "Ball"
