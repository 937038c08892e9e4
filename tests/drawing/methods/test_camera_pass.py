# SPDX-License-Identifier: GPL-3.0-or-later
"""The sample-based camera as a pass (drawing/methods/camera_pass.py): its reflected
triangles made once per camera and kept, the first orders it claims from the passes
after it, and the renderer drawing it like any other pass."""

import numpy as np
import pytest

from curved_reflections.engine import DiffuseMesh, look_at_view
from curved_reflections.engine.geometry.shapes import box
from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.engine.methods.sbc import build_sample_based_camera
from curved_reflections.engine.scene import scene_bounds


def _cube(centre, size):
    shape = box((size,) * 3).moved(centre)
    return DiffuseMesh("Cube", shape.vertices, shape.triangles, np.tile([1.0, 0.2, 0.1, 1.0], (len(shape.vertices), 1)))


@pytest.fixture(scope="module")
def scene():
    mirrors = [icosphere((-1.1, 0.0, 0.0), 1.0, 3, name="Left"), icosphere((1.1, 0.0, 0.0), 1.0, 3, name="Right")]
    meshes = [_cube((0.0, -2.2, 0.0), 0.8)]
    view = look_at_view((0.0, -7.0, 1.0), (0.0, 0.0, 0.0), fov_y_deg=35.0, width=96, height=64)
    bounds = scene_bounds(mirrors, meshes, margin=1.0)
    return mirrors, meshes, view, bounds


def test_a_camera_is_projected_once_kept_and_claims_every_first_order(gpu_ready, scene):
    from curved_reflections.drawing.methods import camera_pass
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    mirrors, meshes, view, bounds = scene
    camera = build_sample_based_camera(mirrors, view, bounds, max_order=1, downsample=2)
    renderer = ReflectionRenderer(mirrors, meshes)
    assert renderer.passes == (renderer.camera_pass,) and renderer.pass_named("camera") is renderer.camera_pass

    first = renderer.render(view, camera)
    source = renderer.camera_pass.last.source
    second = renderer.render(view, camera)
    assert renderer.counts["projections"] == 1  # the second render drew the kept triangles
    assert renderer.camera_pass.source_for(camera) is source and renderer.camera_pass.holds(source)
    np.testing.assert_array_equal(first, second)
    assert renderer.camera_pass.claims() == {0, 1}  # no per-frame pass: the camera draws both mirrors
    assert renderer.stats["projected_vertices"] > 0

    # A render without the camera draws no reflection (the cube's red is gone from the
    # mirrors) and claims nothing.
    bare = renderer.render(view)
    assert renderer.camera_pass.claims() == frozenset() and renderer.camera_pass.current is None
    reflected = (np.abs(first - bare).max(axis=2) > 0.1) & (first[..., 0] > first[..., 1] + 0.3)
    assert reflected.sum() > 20

    # The last KEPT_CAMERAS sources are kept, the least recently drawn one goes first.
    sources = [object() for _ in range(camera_pass.KEPT_CAMERAS)]
    kept = renderer.camera_pass.last
    for made in sources:
        renderer.camera_pass._keep(type(kept)(made, view, None, (), 0, 0))
    assert not renderer.camera_pass.holds(source) and all(renderer.camera_pass.holds(s) for s in sources)

    renderer.invalidate()
    assert not any(renderer.camera_pass.holds(s) for s in sources)
    renderer.render(view, camera)
    assert renderer.counts["projections"] == 2


def test_the_per_frame_passes_skip_what_the_camera_claimed(gpu_ready, scene):
    """With a flat answer pass on the left mirror, a camera that left the left mirror to it
    claims only the right one; the pass draws the left one and is told to skip the right."""
    from curved_reflections.drawing.frame_pass import FramePass
    from curved_reflections.drawing.reflection_draw import ReflectionRenderer

    seen = []

    class LeftOnly(FramePass):
        name = "left only"

        @classmethod
        def of_inputs(cls, methods, inputs):
            pass_ = cls()
            pass_.geometry, pass_.meshes, pass_.methods = inputs.geometry, inputs.meshes, []
            return pass_

        @property
        def reflector_indices(self):
            return [0]

        def update(self, frame):
            seen.append(frame.claimed)

        def answers(self):
            return []

    mirrors, meshes, view, bounds = scene
    renderer = ReflectionRenderer(mirrors, meshes, passes=[LeftOnly.factory(())])
    assert renderer.per_frame_reflectors(view) == {0}
    camera = build_sample_based_camera(mirrors, view, bounds, max_order=1, downsample=2,
                                       first_order_left_out=renderer.per_frame_reflectors(view))
    renderer.render(view, camera)
    assert renderer.camera_pass.current.per_frame == {0}
    assert renderer.camera_pass.claims() == {1} and seen[-1] == {1}
    assert [tuple(h) for h in camera.groups] and all(tuple(h) != (0,) for h in camera.groups)
