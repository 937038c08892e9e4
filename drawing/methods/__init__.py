# SPDX-License-Identifier: GPL-3.0-or-later
"""Each method's GPU side, a pass (``frame_pass.FramePass``) of the method-agnostic
renderer (``reflection_draw.py``):

- sample-based cameras: cameras packed into textures (:mod:`.sbc_pack`) and projected in a
  vertex shader (:mod:`.sbc_gpu`) or in numpy (:mod:`.camera_source`), at the depth that
  orders reflections (:mod:`.reflected_depth`), their reflected triangles
  (:mod:`.sbc_triangles`), kept and drawn by their pass (:mod:`.camera_pass`);
- morphing grids (tetrahedral and octree): node images on the GPU and their per-frame blend
  (:mod:`.morph_source`, :mod:`.morph_pass`);
- the iterative search: the reflector's cube map baked (:mod:`.iterative_bake`) and the
  per-frame search (:mod:`.iterative_draw`);
- perturbation: the per-vertex Taylor steps (:mod:`.perturbation_gpu`) and its pass
  (:mod:`.perturbation_pass`).

The per-frame passes write one answer texel per vertex and reflector, drawn by
:mod:`..reflected_meshes`; the camera's pass draws its own triangles.
"""
