# SPDX-License-Identifier: GPL-3.0-or-later
"""Glass in Blender (issue 47): marking it, its index of refraction from its material,
and Render Image drawing what lies behind it refracted (blender/glass_layer.py),
measured against exactly traced rays."""

import bpy
import numpy as np
import pytest

from curved_reflections.blender import demo_scenes
from curved_reflections.blender.capture import capture_scene
from curved_reflections.blender.material_ior import DEFAULT_IOR, glass_ior
from curved_reflections.blender.render_image import render_scene
from curved_reflections.engine import Reflector
from curved_reflections.engine.errors import SceneInputError
from curved_reflections.engine.geometry.raytrace import ReflectorSet
from curved_reflections.engine.geometry.sphere import icosphere

WIDTH, HEIGHT = 128, 96
#: Display colours of the labelled objects behind the glass.
COLOURS = {"Red": (1.0, 0.1, 0.1), "Green": (0.1, 0.9, 0.1), "Blue": (0.2, 0.3, 1.0), "Yellow": (1.0, 0.9, 0.1)}


def _material(kind: str, ior: float, transmission: float = 1.0):
    material = bpy.data.materials.new(f"{kind} glass")
    nodes = material.node_tree.nodes
    output = next(n for n in nodes if n.bl_idname == 'ShaderNodeOutputMaterial')
    if kind in ("Glass", "Refraction"):
        shader = nodes.new(f"ShaderNodeBsdf{kind}")
    else:
        shader = next(n for n in nodes if n.bl_idname == 'ShaderNodeBsdfPrincipled')
        shader.inputs["Transmission Weight"].default_value = transmission
    shader.inputs["IOR"].default_value = ior
    material.node_tree.links.new(shader.outputs[0], output.inputs["Surface"])
    return material


def _ball(name="Ball", material=None, location=(0.0, 0.0, 1.0), radius=1.0):
    shape = icosphere(location, radius, 4, name)
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(shape.vertices.tolist(), [], shape.triangles.tolist())
    mesh.shade_smooth()
    if material is not None:
        mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    obj.curved_reflections.is_refractor = True
    return obj


def _glass_scene(world=None):
    """A glass ball (IOR 1.45 from its Glass BSDF) before four coloured panels, a camera
    looking at it, the world ``world`` (linear RGB; default the demos' lavender);
    returns the scene."""
    scene = bpy.context.scene
    demo_scenes._prepare(scene, WIDTH, HEIGHT)
    if world is not None:
        scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (*world, 1.0)
    _ball(material=_material("Glass", 1.45))
    for k, (name, colour) in enumerate(COLOURS.items()):
        x, z = (-1.5 + 3.0 * (k % 2), 1.0 + 1.5 * (k // 2 * 2 - 1))
        bpy.ops.mesh.primitive_plane_add(size=3.0, location=(x, 3.0, z), rotation=(np.pi / 2, 0.0, 0.0))
        panel = bpy.context.active_object
        panel.name = name
        panel.data.materials.append(demo_scenes._emission_material(name, colour))
    demo_scenes._camera(scene, (0.4, -6.0, 1.3), (0.0, 0.0, 1.0), 50.0)
    bpy.context.view_layer.update()
    return scene


def test_a_glass_objects_index_of_refraction_comes_from_its_material_unless_set(empty_scene, registered):
    glass = _ball("A", _material("Glass", 1.33))
    principled = _ball("B", _material("Principled", 1.6), location=(3.0, 0.0, 1.0))
    solid = _ball("C", _material("Principled", 1.6, transmission=0.2), location=(6.0, 0.0, 1.0))
    refraction = _ball("D", _material("Refraction", 1.2), location=(9.0, 0.0, 1.0))
    assert (glass_ior(glass), glass_ior(principled), glass_ior(solid), glass_ior(refraction)) == pytest.approx(
        (1.33, 1.6, DEFAULT_IOR, 1.2))
    glass.curved_reflections.ior = 2.4
    assert glass_ior(glass) == pytest.approx(2.4)
    bpy.context.view_layer.update()
    captured = capture_scene(bpy.context.evaluated_depsgraph_get())
    # A Refraction BSDF refracts without reflecting, as in Cycles.
    assert [(g.name, round(g.ior, 3), g.reflects) for g in captured.glass] == [
        ("A", 2.4, True), ("B", 1.6, True), ("C", 1.5, True), ("D", 1.2, False)]
    assert not captured.reflectors and {m.name for m in captured.meshes} == {"A", "B", "C", "D"}
    glass.curved_reflections.is_reflector = True
    with pytest.raises(SceneInputError, match="'A': is marked both as a reflector and as glass"):
        capture_scene(bpy.context.evaluated_depsgraph_get())


def _traced_labels(captured, view, pixels, through_glass: bool = True, rays=None) -> np.ndarray:
    """Index into COLOURS of the panel each pixel's eye ray meets, refracted through the
    glass (-2 where it meets no glass) or, without ``through_glass``, straight on (-1:
    none), traced exactly; ``rays``: (origins, directions) to meet the panels with
    instead of the pixels' (with ``through_glass`` off)."""
    from curved_reflections.engine.glass import GlassSet

    origins, directions = view.pixel_rays(pixels + 0.5) if rays is None else rays
    paths = GlassSet(list(captured.glass)).trace(origins, directions)
    if through_glass:
        origins, directions = paths.origin, paths.direction
    panels = [m for m in captured.meshes if m.name in COLOURS]
    surfaces = ReflectorSet([Reflector(m.name, m.vertices, m.triangles, np.tile([0.0, 0.0, 1.0], (len(m.vertices), 1)))
                             for m in panels])
    hits = surfaces.intersect(origins, directions)
    names = list(COLOURS)
    labels = np.array([names.index(panels[k].name) if k >= 0 else -1 for k in hits.reflector])
    return np.where(paths.through_glass | (not through_glass), labels, -2)


def _labels(image) -> np.ndarray:
    """Index into COLOURS of each pixel's colour (linear RGBA), -1 where none is within
    a quarter of the palette's spacing (0.5)."""
    from curved_reflections.engine.srgb import linear_to_srgb

    shown = linear_to_srgb(image[..., :3])
    palette = np.array(list(COLOURS.values()))
    nearest = np.argmin(np.linalg.norm(shown[..., None, :] - palette, axis=-1), axis=-1)
    return np.where(np.linalg.norm(shown - palette[nearest], axis=-1) < 0.25, nearest, -1)


def test_render_image_draws_what_lies_behind_glass_where_exactly_traced_rays_see_it(empty_scene, registered,
                                                                                    gpu_ready):
    """In a black world (nothing for the glass to reflect), the ball's pixels show the
    panel the exact ray through each meets after both refractions, every one of them
    but along its outline (the pre-pass's and the rays' edges differ by a pixel). The
    picture is turned round: the panels met straight on agree on far fewer of them."""
    scene = _glass_scene(world=(0.0, 0.0, 0.0))
    result = render_scene(scene, bpy.context.evaluated_depsgraph_get())
    in_glass = result.stats["glass"]["pixels"]
    captured = capture_scene(bpy.context.evaluated_depsgraph_get())
    rows, columns = np.nonzero(np.ones((HEIGHT, WIDTH), dtype=bool))
    pixels = np.stack([columns, rows], axis=1)
    truth = _traced_labels(captured, result.view, pixels).reshape(HEIGHT, WIDTH)
    glass = truth > -2
    assert in_glass > 1500 and abs(int(glass.sum()) - in_glass) < 0.05 * in_glass
    padded = np.pad(glass, 1)
    inner = glass & np.all([padded[1 + i:HEIGHT + 1 + i, 1 + j:WIDTH + 1 + j]
                            for i in range(-1, 2) for j in range(-1, 2)], axis=0)
    ours = _labels(result.image)
    assert inner.sum() > 1500 and (ours == truth)[inner].mean() > 0.995
    straight = _traced_labels(captured, result.view, pixels, through_glass=False).reshape(HEIGHT, WIDTH)
    assert (ours == straight)[inner].mean() < 0.6
    assert (ours == straight)[~glass].mean() > 0.99  # elsewhere the panels as they are


def test_the_glass_reflects_the_world_by_the_fresnel_reflectance(empty_scene, registered, gpu_ready):
    """Head on, glass of index 1.45 reflects ((n - 1) / (n + 1))^2 = 3.4 % at each
    surface: the ball's centre shows the lavender world reflected off its front, and of
    the light inside, the panel behind it and the world reflected back off its back."""
    from curved_reflections.engine.srgb import srgb_to_linear

    scene = _glass_scene()
    result = render_scene(scene, bpy.context.evaluated_depsgraph_get())
    world = np.array(srgb_to_linear(demo_scenes.WORLD_COLOUR))
    x, y = np.rint(result.view.to_pixels(np.array([[0.0, 0.0, 1.0]]))[0][0] - 0.5).astype(int)
    captured = capture_scene(bpy.context.evaluated_depsgraph_get())
    [panel] = _traced_labels(captured, result.view, np.array([[x, y]]))
    behind = np.array(srgb_to_linear(list(COLOURS.values())[panel]))
    r0 = ((1.45 - 1.0) / (1.45 + 1.0)) ** 2
    # Reflected at the front (r0 of the world), and of what goes in, reflected back at the
    # back (r0 again: it leaves through the front toward the world).
    assert np.allclose(result.image[y, x, :3], r0 * world + (1.0 - r0) * ((1.0 - r0) * behind + r0 * world),
                       atol=2e-3)


def test_a_scene_of_glass_alone_renders_and_a_camera_inside_glass_sees_out_through_it(empty_scene, registered,
                                                                                      gpu_ready):
    """With no mirror the glass's renderer draws the whole frame. From inside the ball
    (a Refraction BSDF: no reflection) Render Image and the live view trace each ray out
    of the glass: the panels show where exact paths starting inside the glass meet them
    (measured: all of the pixels whose path leaves without reflecting totally)."""
    from curved_reflections.engine.glass import GlassSet

    scene = _refraction_scene()
    result = render_scene(scene, bpy.context.evaluated_depsgraph_get())
    assert result.image.shape == (HEIGHT, WIDTH, 4) and result.stats["methods"] == {}
    scene.camera.location = (0.0, -0.2, 1.0)
    bpy.context.view_layer.update()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    result = render_scene(scene, depsgraph)
    rows, columns = np.nonzero(np.ones((HEIGHT, WIDTH), dtype=bool))
    pixels = np.stack([columns, rows], axis=1)
    captured = capture_scene(depsgraph)
    inside = np.zeros(len(pixels), int)  # the ball's index
    paths = GlassSet(list(captured.glass)).trace(*result.view.pixel_rays(pixels + 0.5), media=inside)
    truth = _traced_labels(captured, result.view, pixels, through_glass=False, rays=(paths.origin, paths.direction))
    leaves = ((paths.total_reflections == 0) & (paths.exit_glass == 0)).reshape(HEIGHT, WIDTH)
    judged = _inner(leaves & (truth.reshape(HEIGHT, WIDTH) >= 0))
    assert judged.sum() > 1000 and (_labels(result.image) == truth.reshape(HEIGHT, WIDTH))[judged].mean() > 0.995
    _, live_image = _live_image(scene)
    assert (_labels(live_image) == truth.reshape(HEIGHT, WIDTH))[judged].mean() > 0.995


def test_the_live_view_draws_a_scene_of_glass_alone(empty_scene, registered, gpu_ready):
    """No mirror: Start draws the glass's refracted images (the panels behind the ball)
    without building any camera."""
    from curved_reflections.blender import live

    scene = _refraction_scene()
    view, image = _live_image(scene)
    shown = _labels(image)
    assert (shown >= 0).sum() > 1500 and len(np.unique(shown[shown >= 0])) == len(COLOURS)
    state = live.start(scene, bpy.context.evaluated_depsgraph_get(), wait=True)
    assert state.renderer is None and state.cameras == {} and state.status == "Reflections up to date"
    live.clear(scene)


def test_where_glass_must_reflect_totally_a_refraction_bsdf_shows_black(empty_scene, registered, gpu_ready):
    """A glass box seen at an angle: rays entering its top meet a side past the critical
    angle. Glass (a Glass BSDF) reflects them on; a Refraction BSDF cannot, so Cycles
    shows those pixels black, and so do Render Image and the live view (the live view's
    glass over a black framebuffer: measured 2,300 more black pixels)."""
    scene = _glass_scene()
    bpy.data.objects.remove(bpy.data.objects["Ball"])
    demo_scenes._camera(scene, (2.5, -5.0, 3.5), (0.0, 0.0, 1.0), 50.0)
    live_dark = {}
    for kind, black in (("Glass", False), ("Refraction", True)):
        bpy.ops.mesh.primitive_cube_add(size=1.6, location=(0.0, 0.0, 1.0))
        box = bpy.context.active_object
        box.data.materials.append(_material(kind, 1.5))
        box.curved_reflections.is_refractor = True
        bpy.context.view_layer.update()
        result = render_scene(scene, bpy.context.evaluated_depsgraph_get())
        dark = (result.image[..., :3].max(axis=2) < 1e-6).sum()
        assert (dark > 50) == black, (kind, dark)
        live_dark[kind] = int((_live_image(scene)[1][..., :3].max(axis=2) < 1e-6).sum())
        bpy.data.objects.remove(box)
    assert live_dark["Refraction"] > live_dark["Glass"] + 500, live_dark


def test_glass_inside_glass_is_drawn_with_a_warning_naming_the_outer_glass(empty_scene, registered, gpu_ready):
    """A ray leaving the inner glass is taken to leave into air (the media are tracked
    one at a time): the render says so instead of passing it off as exact."""
    scene = _glass_scene()
    _ball("Bubble", _material("Glass", 1.33), radius=0.4)
    bpy.context.view_layer.update()
    result = render_scene(scene, bpy.context.evaluated_depsgraph_get())
    assert result.stats["warnings"] == ["Glass inside other glass (seen through Ball): a ray leaving the inner glass "
                                        "is drawn as if it left into air"]


def _inner(mask: np.ndarray) -> np.ndarray:
    """``mask`` without its outline: the pixels whose 8 neighbours are all in it."""
    height, width = mask.shape
    padded = np.pad(mask, 1)
    return mask & np.all([padded[1 + i:height + 1 + i, 1 + j:width + 1 + j]
                          for i in range(-1, 2) for j in range(-1, 2)], axis=0)


def _refraction_scene():
    """The glass scene in a black world with the ball of a Refraction BSDF (no Fresnel
    reflection): what it shows is the refracted panels alone."""
    scene = _glass_scene(world=(0.0, 0.0, 0.0))
    bpy.data.objects["Ball"].data.materials[0] = _material("Refraction", 1.45)
    bpy.context.view_layer.update()
    return scene


def _live_image(scene):
    """The live view of the scene camera drawn as the draw handler draws it, over a black
    framebuffer whose depth is cleared (nothing of Blender's own drawing in front)."""
    import gpu

    from curved_reflections.blender import live
    from curved_reflections.blender.capture import view_from_camera

    depsgraph = bpy.context.evaluated_depsgraph_get()
    live.start(scene, depsgraph, wait=True)
    view = view_from_camera(scene.camera, scene, depsgraph)
    offscreen = gpu.types.GPUOffScreen(WIDTH, HEIGHT, format='RGBA32F')
    try:
        with offscreen.bind():
            framebuffer = gpu.state.active_framebuffer_get()
            framebuffer.clear(color=(0.0, 0.0, 0.0, 1.0), depth=1.0)
            assert live.draw_safely(scene, live.CAMERA_KEY, view)
            pixels = framebuffer.read_color(0, 0, WIDTH, HEIGHT, 4, 0, 'FLOAT')
    finally:
        offscreen.free()
        live.clear(scene)
    pixels.dimensions = WIDTH * HEIGHT * 4
    return view, np.array(pixels, dtype=np.float32).reshape(HEIGHT, WIDTH, 4)


@pytest.mark.parametrize("shape", ["ball", "torus"])
def test_the_live_view_draws_what_lies_behind_glass_of_any_shape(empty_scene, registered, gpu_ready, shape):
    """The viewport traces the glass on the GPU every frame (its pixels' paths through
    it, met with the scene), a ball or a torus (not convex: rays leave and enter it
    again): its inner pixels show the panel exact rays meet through it (measured: all
    of them, on either), and the panel says it is traced. A
    mirror elsewhere in the view is what starts the live view."""
    from curved_reflections.blender import live
    from curved_reflections.blender.panel import glass_note

    scene = _refraction_scene()
    if shape == "torus":
        material = bpy.data.objects["Ball"].data.materials[0]
        bpy.data.objects.remove(bpy.data.objects["Ball"])
        bpy.ops.mesh.primitive_torus_add(location=(0.0, 0.0, 1.0), rotation=(1.2, 0.0, 0.3), major_radius=1.0,
                                         minor_radius=0.4)
        torus = bpy.context.active_object
        torus.name = "Ball"
        torus.data.materials.append(material)
        torus.data.shade_smooth()
        torus.curved_reflections.is_refractor = True
    mirror = _ball("Mirror", location=(-3.2, 2.0, 3.0), radius=0.5)
    mirror.curved_reflections.is_refractor = False
    mirror.curved_reflections.is_reflector = True
    bpy.context.view_layer.update()
    view, image = _live_image(scene)
    captured = capture_scene(bpy.context.evaluated_depsgraph_get())
    rows, columns = np.nonzero(np.ones((HEIGHT, WIDTH), dtype=bool))
    truth = _traced_labels(captured, view, np.stack([columns, rows], axis=1)).reshape(HEIGHT, WIDTH)
    inner = _inner(truth > -2)
    assert inner.sum() > 1500 and (_labels(image) == truth)[inner].mean() > 0.995
    state = live.start(scene, bpy.context.evaluated_depsgraph_get(), wait=True)
    assert glass_note("Ball", state).startswith("The viewport and Render Image trace it on the GPU every frame")
    live.clear(scene)


def test_live_glass_that_reflects_shows_what_it_reflects_by_its_fresnel_reflectance(empty_scene, registered,
                                                                                     gpu_ready):
    """A Glass BSDF of index 1.45 over a black world, a white panel beside it. Head on it
    lets through (1 - R0)^2, R0 = ((n - 1) / (n + 1))^2, of the panel behind the ball's
    centre (R0 is reflected at the front, and of what goes in, R0 back at the back) and
    reflects R0 of the black world. Toward the rim its reflectance F grows (Fresnel's
    equations, as Cycles weighs a Glass BSDF) and it reflects F of the white panel, which
    the iterative search draws on the glass as on a mirror: the live view shows there
    what Render Image traces exactly."""
    from curved_reflections.engine.geometry.raytrace import reflect
    from curved_reflections.engine.glass import GlassSet, fresnel_dielectric
    from curved_reflections.engine.srgb import srgb_to_linear

    scene = _glass_scene(world=(0.0, 0.0, 0.0))
    bpy.ops.mesh.primitive_plane_add(size=10.0, location=(3.5, -2.0, 1.0), rotation=(0.0, np.pi / 2, 0.0))
    bpy.context.active_object.data.materials.append(demo_scenes._emission_material("White", (1.0, 1.0, 1.0)))
    bpy.context.view_layer.update()
    view, image = _live_image(scene)
    exact = render_scene(scene, bpy.context.evaluated_depsgraph_get()).image
    captured = capture_scene(bpy.context.evaluated_depsgraph_get())
    colours = np.array(srgb_to_linear(np.array(list(COLOURS.values()))))
    r0 = ((1.45 - 1.0) / (1.45 + 1.0)) ** 2
    centre = np.rint(view.to_pixels(np.array([[0.0, 0.0, 1.0]]))[0][0] - 0.5).astype(int)
    [panel] = _traced_labels(captured, view, centre[None])
    assert np.allclose(image[centre[1], centre[0], :3], (1.0 - r0) ** 2 * colours[panel], atol=5e-3)
    rim = np.rint(view.to_pixels(np.array([[0.93, 0.0, 1.0]]))[0][0] - 0.5).astype(int)
    origins, directions = view.pixel_rays(rim[None] + 0.5)
    paths = GlassSet(list(captured.glass)).trace(origins, directions)
    share = float(fresnel_dielectric(abs(float(paths.first_normal[0] @ directions[0])), 1.0 / 1.45))
    mirrored = reflect(directions, paths.first_normal)[0]
    on_panel = paths.first_position[0] + (3.5 - paths.first_position[0][0]) / mirrored[0] * mirrored
    assert share > 0.1 and mirrored[0] > 0.0 and abs(on_panel[1] + 2.0) < 5.0 and abs(on_panel[2] - 1.0) < 5.0
    assert np.allclose(image[rim[1], rim[0], :3], exact[rim[1], rim[0], :3], atol=0.03)


def test_a_traced_mirror_shows_what_lies_behind_the_glass_it_reflects(empty_scene, registered, gpu_ready):
    """A mirror ball in Ray Traced mode beside the glass ball reflects it: its rays
    refract through the glass's own triangles. Glass of index 1 bends nothing, so the
    mirror shows what it shows with the glass hidden, pixel for pixel, where the glass
    drawn as a solid object (not marked as glass) covers a part of its reflection."""
    scene = _glass_scene(world=(0.0, 0.0, 0.0))
    glass = bpy.data.objects["Ball"]
    glass.active_material = _material("Refraction", 1.0)
    mirror = _ball("Mirror", location=(1.9, -2.6, 1.0), radius=0.7)
    mirror.curved_reflections.is_refractor = False
    mirror.curved_reflections.is_reflector = True
    mirror.curved_reflections.mode = 'TRACED'
    mirror.data.materials.append(demo_scenes._mirror_material())
    bpy.context.view_layer.update()

    def render():
        return render_scene(scene, bpy.context.evaluated_depsgraph_get()).image[..., :3]

    clear = render()
    glass.hide_render = glass.hide_viewport = True
    hidden = render()
    glass.hide_render = glass.hide_viewport = False
    glass.curved_reflections.is_refractor = False
    solid = render()
    glass.hide_render = glass.hide_viewport = True
    mirror.curved_reflections.reflectivity = 0.0
    in_mirror = np.abs(render() - hidden).max(axis=2) > 0.05  # the mirror's pixels: it shows its colour
    assert in_mirror.sum() > 300

    def unlike(image):
        return np.abs(image - hidden).max(axis=2) > 0.05

    assert (unlike(solid) & in_mirror).sum() > 50  # the solid ball in the mirror
    assert unlike(clear).sum() == 0  # the mirror sees through the glass as through air
