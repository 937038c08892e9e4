# SPDX-License-Identifier: GPL-3.0-or-later
"""Glass: refraction at the interfaces of glass solids and sheets (issue 47).

``snell`` holds the optics of one interface (Snell's law, total internal reflection,
dielectric Fresnel); ``paths`` follows rays through a scene's glass, interface after
interface; ``refraction_search`` says which glass the GPU's per-vertex search of refracted
paths can draw (``drawing/methods/refraction_draw.py``), and holds its constants. Not shipped: the exact reference solver of refracted images
(``tools/exact_refraction.py``) and sample-based cameras on refracted rays
(``tools/glass_camera.py``, SBC paper VII).
"""

from .paths import GlassPaths, GlassSet, Glass
from .snell import fresnel_dielectric, refract

__all__ = ["Glass", "GlassPaths", "GlassSet", "fresnel_dielectric", "refract"]
