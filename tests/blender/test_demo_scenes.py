# SPDX-License-Identifier: GPL-3.0-or-later
"""The demo scenes: built by code, measurable (distinct flat colours), mirrors exact."""

import numpy as np
import pytest

import bpy

from curved_reflections.engine.geometry import shapes
from curved_reflections.engine.srgb import linear_to_srgb
from curved_reflections.blender import demo_scenes
from curved_reflections.tools import metrics, reference_render


@pytest.fixture
def build(registered):
    """Build a demo scene into a fresh scene; remove that scene afterwards."""
    built = []

    def _build(kind, width=64, height=48):
        scene = demo_scenes.build(kind, bpy.data.scenes.new(f"test_{kind}"), width, height)
        built.append(scene)
        return scene

    yield _build
    for scene in built:
        bpy.data.scenes.remove(scene)


def _world_vertices(obj) -> np.ndarray:
    local = np.empty(len(obj.data.vertices) * 3)
    obj.data.vertices.foreach_get("co", local)
    matrix = np.array(obj.matrix_world)
    return local.reshape(-1, 3) @ matrix[:3, :3].T + matrix[:3, 3]


def _corner_normals(mesh) -> tuple[np.ndarray, np.ndarray]:
    """(corner vertex indices, corner normals) as Blender shades them."""
    vertex = np.empty(len(mesh.loops), dtype=np.int64)
    mesh.loops.foreach_get("vertex_index", vertex)
    normals = np.empty(len(mesh.loops) * 3)
    mesh.corner_normals.foreach_get("vector", normals)
    return vertex, normals.reshape(-1, 3)


@pytest.mark.parametrize("kind", sorted(demo_scenes.BUILDERS))
def test_scene_has_camera_marked_mirrors_and_resolution(build, kind):
    scene = build(kind, 80, 60)
    assert scene.camera is not None and scene.camera.type == "CAMERA"
    assert (scene.render.resolution_x, scene.render.resolution_y) == (80, 60)
    assert scene.view_settings.view_transform == "Standard"
    mirrors = demo_scenes.reflectors(scene)
    glass = [o for o in scene.objects if o.curved_reflections.is_refractor]
    assert mirrors or glass
    for obj in glass:
        shader = next(n for n in obj.active_material.node_tree.nodes if n.type == "BSDF_GLASS")
        assert shader.inputs["IOR"].default_value == pytest.approx(demo_scenes.GLASS_IOR)
    for obj in mirrors:
        assert len(obj.data.polygons) > 0
        assert obj.data.has_custom_normals
        bsdf = next(n for n in obj.active_material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
        assert bsdf.inputs["Metallic"].default_value == 1.0
        assert bsdf.inputs["Roughness"].default_value == 0.0
        assert tuple(bsdf.inputs["Base Color"].default_value) == (1.0, 1.0, 1.0, 1.0)


@pytest.mark.parametrize("kind", sorted(demo_scenes.BUILDERS))
def test_every_diffuse_object_has_a_distinct_flat_emission_colour(build, kind):
    scene = build(kind)
    palette = demo_scenes.palette(scene)
    diffuse = [o for o in scene.objects if o.type == "MESH" and not o.curved_reflections.is_reflector
               and not o.curved_reflections.is_refractor]
    assert sorted(palette) == sorted([demo_scenes.WORLD_KEY] + [o.name for o in diffuse])
    display = linear_to_srgb(np.array(list(palette.values())))
    gaps = np.linalg.norm(display[:, None] - display[None, :], axis=2) + 10 * np.eye(len(display))
    assert gaps.min() >= 0.49  # far apart in display space: labels survive noise and blending
    for obj in diffuse:
        assert len(obj.material_slots) == 1
        nodes = obj.active_material.node_tree.nodes
        assert {n.type for n in nodes} == {"EMISSION", "OUTPUT_MATERIAL"}
        assert np.allclose(obj.color[:3], palette[obj.name])
        assert np.allclose(obj.active_material.diffuse_color[:3], palette[obj.name])


def test_vase_follows_chen_arvo_profile_with_analytic_normals(build):
    scene = build("vase")
    (vase,) = demo_scenes.reflectors(scene)
    points = _world_vertices(vase)
    assert len(points) == 96 * 65
    assert points[:, 2].min() == pytest.approx(0.0) and points[:, 2].max() == pytest.approx(2.0)
    radius = np.hypot(points[:, 0], points[:, 1])
    t = points[:, 2] / 2.0
    assert np.allclose(radius, 5.80 * t**3 - 9.78 * t**2 + 3.90 * t + 0.47, atol=1e-5)
    vertex, normals = _corner_normals(vase.data)
    p = points[vertex]
    expected = np.stack([p[:, 0] / np.hypot(p[:, 0], p[:, 1]), p[:, 1] / np.hypot(p[:, 0], p[:, 1]),
                         -shapes.vase_radius_slope(p[:, 2])], axis=1)
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    assert np.abs(normals - expected).max() < 2e-3  # custom normals are stored compressed


def test_sphere_mirror_normals_point_from_centre(build):
    scene = build("sbc_fig3")
    (sphere,) = demo_scenes.reflectors(scene)
    points = _world_vertices(sphere)
    vertex, normals = _corner_normals(sphere.data)
    expected = points[vertex] - np.array(sphere.location)
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    assert np.abs(normals - expected).max() < 2e-3


def test_two_spheres_are_close_but_apart(build):
    scene = build("two_spheres")
    (a, b) = sorted(demo_scenes.reflectors(scene), key=lambda o: o.name)
    centre_a, radius_a = reference_render.reflector_bounds(a)
    centre_b, radius_b = reference_render.reflector_bounds(b)
    gap = np.linalg.norm(centre_a - centre_b) - radius_a - radius_b
    assert 0.05 < gap < 0.3


def test_teapot_parts_face_outward():
    teapot = shapes.teapot(32)
    v, n, tri = teapot.vertices, teapot.normals, teapot.triangles
    geometric = np.cross(v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]])
    area = np.linalg.norm(geometric, axis=1)
    agree = np.einsum("ij,ij->i", geometric, n[tri].sum(axis=1)) > 0
    assert agree[area > 1e-12].all()


def test_operator_adds_a_demo_scene(registered):
    before = set(bpy.data.scenes)
    assert bpy.ops.curved_reflections.add_demo_scene(demo="two_spheres", width=40, height=30) == {"FINISHED"}
    (added,) = set(bpy.data.scenes) - before
    try:
        assert len(demo_scenes.reflectors(added)) == 2
        assert added.render.resolution_x == 40
    finally:
        bpy.data.scenes.remove(added)


def test_tiny_cycles_render_and_mask_show_the_palette(build, tmp_path):
    scene = build("sbc_fig3", 32, 24)
    mirrors = demo_scenes.reflectors(scene)
    mask, _ = reference_render.render_mask(scene, tmp_path / "mask.png", mirrors)
    assert mask.shape == (24, 32) and 20 < mask.sum() < 400
    assert mask[12, 16]  # the sphere is in the middle of the frame
    result = reference_render.render_cycles(scene, tmp_path / "cycles.png", samples=2)
    palette = demo_scenes.palette(scene)
    labels = metrics.label_image(result.image, palette, max_distance=0.1)
    assert (labels >= 0).mean() > 0.95  # flat emission colours come out exactly
    names = metrics.palette_names(palette)
    assert labels[-1, 16] == names.index(demo_scenes.WORLD_KEY)  # top row (rows go up): sky
    assert result.seconds > 0 and result.path.exists()
