# SPDX-License-Identifier: GPL-3.0-or-later
"""Many named arrays as two: a layout and one byte buffer.

A node's cameras are a few hundred arrays (``sbc_arrays``: every field of every face's
camera, markers and scalars included). Written one by one into an ``.npz``, each is a
zip entry with its own header, deflate stream and checksum: the 9x9x5 bake spent 9.7 of
its 119.5 CPU seconds writing node files, about twice what compressing their bytes
takes. Packed, a node file holds three entries (the key, this layout, these bytes), and
reading it back makes views into one buffer. Only numeric, boolean and fixed-width
string arrays are stored (as ``np.save`` would, never pickled objects).
"""

from __future__ import annotations

import json

import numpy as np

#: Every array starts at a multiple of this in the buffer (the widest element).
ALIGNMENT = 16


def pack_arrays(arrays: dict) -> dict:
    """{"layout": JSON of (name, dtype, shape, offset) per array, "data": uint8 buffer}."""
    layout, offset = [], 0
    for name, value in arrays.items():
        value = np.asarray(value)
        if value.dtype.hasobject:
            raise TypeError(f"{name}: object arrays cannot be stored")
        layout.append((name, value.dtype.str, list(value.shape), offset))
        offset += -(-value.nbytes // ALIGNMENT) * ALIGNMENT
    data = np.zeros(offset, np.uint8)
    for (name, _, _, start), value in zip(layout, arrays.values()):
        flat = np.ascontiguousarray(value).reshape(-1).view(np.uint8)
        data[start:start + len(flat)] = flat
    return {"layout": np.array(json.dumps(layout)), "data": data}


def unpack_arrays(packed) -> dict:
    """The arrays of :func:`pack_arrays` (views into ``packed["data"]``). A malformed
    layout raises ValueError or KeyError."""
    data = np.asarray(packed["data"])
    if data.dtype != np.uint8 or data.ndim != 1:
        raise ValueError("the packed buffer is not bytes")
    out = {}
    for name, dtype, shape, start in json.loads(str(packed["layout"])):
        dtype = np.dtype(dtype)
        if dtype.hasobject:
            raise ValueError(f"{name}: object arrays cannot be read")
        count = int(np.prod(shape, dtype=np.int64))
        end = start + count * dtype.itemsize
        if start < 0 or end > len(data):
            raise ValueError(f"{name} lies outside the packed buffer")
        out[name] = data[start:end].view(dtype).reshape(shape)
    return out
