# SPDX-License-Identifier: GPL-3.0-or-later
"""The settings every stage of a frame reads, as one frozen record.

A frame's stages (the method plan, the renderer and its per-frame passes, the
sample-based camera's build on a worker thread) all read their settings from one
:class:`FrameSettings`, made once per frame from the scene (``blender/frame_pipeline.py``)
or by a caller that has no scene (tests, benchmarks). Two frames with equal settings
draw alike; a live view whose settings changed rebuilds what depends on them.
"""

from __future__ import annotations

from dataclasses import dataclass

#: GPU memory (MB) the morphing grids' node images may hold, unless the scene says otherwise.
DEFAULT_MORPH_BUDGET_MB = 256.0


@dataclass(frozen=True)
class FrameSettings:
    """What a frame is drawn with.

    ``max_order``: the highest order of reflection drawn; ``downsample``: the ray map's
    pixels per sample side (SBC paper III); ``accuracy_px``: the error (pixels) the
    cameras and the per-frame methods are built to; ``polish_frames``: each frame's
    blended morphing images are moved onto the mirror; ``morph_budget_mb``: GPU memory
    for the grids' node images; ``polish_camera``: a sample-based camera's ray-list and
    fold answers are polished on the true rays on the CPU (exact, seconds per camera with
    the numpy BVH: Render Image does it, the live viewport does not).
    """

    max_order: int = 2
    downsample: int = 4
    accuracy_px: float = 0.5
    polish_frames: bool = True
    morph_budget_mb: float = DEFAULT_MORPH_BUDGET_MB
    polish_camera: bool = True

    def __post_init__(self):
        object.__setattr__(self, "max_order", int(self.max_order))
        object.__setattr__(self, "downsample", int(self.downsample))
        object.__setattr__(self, "accuracy_px", float(self.accuracy_px))
        object.__setattr__(self, "polish_frames", bool(self.polish_frames))
        object.__setattr__(self, "morph_budget_mb", float(self.morph_budget_mb))
        object.__setattr__(self, "polish_camera", bool(self.polish_camera))
