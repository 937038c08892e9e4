# SPDX-License-Identifier: GPL-3.0-or-later
import platform

from curved_reflections.engine.heap import release_freed_memory


def test_freed_memory_is_handed_back_where_the_c_library_is_glibc():
    """glibc's malloc_trim runs (a frame calls it between its stages); elsewhere nothing
    happens and nothing fails."""
    ran = release_freed_memory()
    assert ran == (platform.system() == "Linux" and platform.libc_ver()[0] == "glibc")
    assert release_freed_memory() == ran
