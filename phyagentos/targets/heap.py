"""Giving memory back after a large MuJoCo world is built or closed.

glibc's heap keeps freed pages mapped (the compiler's temporaries and robosuite's first
model after a LIBERO world is built; a closed world's model, data and renderers) until the
allocator decides to return them, so a process that builds one world after another grows
by what the last one left. ``malloc_trim(0)`` returns every whole free page of every arena
at once (10-50 ms after a LIBERO world); :func:`trim_heap` calls it where the C library is
glibc and does nothing elsewhere. It changes nothing a model or a simulation computes.

What it does not give back is MuJoCo's compiler **asset cache** (``mujoco.mj_getCache``):
every decoded texture and processed mesh, up to 512 MiB, kept so that compiling the same
files again is faster. A LIBERO world leaves 315-380 MB there. Emptying it
(``mujoco.mj_clearCache``) would save that much per process, but each LIBERO world built
later in the same process then takes about 2.3 s longer (1.6 s -> 3.9 s, libero_object
tasks 1-4 after task 0; a bench builds one per episode and one per task for the looks:
about +30 % wall time on a 10-episode run), so the cache stays.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools

__all__ = ["trim_heap"]


@functools.lru_cache(maxsize=1)
def _malloc_trim():
    """glibc's ``malloc_trim``, or None where the C library has none (musl, macOS)."""
    name = ctypes.util.find_library("c")
    try:
        fn = ctypes.CDLL(name).malloc_trim if name else None
    except (OSError, AttributeError):
        return None
    if fn is not None:
        fn.argtypes = [ctypes.c_size_t]
        fn.restype = ctypes.c_int
    return fn


def trim_heap() -> bool:
    """Return the heap's free pages to the operating system (glibc ``malloc_trim(0)``).
    Returns True if memory was released, False if none was or the C library is not glibc."""
    fn = _malloc_trim()
    if fn is None:
        return False
    return bool(fn(0))
