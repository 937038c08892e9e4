# SPDX-License-Identifier: GPL-3.0-or-later
"""Named arrays packed into a layout and one buffer (``engine/baking/packed_arrays.py``),
the form of a node file."""

import io
import json

import numpy as np
import pytest

from curved_reflections.engine.baking.packed_arrays import ALIGNMENT, pack_arrays, unpack_arrays


def _arrays():
    rng = np.random.default_rng(3)
    return {"points": rng.normal(size=(7, 3)), "index": np.arange(-1, 12, dtype=np.int64).reshape(13, 1),
            "valid": np.array([True, False, True]), "name#str": np.array("face0"), "count#scalar": np.array(5),
            "empty": np.zeros((0, 4), np.float32), "labels": np.array(["a", "bcd"]), "one": np.array(2.5),
            "tail": np.arange(3, dtype=np.int8)}


def test_packed_arrays_come_back_equal_in_dtype_shape_and_value_through_an_npz():
    arrays = _arrays()
    stream = io.BytesIO()
    np.savez_compressed(stream, **pack_arrays(arrays))
    stream.seek(0)
    with np.load(stream, allow_pickle=False) as data:
        assert sorted(data.files) == ["data", "layout"]
        back = unpack_arrays({k: data[k] for k in data.files})
    assert list(back) == list(arrays)
    for name, value in arrays.items():
        assert back[name].dtype == value.dtype and back[name].shape == value.shape, name
        np.testing.assert_array_equal(back[name], value)
    starts = [start for _, _, _, start in json.loads(str(pack_arrays(arrays)["layout"]))]
    assert all(start % ALIGNMENT == 0 for start in starts) and starts == sorted(starts)


def test_a_malformed_packing_is_refused_with_a_value_error():
    packed = pack_arrays(_arrays())
    layout = json.loads(str(packed["layout"]))
    layout[0][3] = len(packed["data"])  # the first array past the buffer's end
    with pytest.raises(ValueError, match="points lies outside"):
        unpack_arrays({"layout": np.array(json.dumps(layout)), "data": packed["data"]})
    with pytest.raises(ValueError, match="not bytes"):
        unpack_arrays({"layout": packed["layout"], "data": packed["data"].view(np.int16)})
    with pytest.raises(KeyError):
        unpack_arrays({"data": packed["data"]})
    with pytest.raises(TypeError, match="object arrays"):
        pack_arrays({"cameras": np.array([object()])})
