# SPDX-License-Identifier: GPL-3.0-or-later
"""A sample-based camera as a flat dict of plain numpy arrays, and back.

Baked morphing grids are stored as ``.npz`` and loaded with ``allow_pickle=False``
(no code runs from a cache file), so everything an SBC holds is written as numeric or
fixed-width string arrays. The walk is generic over dataclass fields (the camera, its
ray map and view, its BSP trees, their leaf models, its mixed-cell tables), so a field
added to any of them is stored too; a class is named by a string and looked up in
:data:`CLASSES` when read back. Group grids are not stored: they are recomputed from
the ray map (one per surface set of a history, shared by its sheets).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from .bsp import BSPTree
from .pinhole import PinholeCameras
from .ray_patch import RayPatches
from .raymap import RayMap
from .sbc import SampleBasedCamera
from .sbc_cells import FoldCells, MixedCells
from ...view import View

CLASSES = {cls.__name__: cls for cls in (SampleBasedCamera, RayMap, View, BSPTree, RayPatches, PinholeCameras,
                                         MixedCells, FoldCells)}
#: Fields recomputed on load rather than stored.
DERIVED = {"SampleBasedCamera": ("grids",)}
#: Fields not stored: references to the scene a camera was built in (the reflectors that
#: polish answers on the true rays), and the first orders left to a frame's per-frame
#: methods (a stored camera is a grid node's, made for every group); a loaded camera has
#: their defaults (None, none left out).
TRANSIENT = {"SampleBasedCamera": ("true_rays", "first_order_left_out")}


def _put(out: dict, key: str, value) -> None:
    if value is None:
        out[key + "#none"] = np.array(0)
    elif dataclasses.is_dataclass(value):
        name = type(value).__name__
        if name not in CLASSES:
            raise TypeError(f"cannot store a {name}")
        out[key + "#class"] = np.array(name)
        for f in dataclasses.fields(value):
            if f.name not in DERIVED.get(name, ()) + TRANSIENT.get(name, ()):
                _put(out, f"{key}.{f.name}", getattr(value, f.name))
    elif isinstance(value, np.ndarray):
        if value.dtype == object:
            raise TypeError(f"{key}: object arrays would need pickle")
        out[key] = value
    elif isinstance(value, (bool, int, float, np.generic)):
        out[key + "#scalar"] = np.array(value)
    elif isinstance(value, str):
        out[key + "#str"] = np.array(value)
    elif isinstance(value, dict):
        out[key + "#json"] = np.array(json.dumps(value))
    elif isinstance(value, (list, tuple)):
        out[key + ("#tuple" if isinstance(value, tuple) else "#list")] = np.array(len(value))
        for k, item in enumerate(value):
            _put(out, f"{key}[{k}]", item)
    else:
        raise TypeError(f"{key}: cannot store a {type(value).__name__}")


def _get(data, key: str):
    if key in data:
        return data[key]
    if key + "#none" in data:
        return None
    if key + "#scalar" in data:
        return data[key + "#scalar"].item()
    if key + "#str" in data:
        return str(data[key + "#str"])
    if key + "#json" in data:
        return json.loads(str(data[key + "#json"]))
    for marker, kind in (("#tuple", tuple), ("#list", list)):
        if key + marker in data:
            return kind(_get(data, f"{key}[{k}]") for k in range(int(data[key + marker])))
    if key + "#class" in data:
        name = str(data[key + "#class"])
        if name not in CLASSES:
            raise ValueError(f"unknown class {name!r}")
        cls = CLASSES[name]
        values = {f.name: _get(data, f"{key}.{f.name}") for f in dataclasses.fields(cls)
                  if f.name not in DERIVED.get(name, ()) + TRANSIENT.get(name, ()) and f.init}
        if name == "SampleBasedCamera":
            ray_map = values["ray_map"]
            surfaces = values["surfaces"] or [None] * len(values["histories"])
            keys = [(tuple(h), None if s is None else tuple(s)) for h, s in zip(values["histories"], surfaces)]
            # The sheets of one surface set share one grid object, as when built.
            grids = {key: ray_map.group_grid(ray_map.histories.index(key[0]), key[1]) for key in dict.fromkeys(keys)}
            values["grids"] = [grids[key] for key in keys]
        return cls(**values)
    raise KeyError(f"{key} is not stored")


def sbc_to_arrays(sbc: SampleBasedCamera, prefix: str = "") -> dict:
    """Every array of ``sbc`` under keys starting with ``prefix``."""
    out = {}
    _put(out, prefix + "sbc", sbc)
    return out


def sbc_from_arrays(data, prefix: str = "", name: str | None = None) -> SampleBasedCamera:
    """The camera written by :func:`sbc_to_arrays` (``data``: a dict of arrays)."""
    if not isinstance(data, dict):
        data = {k: data[k] for k in data.files}
    sbc = _get(data, prefix + "sbc")
    if not isinstance(sbc, SampleBasedCamera):
        raise ValueError(f"{prefix}sbc is not a sample-based camera")
    return sbc
