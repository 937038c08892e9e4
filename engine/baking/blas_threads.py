# SPDX-License-Identifier: GPL-3.0-or-later
"""One BLAS thread per bake worker.

A bake runs one worker process per core. numpy's OpenBLAS starts a thread per core in
each of them as well, and on the small matrix products of a node build those threads
spin waiting for work: with two workers on two cores, each worker's spare thread took
CPU from the other worker (0.1 s of a node's 0.3 s, measured with
``OPENBLAS_NUM_THREADS=1`` against the default). The environment variable cannot help
once numpy is loaded (inside Blender it always is), so each worker asks the library
itself, as threadpoolctl does: find numpy's OpenBLAS among the loaded libraries and call
its ``openblas_set_num_threads``. Where none is found (another BLAS, another platform)
nothing changes and the bake is only slower.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

#: Entry points by OpenBLAS build: numpy's 64-bit-integer build suffixes its symbols.
SET_THREADS_SYMBOLS = ("openblas_set_num_threads64_", "openblas_set_num_threads", "scipy_openblas_set_num_threads64_")


def _loaded_openblas() -> list[str]:
    """Paths of the OpenBLAS libraries in this process: from /proc/self/maps (Linux),
    else those shipped beside numpy (macOS wheels keep them in numpy/.dylibs)."""
    maps = Path("/proc/self/maps")
    if maps.exists():
        with open(maps) as lines:
            return sorted({line.split()[-1] for line in lines if "openblas" in line.split()[-1].lower()})
    package = Path(np.__file__).parent
    return sorted(str(p) for folder in (package / ".dylibs", package.parent / "numpy.libs")
                  for p in folder.glob("*openblas*"))


def limit_blas_threads(count: int = 1) -> int:
    """Ask every loaded OpenBLAS to use ``count`` threads; returns how many libraries did."""
    limited = 0
    for path in _loaded_openblas():
        try:
            library = ctypes.CDLL(path)
        except OSError:
            continue
        for symbol in SET_THREADS_SYMBOLS:
            setter = getattr(library, symbol, None)
            if setter is not None:
                setter(ctypes.c_int(count))
                limited += 1
                break
    return limited
