# SPDX-License-Identifier: GPL-3.0-or-later
"""Sample-based cameras (Popescu, Sacks & Mei 2006): Runtime mode, and the cameras at the
nodes of the morphing grid.

- :mod:`.raymap`: the view's ray map (section III), one reflected ray per down-sampled pixel;
- :mod:`.bsp`, :mod:`.pinhole`, :mod:`.ray_patch`: the BSP tree of leaf cameras (section IV),
  the paper's pinhole leaves and our ray-patch leaves;
- :mod:`.sbc_build`: a camera built from a view (sheets where rays cross);
- :mod:`.sbc`: the camera answering the one question (:mod:`...projection`), with
  :mod:`.sbc_cells` (fold and mixed cells), :mod:`.sbc_edges` (answers past its rays),
  :mod:`.sheet_bounds` (where a sheet can project) and :mod:`.sbc_arrays` (flat arrays).
"""

from .sbc import SampleBasedCamera
from .sbc_build import build_sample_based_camera

__all__ = ["SampleBasedCamera", "build_sample_based_camera"]
