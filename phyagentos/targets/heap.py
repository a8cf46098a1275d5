"""Giving memory back after a large MuJoCo world is built or closed.

Two things keep a process's resident memory high after a big model (a LIBERO world: 14
textures, 147 MB, a million mesh vertices) is compiled or freed:

- MuJoCo's **asset cache** (``mj_getCache``): the compiler keeps every decoded texture and
  processed mesh, up to 512 MiB by default, so that compiling the same files again is
  faster. A LIBERO world leaves 315 MB there (measured: libero_object task 5), allocated by
  the compiler's threads in glibc's per-thread arenas. :func:`clear_asset_cache` empties it.
- **glibc's heap** keeps freed pages mapped (the compiler's temporaries, a closed world's
  model and renderers) until the allocator decides to return them; ``malloc_trim(0)``
  returns every whole free page of every arena at once (10-50 ms after a LIBERO world).
  :func:`trim_heap` calls it where the C library is glibc and does nothing elsewhere.

Neither changes what a model or a simulation computes: the cache only saves decoding time
(a LIBERO world built again in the same process: about 1-2 s more without it).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import logging

import mujoco

__all__ = ["clear_asset_cache", "trim_heap"]

log = logging.getLogger(__name__)


def clear_asset_cache() -> int:
    """Empty MuJoCo's compiler asset cache; returns the bytes it held."""
    cache = mujoco.mj_getCache()
    held = int(mujoco.mj_getCacheSize(cache))
    mujoco.mj_clearCache(cache)
    return held


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
