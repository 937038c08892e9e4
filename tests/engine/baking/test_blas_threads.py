# SPDX-License-Identifier: GPL-3.0-or-later
import ctypes
import multiprocessing
import sys

import pytest

from curved_reflections.engine.baking import blas_threads


def _threads_after_limit(_):
    limited = blas_threads.limit_blas_threads(1)
    counts = []
    for path in blas_threads._loaded_openblas():
        library = ctypes.CDLL(path)
        getter = getattr(library, "openblas_get_num_threads64_", None) or getattr(library, "openblas_get_num_threads")
        counts.append(getter())
    return limited, counts


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the bake forks workers on Linux and macOS; "
                    "this checks numpy's OpenBLAS wheel on Linux, the platform CI runs")
def test_a_forked_bake_worker_runs_numpys_openblas_on_one_thread():
    # In a forked child, as the bake's pool initializer runs: the parent keeps its threads.
    with multiprocessing.get_context("fork").Pool(1) as pool:
        limited, counts = pool.map(_threads_after_limit, [0])[0]
    assert limited >= 1, "numpy's OpenBLAS was not found among the loaded libraries"
    assert counts and all(c == 1 for c in counts)
