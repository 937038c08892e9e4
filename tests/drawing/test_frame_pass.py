# SPDX-License-Identifier: GPL-3.0-or-later
"""The per-frame passes behind one interface (``drawing/frame_pass.py``): what each
tells the renderer about its reflectors, read without a GPU (nothing here draws)."""

from types import SimpleNamespace

import numpy as np

from curved_reflections.engine import DiffuseMesh, Reflector
from curved_reflections.engine.geometry.closed_surfaces import ConvexMirrors
from curved_reflections.engine.geometry.sphere import icosphere
from curved_reflections.drawing.draw_geometry import prepare_geometry
from curved_reflections.drawing.frame_pass import FramePass
from curved_reflections.drawing.methods.iterative_draw import IterativePass
from curved_reflections.drawing.methods.morph_pass import MorphPass
from curved_reflections.drawing.methods.perturbation_pass import PerturbationPass
from curved_reflections.drawing.reflected_meshes import ReflectedMeshes


def _geometry():
    mirrors = [icosphere((0.0, 0.0, 0.0), 1.0, 2, name="A"), icosphere((3.0, 0.0, 0.0), 1.0, 2, name="B")]
    triangle = DiffuseMesh("Tri", np.array([[0.0, 3.0, 0.0], [1.0, 3.0, 0.0], [0.0, 3.0, 1.0]]), np.array([[0, 1, 2]]),
                       np.ones((3, 4), np.float32))
    return mirrors, prepare_geometry(mirrors, [triangle])


def test_each_pass_says_how_the_band_trace_treats_its_reflectors():
    """Searched mirrors (iterative, perturbation) get their silhouette band traced; the
    iterative search's folded ones are its non-convex mirrors, or all when not alone; a
    morphing pass has no searched mirror and draws gaps only where it blended; the
    renderer asks these and never which method a pass is."""
    mirrors, geometry = _geometry()
    meshes = ReflectedMeshes(geometry)
    convex = SimpleNamespace(index=0, reflector_map=SimpleNamespace(convex=True))
    bumpy = SimpleNamespace(index=1, reflector_map=SimpleNamespace(convex=False))
    alone = IterativePass(geometry, [convex, bumpy], meshes, n_reflectors=1)
    assert alone.reflector_indices == alone.searched_reflectors == [0, 1]
    assert alone.folded_reflectors == [1] and alone.traces_band
    assert IterativePass(geometry, [convex], meshes, n_reflectors=2).folded_reflectors == [0]
    perturbation = PerturbationPass(geometry, mirrors, [SimpleNamespace(index=1)], meshes)
    assert perturbation.searched_reflectors == [1] and perturbation.traces_band
    morph = MorphPass(geometry, [], meshes)
    assert morph.searched_reflectors == morph.gap_reflectors == [] and not morph.traces_band
    assert morph.hidden_fraction == float("inf")  # its blended images lie off the mesh
    assert alone.hidden_fraction == perturbation.hidden_fraction == FramePass.hidden_fraction < 0.01
    assert IterativePass(geometry, [], meshes).traces_band is False


def test_only_mirrors_whose_every_image_is_mirrored_cull_closed_solids():
    """A convex searched map and a declared exact surface (convex bodies, first order)
    show every image mirrored, so the far sides of closed solids may be culled; a
    non-convex map flips the images beyond its folds, a mesh under perturbation may be
    non-convex: they keep every triangle. A morphing grid's mirror culls where its mesh
    bounds a convex body."""
    mirrors, geometry = _geometry()
    meshes = ReflectedMeshes(geometry)
    convex = SimpleNamespace(index=0, reflector_map=SimpleNamespace(convex=True))
    bumpy = SimpleNamespace(index=1, reflector_map=SimpleNamespace(convex=False))
    assert IterativePass(geometry, [convex, bumpy], meshes).mirrored_reflectors == [0]
    declared = SimpleNamespace(index=0, surface=SimpleNamespace(shape="SPHERE"))
    mesh = SimpleNamespace(index=1, surface=None)
    assert PerturbationPass(geometry, mirrors, [declared, mesh], meshes).mirrored_reflectors == [0]
    assert MorphPass(geometry, [], meshes).mirrored_reflectors == []
    dented = mirrors[1]
    vertices = dented.vertices.copy()
    vertices[0] = dented.vertices.mean(axis=0) + 0.8 * (vertices[0] - dented.vertices.mean(axis=0))
    dented = Reflector(dented.name, vertices, dented.triangles, dented.normals)
    grids = [(SimpleNamespace(reflector_index=0), None), (SimpleNamespace(reflector_index=1), None)]
    assert MorphPass(geometry, grids, meshes, convex_mirrors=ConvexMirrors([mirrors[0], dented])
                     ).mirrored_reflectors == [0]
    assert MorphPass(geometry, grids, meshes, convex_mirrors=ConvexMirrors(mirrors)).mirrored_reflectors == [0, 1]


def test_morphing_snaps_live_vertices_to_the_scene_accuracy():
    """The live view snaps a pass's vertices to a grid of its Accuracy: a morphing pass
    takes the scene's, and without one it is not snapped."""
    _, geometry = _geometry()
    meshes = ReflectedMeshes(geometry)
    assert MorphPass(geometry, [], meshes, accuracy_px=0.5).accuracy_px == 0.5
    assert MorphPass(geometry, [], meshes).accuracy_px is None
