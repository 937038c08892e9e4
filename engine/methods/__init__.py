# SPDX-License-Identifier: GPL-3.0-or-later
"""The projection methods: each answers *where does this 3D point appear, reflected, in
this view?* behind the one interface of :mod:`..projection`, each in its own sub-package.

- :mod:`.sbc`: sample-based cameras (Popescu, Sacks & Mei 2006), Runtime mode: a BSP tree
  of leaf cameras over the view's ray map, built per view.
- :mod:`.morphing`: reflection morphing on a tetrahedral grid of those cameras (the same
  paper, section VI), Morphing mode; baked once (``engine/baking``), blended every frame.
- :mod:`.octree`: ray octrees at the nodes of a regular grid (Martin & Popescu 2004),
  Octree mode, blended trilinearly.
- :mod:`.iterative`: Roger & Holzschuch (2006), a per-vertex search on a star-shaped
  reflector stored as a texture; runs on the GPU every frame.
- :mod:`.perturbation`: Chen & Arvo (2000), Taylor steps from a sparse set of traced
  reflection paths by path Jacobians and Hessians; any smooth reflector, exact spheres
  and ellipsoids, several bounces.

Every method is measured against :mod:`..reference`; all of them stand on :mod:`..geometry`.
"""
