"""The process's C allocator: one malloc arena for the ``lodprt`` command (glibc).

glibc's malloc gives each thread that allocates its own arena, up to eight per core. lodprt's threads allocate: the
CPU kernel slices (``lodprt.launches.KernelThreads``) and their numpy temporaries, and, in the viewer, Mesa's
llvmpipe threads. Memory a thread frees goes back to that thread's arena, and an arena's heaps are handed back to
the system only from their top, so the freed temporaries of each light sample completed at run time stay resident
beside the next sample's. Measured on the bunny + 1000 floor (1.04M vertices, 27 samples, ``lodprt view --path
orbit --frames 10``): the viewer's resident peak climbed by 30-45 MB a sample completed, to 1.72 GB headless and
2.00 GB in a window, where ``lodprt frames`` on the same store peaked at 1.48 GB; with one arena the viewer
peaked at 1.43 and 1.46 GB, ``frames`` at 1.29 GB and ``lodprt bake`` at 1.15 GB against 1.38 GB, their frame
and bake times unchanged (docs/SCALE.md, "One malloc arena").

``one_malloc_arena()`` is the first thing ``lodprt.cli.main`` does; a program that uses the library from Python can
call it first too, or set ``MALLOC_ARENA_MAX=1`` in its environment.
"""

from __future__ import annotations

import ctypes
import os
import sys

#: the environment variable glibc reads at start-up, and the ``mallopt`` parameter that sets the same (malloc.h)
ARENA_VARIABLE = "MALLOC_ARENA_MAX"
M_ARENA_MAX = -8


def one_malloc_arena() -> bool:
    """Make every thread of this process, and of the processes it starts, allocate from one malloc arena: set
    ``MALLOC_ARENA_MAX=1`` for child processes (a bake's local dask workers) and call glibc's ``mallopt`` for this
    one. Threads started before the call keep the arena they have. Nothing changes when ``MALLOC_ARENA_MAX`` is set
    already (the user's value stands), off Linux, or when the C library has no working ``mallopt`` (musl's returns
    0). True when this process now allocates from one arena."""
    if not sys.platform.startswith("linux") or os.environ.get(ARENA_VARIABLE):
        return False  # (ctypes.CDLL(None) is a TypeError on Windows)
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    if mallopt(M_ARENA_MAX, 1) != 1:  # 1 on success; musl's and other libraries' stubs return 0
        return False
    os.environ[ARENA_VARIABLE] = "1"
    return True
