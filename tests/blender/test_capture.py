# SPDX-License-Identifier: GPL-3.0-or-later
"""Capture of real Blender scenes: modifiers, transforms, normals, colours, views, bad input."""

import math

import bpy
import numpy as np
import pytest
from bpy_extras.object_utils import world_to_camera_view
from bpy_extras.view3d_utils import location_3d_to_region_2d
from mathutils import Vector

from curved_reflections.engine.errors import SceneInputError
from curved_reflections.blender.capture import capture_scene, view_from_camera, view_from_region

pytestmark = pytest.mark.usefixtures("registered")


def _link(obj):
    bpy.context.scene.collection.objects.link(obj)
    return obj


def mesh_object(name, vertices, faces, *, smooth=True):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(vertices, [], faces)
    mesh.update()
    if smooth:
        mesh.shade_smooth()
    return _link(bpy.data.objects.new(name, mesh))


def cube_object(name, *, smooth=True):
    corners = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return mesh_object(name, corners, faces, smooth=smooth)


def folded_quads(name):
    """Two quads sharing the edge x = 1, folded 45 degrees: 6 vertices."""
    vertices = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 1), (2, 1, 1)]
    return mesh_object(name, vertices, [(0, 1, 2, 3), (1, 4, 5, 2)])


def reflector(obj):
    obj.curved_reflections.is_reflector = True
    return obj


def capture(**kwargs):
    captured = capture_scene(bpy.context.evaluated_depsgraph_get(), **kwargs)
    return {r.name: r for r in captured.reflectors}, {m.name: m for m in captured.meshes}


def material(name, *, base=None, emission=None, strength=0.0):
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender 4.x: new materials start without nodes
        mat.use_nodes = True
    principled = mat.node_tree.nodes["Principled BSDF"]
    if base is not None:
        principled.inputs["Base Color"].default_value = base
    if emission is not None:
        principled.inputs["Emission Color"].default_value = emission
    principled.inputs["Emission Strength"].default_value = strength
    return mat


# --- geometry -------------------------------------------------------------------------


def test_subdivision_modifier_is_applied_and_smooth_normals_point_outward(empty_scene):
    cube = reflector(cube_object("Cube"))
    cube.modifiers.new("Subdivision", 'SUBSURF').levels = 1
    mirror = capture()[0]["Cube"]
    # One Catmull-Clark step of a cube: 8 + 12 + 6 = 26 vertices, 24 quads = 48 triangles.
    assert mirror.vertices.shape == (26, 3)
    assert mirror.triangles.shape == (48, 3)
    assert np.all(np.sum(mirror.normals * mirror.vertices, axis=1) > 0)
    # By symmetry the normal at the limit position of a cube corner is the diagonal.
    corner = np.argmax(mirror.vertices @ np.ones(3))
    np.testing.assert_allclose(mirror.normals[corner], np.ones(3) / math.sqrt(3), atol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(mirror.normals, axis=1), 1.0, atol=1e-6)


def test_bevel_modifier_on_a_flat_cube_splits_reflector_vertices_per_face(empty_scene):
    cube = reflector(cube_object("Cube", smooth=False))
    bevel = cube.modifiers.new("Bevel", 'BEVEL')
    bevel.width, bevel.segments = 0.1, 1
    mirror = capture()[0]["Cube"]
    # 6 faces + 12 edge quads + 8 corner triangles; every corner keeps its face's normal.
    assert mirror.triangles.shape == (6 * 2 + 12 * 2 + 8, 3)
    assert mirror.vertices.shape == (6 * 4 + 12 * 4 + 8 * 3, 3)
    facing_up = mirror.normals[:, 2] > 1 - 1e-6
    assert facing_up.sum() == 4  # the top face's own corners, inset by the bevel
    np.testing.assert_allclose(mirror.vertices[facing_up, 2], 1.0, atol=1e-6)
    np.testing.assert_allclose(np.abs(mirror.vertices[facing_up, :2]), 0.9, atol=1e-6)


def test_bevelled_diffuse_mesh_keeps_shared_vertices(empty_scene):
    reflector(folded_quads("Mirror"))
    bevel = cube_object("Box").modifiers.new("Bevel", 'BEVEL')
    bevel.width, bevel.segments = 0.1, 1
    box = capture()[1]["Box"]
    assert box.vertices.shape == (24, 3)  # one colour: no split
    assert box.triangles.shape == (44, 3)


def test_world_transform_moves_points_and_normals_by_inverse_transpose(empty_scene):
    # One triangle tilted 45 degrees about y: its smooth normal is (-1, 0, 1) / sqrt 2.
    obj = reflector(mesh_object("Tilted", [(0, 0, 0), (1, 0, 1), (0, 1, 0)], [(0, 1, 2)]))
    obj.location = (1, 2, 3)
    obj.rotation_euler = (0, 0, math.pi / 2)
    obj.scale = (2, 1, 1)
    mirror = capture()[0]["Tilted"]
    # Scale x by 2 then rotate +90 degrees about z: (x, y, z) -> (-y, 2x, z), then translate.
    expected = {(1, 2, 3), (1, 4, 4), (0, 2, 3)}
    assert {tuple(np.round(v, 6)) for v in mirror.vertices} == expected
    # Normal: inverse-transpose scales x by 1/2, -> (-0.5, 0, 1); rotated -> (0, -0.5, 1).
    np.testing.assert_allclose(mirror.normals, [[0, -0.5, 1] / np.linalg.norm([0, -0.5, 1])] * 3, atol=1e-6)


@pytest.mark.parametrize("scale", [(1, 1, 1), (-1, 1, 1)])
def test_winding_agrees_with_normals_under_mirroring_scale(empty_scene, scale):
    obj = reflector(mesh_object("Tri", [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)]))
    obj.scale = scale
    mirror = capture()[0]["Tri"]
    a, b, c = mirror.vertices[mirror.triangles[0]]
    assert np.dot(np.cross(b - a, c - a), mirror.normals[0]) > 0
    np.testing.assert_allclose(mirror.normals, [[0, 0, 1]] * 3, atol=1e-6)


def test_sharp_edge_splits_vertices_and_smooth_edge_shares_them(empty_scene):
    obj = reflector(folded_quads("Fold"))
    smooth = capture()[0]["Fold"]
    assert smooth.vertices.shape == (6, 3)
    shared = np.isclose(smooth.vertices[:, 0], 1)
    # The shared edge's normal bisects the two faces' normals (0,0,1) and (-1,0,1)/sqrt 2.
    expected = np.array([0, 0, 1]) + np.array([-1, 0, 1]) / math.sqrt(2)
    np.testing.assert_allclose(smooth.normals[shared], [expected / np.linalg.norm(expected)] * 2, atol=1e-5)

    shared_edge = next(e for e in obj.data.edges if set(e.vertices) == {1, 2})
    shared_edge.use_edge_sharp = True
    obj.data.update()
    sharp = capture()[0]["Fold"]
    assert sharp.vertices.shape == (8, 3)
    at_edge = np.isclose(sharp.vertices[:, 0], 1)
    normals = {tuple(np.round(n, 5)) for n in sharp.normals[at_edge]}
    assert normals == {(0, 0, 1), tuple(np.round([-1 / math.sqrt(2), 0, 1 / math.sqrt(2)], 5))}


def test_custom_split_normals_are_honoured(empty_scene):
    obj = reflector(mesh_object("Custom", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)]))
    obj.data.normals_split_custom_set([(0.0, 0.6, 0.8)] * len(obj.data.loops))
    obj.data.update()
    mirror = capture()[0]["Custom"]
    assert mirror.vertices.shape == (4, 3)
    # Custom normals are stored compressed: equal to about 1e-4.
    np.testing.assert_allclose(mirror.normals, [[0, 0.6, 0.8]] * 4, atol=1e-3)


def test_reflectors_known_unchanged_are_taken_from_the_earlier_capture(empty_scene):
    """After a diffuse object's edit the live view passes the earlier reflectors on: each
    one is taken by name, not read again, unless it is an instance (its instancer may
    have moved); a reflector new since then is read."""
    reflector(cube_object("Mirror"))
    collection = bpy.data.collections.new("Mirrors")
    collection.objects.link(reflector(bpy.data.objects.new("Inner", cube_object("Plain").data)))
    _link(bpy.data.objects.new("Instancer", None)).instance_type = 'COLLECTION'
    bpy.data.objects["Instancer"].instance_collection = collection
    bpy.data.objects["Instancer"].location.x = 5.0
    depsgraph = bpy.context.evaluated_depsgraph_get()
    earlier = capture_scene(depsgraph).reflectors
    assert {r.name for r in earlier} == {"Mirror", "Inner (instanced by Instancer)"}
    bpy.data.objects["Instancer"].location.x = 8.0
    reflector(cube_object("Added")).location.x = -5.0
    now = {r.name: r for r in capture_scene(bpy.context.evaluated_depsgraph_get(),
                                            reflectors_as_before=earlier).reflectors}
    assert now["Mirror"] is earlier[[r.name for r in earlier].index("Mirror")]
    assert now["Inner (instanced by Instancer)"].vertices[:, 0].min() == pytest.approx(7.0)
    assert now["Added"].vertices[:, 0].max() == pytest.approx(-4.0)


def test_hidden_objects_are_not_captured_and_instances_get_unique_names(empty_scene):
    reflector(folded_quads("Mirror"))
    cube_object("Hidden").hide_set(True)
    cube_object("Disabled").hide_viewport = True
    collection = bpy.data.collections.new("Props")
    inner = bpy.data.objects.new("Prop", cube_object("Template").data)
    collection.objects.link(inner)
    for k, x in enumerate((10, 20)):
        empty = _link(bpy.data.objects.new(f"Instancer{k}", None))
        empty.instance_type, empty.instance_collection = 'COLLECTION', collection
        empty.location.x = x
    meshes = capture()[1]
    assert set(meshes) == {"Template", "Prop (instanced by Instancer0)", "Prop (instanced by Instancer1)"}
    assert meshes["Prop (instanced by Instancer1)"].vertices[:, 0].min() == pytest.approx(19)


def test_curve_text_and_metaball_objects_are_captured_once(empty_scene):
    """Blender lists these objects twice (as themselves and as an instance of their own
    evaluated mesh); each is captured once, a metaball mirror too."""
    bpy.ops.curve.primitive_bezier_circle_add(location=(3, 0, 0))
    ring = bpy.context.active_object
    ring.name, ring.data.bevel_depth = "Ring", 0.2
    bpy.ops.object.text_add(location=(-3, 0, 0))
    bpy.context.active_object.name = "Label"
    bpy.ops.object.metaball_add(type='BALL', location=(0, 3, 0))
    blob = reflector(bpy.context.active_object)
    blob.name = "Blob"
    cube_object("Box")
    reflectors, meshes = capture()
    assert list(reflectors) == ["Blob"]
    assert sorted(meshes) == ["Box", "Label", "Ring"]
    assert len(meshes["Ring"].triangles) > 100 and len(reflectors["Blob"].triangles) > 100


def test_text_object_is_a_diffuse_mesh(empty_scene):
    reflector(folded_quads("Mirror"))
    text = _link(bpy.data.objects.new("Label", bpy.data.curves.new("Label", 'FONT')))
    text.data.body = "A"
    label = capture()[1]["Label"]
    assert len(label.triangles) > 4


# --- colours --------------------------------------------------------------------------


def test_base_colour_and_emission_colours(empty_scene):
    reflector(folded_quads("Mirror"))
    plain = cube_object("Plain")
    plain.data.materials.append(material("Base", base=(0.2, 0.4, 0.6, 1.0)))
    glowing = cube_object("Glowing")
    glowing.data.materials.append(
        material("Glow", base=(0.2, 0.4, 0.6, 1.0), emission=(1.0, 0.5, 0.0, 1.0), strength=5.0)
    )
    meshes = capture()[1]
    np.testing.assert_allclose(meshes["Plain"].colors, [[0.2, 0.4, 0.6, 1.0]] * 8, atol=1e-6)
    assert not meshes["Plain"].emissive
    np.testing.assert_allclose(meshes["Glowing"].colors, [[1.0, 0.5, 0.0, 1.0]] * 8, atol=1e-6)
    assert meshes["Glowing"].emissive


def test_emission_node_into_the_output_is_emissive(empty_scene):
    reflector(folded_quads("Mirror"))
    mat = material("EmissionNode")
    tree = mat.node_tree
    emission = tree.nodes.new('ShaderNodeEmission')
    emission.inputs["Color"].default_value = (0.0, 1.0, 0.25, 1.0)
    emission.inputs["Strength"].default_value = 2.0
    output = next(n for n in tree.nodes if n.bl_idname == 'ShaderNodeOutputMaterial')
    tree.links.new(emission.outputs[0], output.inputs["Surface"])
    cube_object("Sign").data.materials.append(mat)
    sign = capture()[1]["Sign"]
    np.testing.assert_allclose(sign.colors, [[0.0, 1.0, 0.25, 1.0]] * 8, atol=1e-6)
    assert sign.emissive


def test_two_materials_split_shared_vertices_by_colour(empty_scene):
    reflector(folded_quads("Mirror"))
    obj = folded_quads("TwoTone")
    obj.data.materials.append(material("Red", base=(1, 0, 0, 1)))
    obj.data.materials.append(material("Blue", base=(0, 0, 1, 1)))
    obj.data.polygons[1].material_index = 1
    obj.data.update()
    two_tone = capture()[1]["TwoTone"]
    assert two_tone.vertices.shape == (8, 3)  # the shared edge's 2 vertices, once per colour
    colors = {tuple(c) for c in two_tone.colors}
    assert colors == {(1, 0, 0, 1), (0, 0, 1, 1)}


def test_textured_base_colour_falls_back_to_viewport_display_colour(empty_scene):
    reflector(folded_quads("Mirror"))
    mat = material("Textured")
    mat.diffuse_color = (0.3, 0.3, 0.1, 1.0)
    texture = mat.node_tree.nodes.new('ShaderNodeTexImage')
    mat.node_tree.links.new(texture.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    cube_object("Crate").data.materials.append(mat)
    np.testing.assert_allclose(capture()[1]["Crate"].colors, [[0.3, 0.3, 0.1, 1.0]] * 8, atol=1e-6)


def test_image_texture_in_base_colour_is_captured_with_uvs(empty_scene):
    """An Image Texture into Base Color: the mesh carries the image (linear), its active
    UV map per corner and white vertex colours; every diffuse mesh carries its normals."""
    reflector(folded_quads("Mirror"))
    image = bpy.data.images.new("Checker", 4, 2, alpha=True)
    pixels = np.tile([0.5, 0.25, 1.0, 1.0], 8).astype(np.float32)
    image.pixels.foreach_set(pixels)
    mat = material("Textured")
    texture = mat.node_tree.nodes.new('ShaderNodeTexImage')
    texture.image = image
    mat.node_tree.links.new(texture.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    quads = folded_quads("Crate")
    quads.data.materials.append(mat)
    layer = quads.data.uv_layers.new(name="UVMap")
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0], [1, 0], [1, 1], [0, 1]], np.float32) * 0.5
    layer.uv.foreach_set("vector", uvs.ravel())
    mesh = capture()[1]["Crate"]
    assert mesh.image.shape == (2, 4, 4)
    from curved_reflections.engine.srgb import srgb_to_linear
    np.testing.assert_allclose(mesh.image[0, 0, :3], srgb_to_linear([0.5, 0.25, 1.0]), atol=5e-3)  # 8-bit
    assert mesh.uvs.shape == (len(mesh.vertices), 2)
    assert {tuple(np.round(uv, 3)) for uv in mesh.uvs} == {tuple(uv) for uv in np.round(uvs, 3)}
    np.testing.assert_allclose(mesh.colors[:, :3], 1.0)
    np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-6)


def test_no_material_uses_object_colour_or_colour_attribute(empty_scene):
    reflector(folded_quads("Mirror"))
    cube_object("Tinted").color = (0.5, 0.25, 0.125, 1.0)
    painted = folded_quads("Painted")
    attribute = painted.data.color_attributes.new("Paint", 'FLOAT_COLOR', 'POINT')
    paint = np.repeat(np.linspace(0, 1, 6, dtype=np.float32)[:, None], 4, axis=1)
    attribute.data.foreach_set("color", paint.ravel())
    painted.data.update()
    meshes = capture()[1]
    np.testing.assert_allclose(meshes["Tinted"].colors, [[0.5, 0.25, 0.125, 1.0]] * 8)
    got = meshes["Painted"]
    # Vertices come out sorted by source vertex; each carries its painted value.
    np.testing.assert_allclose(got.colors, paint, atol=1e-6)


def test_colour_attribute_node_in_base_colour_is_read_per_corner(empty_scene):
    reflector(folded_quads("Mirror"))
    obj = folded_quads("Corners")
    attribute = obj.data.color_attributes.new("Shade", 'FLOAT_COLOR', 'CORNER')
    # Quad 0 dark, quad 1 bright: the shared vertices split.
    values = np.array([[0.1] * 4] * 4 + [[0.9] * 4] * 4, dtype=np.float32)
    attribute.data.foreach_set("color", values.ravel())
    mat = material("FromAttribute")
    node = mat.node_tree.nodes.new('ShaderNodeVertexColor')
    node.layer_name = "Shade"
    mat.node_tree.links.new(node.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    obj.data.materials.append(mat)
    obj.data.update()
    got = capture()[1]["Corners"]
    assert got.vertices.shape == (8, 3)
    np.testing.assert_allclose(np.sort(got.colors[:, 0]), [0.1] * 4 + [0.9] * 4, atol=1e-6)


# --- views ----------------------------------------------------------------------------


def _camera(scene, *, ortho=False):
    data = bpy.data.cameras.new("Camera")
    camera = _link(bpy.data.objects.new("Camera", data))
    camera.location = (6.0, -7.0, 4.0)
    camera.rotation_euler = (math.radians(63), 0.0, math.radians(46))
    camera.scale = (2.0, 2.0, 2.0)  # ignored by renders, and by the view
    data.lens = 40
    data.shift_x, data.shift_y = 0.1, -0.05
    if ortho:
        data.type, data.ortho_scale = 'ORTHO', 9.0
    scene.camera = camera
    return camera


@pytest.mark.parametrize("ortho", [False, True])
@pytest.mark.parametrize("aspect", [(1.0, 1.0), (2.0, 1.0)])
def test_camera_view_projects_like_blender(empty_scene, ortho, aspect):
    scene = empty_scene
    scene.render.resolution_x, scene.render.resolution_y = 640, 360
    scene.render.resolution_percentage = 50
    scene.render.pixel_aspect_x, scene.render.pixel_aspect_y = aspect
    camera = _camera(scene, ortho=ortho)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view = view_from_camera(camera, scene, depsgraph)
    assert (view.width, view.height) == (320, 180)
    assert view.is_perspective != ortho

    points = np.array([[0, 0, 0], [1, -1, 0.5], [-1.5, 2, 1], [2, 0.5, -1]], dtype=np.float64)
    pixels, _ = view.to_pixels(points)
    for point, pixel in zip(points, pixels):
        normalised = world_to_camera_view(scene, camera, Vector(point))
        np.testing.assert_allclose(pixel, [normalised.x * 320, normalised.y * 180], atol=1e-3)


def test_viewport_view_projects_like_blender(empty_scene):
    # Background Blender still has a window with the factory layout's 3D viewport.
    area = next(a for a in bpy.context.window.screen.areas if a.type == 'VIEW_3D')
    region = next(r for r in area.regions if r.type == 'WINDOW')
    rv3d = area.spaces.active.region_3d
    view = view_from_region(region, rv3d)
    assert (view.width, view.height) == (region.width, region.height)
    points = np.array([[0, 0, 0], [1, -1, 0.5], [-1.5, 2, 1]], dtype=np.float64)
    pixels, _ = view.to_pixels(points)
    for point, pixel in zip(points, pixels):
        np.testing.assert_allclose(pixel, location_3d_to_region_2d(region, rv3d, Vector(point)), atol=1e-3)


def test_camera_view_rejects_other_objects(empty_scene):
    cube = cube_object("NotACamera")
    with pytest.raises(SceneInputError) as error:
        view_from_camera(cube, empty_scene, bpy.context.evaluated_depsgraph_get())
    assert error.value.object_name == "NotACamera"
    assert "not a camera" in error.value.problem


# --- bad input ------------------------------------------------------------------------


def _capture_error(**kwargs) -> SceneInputError:
    with pytest.raises(SceneInputError) as error:
        capture(**kwargs)
    return error.value


def test_reflector_without_faces_after_modifiers(empty_scene):
    obj = reflector(folded_quads("Masked"))
    obj.vertex_groups.new(name="nothing")
    mask = obj.modifiers.new("Mask", 'MASK')
    mask.vertex_group = "nothing"
    error = _capture_error()
    assert error.object_name == "Masked"
    assert "no faces" in error.problem


def test_reflector_with_nan_vertices(empty_scene):
    obj = reflector(folded_quads("Broken"))
    coordinates = np.zeros(len(obj.data.vertices) * 3, dtype=np.float32)
    obj.data.vertices.foreach_get("co", coordinates)
    coordinates[4] = np.nan
    obj.data.vertices.foreach_set("co", coordinates)
    obj.data.update()
    error = _capture_error()
    assert error.object_name == "Broken"
    assert "NaN" in error.problem


def test_diffuse_mesh_with_nan_vertices(empty_scene):
    reflector(folded_quads("Mirror"))
    obj = cube_object("BrokenBox")
    obj.data.vertices[3].co.x = float("nan")
    obj.data.update()
    error = _capture_error()
    assert error.object_name == "BrokenBox"
    assert "NaN" in error.problem


def test_reflector_squashed_flat_has_undefined_normals(empty_scene):
    # Blender never yields zero corner normals (degenerate faces get (0, 0, 1)); a zero
    # scale is how a reflector's normals become undefined.
    reflector(cube_object("Flat")).scale = (1, 1, 0)
    error = _capture_error()
    assert error.object_name == "Flat"
    assert "zero scale" in error.problem


def test_diffuse_object_squashed_flat_is_captured_with_face_normals(empty_scene):
    """A diffuse object scaled to zero on one axis is a flat shape, still seen and
    reflected: captured (no singular-matrix traceback), its normals across the flat side."""
    reflector(folded_quads("Mirror"))
    cube_object("Flat").scale = (1, 1, 0)
    bpy.context.view_layer.update()
    meshes = capture()[1]
    flat = meshes["Flat"]
    assert np.allclose(flat.vertices[:, 2], 0.0, atol=1e-9)
    lengths = np.linalg.norm(flat.normals, axis=1)
    assert np.all((np.abs(lengths - 1.0) < 1e-9) | (lengths == 0.0))
    assert np.allclose(np.abs(flat.normals[lengths > 0][:, 2]), 1.0)


@pytest.mark.parametrize("role", ["reflector", "diffuse"])
def test_nan_scale_names_the_object(empty_scene, role):
    mirror = reflector(folded_quads("Mirror"))
    broken = mirror if role == "reflector" else cube_object("Box")
    broken.scale = (1.0, float("nan"), 1.0)
    bpy.context.view_layer.update()
    error = _capture_error()
    assert error.object_name == broken.name
    assert "not a number" in error.problem
    broken.scale = (1.0, 1.0, 1.0)  # repaired: the next capture works
    bpy.context.view_layer.update()
    assert capture()[0].keys() == {"Mirror"}


def test_non_surface_object_marked_as_reflector(empty_scene):
    reflector(_link(bpy.data.objects.new("Empty", None)))
    error = _capture_error()
    assert error.object_name == "Empty"
    assert error.problem == "is marked as a reflector but is an empty object, which has no surface"


def test_scene_without_reflector(empty_scene):
    cube_object("Box")
    error = _capture_error()
    assert error.object_name == empty_scene.name
    assert "reflector" in error.problem
    assert capture(require_reflector=False)[1].keys() == {"Box"}


def test_weld_sorts_only_the_split_vertices():
    """Issue 46 item 4: the weld of a smooth mesh sorts nothing, and of a mesh with a few
    split vertices only theirs, with the output of the sort of every corner
    (``_weld_sorted``): the first corner of each vertex, numbered by vertex then by the
    values' bits, -0.0 as 0.0. tracemalloc: 13 bytes a corner at its peak on a smooth
    mesh; 80 when every corner's sort keys and orders were made (+240 MB for a
    million-triangle mirror)."""
    import tracemalloc

    from curved_reflections.blender.capture import _weld, _weld_sorted

    rng = np.random.default_rng(46)
    corner_vertex = rng.integers(0, 100_000, 600_000).astype(np.int32)
    normals = rng.normal(size=(100_000, 3)).astype(np.float32)[corner_vertex]
    tracemalloc.start()
    try:
        first, welded = _weld(corner_vertex, normals)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 24 * len(corner_vertex)
    expected = _weld_sorted(corner_vertex, normals)
    np.testing.assert_array_equal(first, expected[0])
    np.testing.assert_array_equal(welded, expected[1])
    split = normals.copy()
    split[rng.random(len(split)) < 0.01] = (0.0, -0.0, 1.0)
    split[rng.random(len(split)) < 0.01] = (-0.0, 0.0, 1.0)
    colors = rng.random((len(split) // 3, 4)).astype(np.float32).repeat(3, axis=0)
    for values in ((split,), (split, colors)):
        got, expected = _weld(corner_vertex, *values), _weld_sorted(corner_vertex, *values)
        np.testing.assert_array_equal(got[0], expected[0])
        np.testing.assert_array_equal(got[1], expected[1])
