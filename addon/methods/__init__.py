# SPDX-License-Identifier: GPL-3.0-or-later
"""The projection methods: each answers *where does this 3D point appear, reflected, in
this view?* behind the one interface of :mod:`..projection`.

- :mod:`.iterative`: Roger & Holzschuch (2006), a per-vertex search on a star-shaped
  reflector stored as a texture; runs on the GPU every frame.
- :mod:`.perturbation`: Chen & Arvo (2000), Taylor steps from a sparse set of traced
  reflection paths by path Jacobians and Hessians; any smooth reflector, exact spheres
  and ellipsoids, several bounces.

The sample-based camera (Popescu, Sacks, Mei 2006) lives in ``addon/sbc.py`` and its
helpers, and its morphing grid in ``addon/morphing.py``.
"""
