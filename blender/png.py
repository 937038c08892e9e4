# SPDX-License-Identifier: GPL-3.0-or-later
"""PNG output through Blender's image datablocks: what Render Image writes its frames with.

Arrays are display sRGB values in [0, 1] (``engine/srgb.py``), rows bottom to top as
Blender stores pixels (y up, the pixel convention of docs/overview.md). A temporary image datablock
does the encoding, so no image library beyond Blender's own is needed, and it is removed
again, so writing leaves the file's data as it was.
"""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np


def write_png(path, array) -> Path:
    """Write (H, W, 3 or 4) display values in [0, 1], rows bottom to top, as an 8-bit PNG."""
    array = np.asarray(array, dtype=np.float32)
    if array.shape[2] == 3:
        array = np.concatenate([array, np.ones(array.shape[:2] + (1,), np.float32)], axis=2)
    height, width = array.shape[:2]
    image = bpy.data.images.new(Path(path).stem, width, height, alpha=True)
    try:
        image.pixels.foreach_set(np.clip(array, 0.0, 1.0).ravel())
        image.filepath_raw = str(Path(path).resolve())
        image.file_format = "PNG"
        image.save()
    finally:
        bpy.data.images.remove(image)
    return Path(path)
