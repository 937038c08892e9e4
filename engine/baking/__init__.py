# SPDX-License-Identifier: GPL-3.0-or-later
"""The preprocess of the grid methods (Morphing, Octree): a grid's nodes built on every
core, in ranges a render farm can split (:mod:`.bake`), and kept in an on-disk cache keyed
by the mirror, the settings and the engine (:mod:`.bake_cache`). Each grid kind says how
its nodes are built, stored and read (``bake_cache.GRID_KINDS``): nothing here branches on
the method."""
