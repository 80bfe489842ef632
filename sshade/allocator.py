"""glibc's memory allocator, told how to treat freed memory.

- :func:`keep_freed_memory` : keep it for reuse (SShaDe's forked sampling workers);
- :func:`release_freed` : give it back to the OS (before a memory measurement).

Both are no-ops returning False where the C library lacks the function (not glibc).
"""
from __future__ import annotations

import ctypes

__all__ = ["keep_freed_memory", "release_freed"]


def _libc(name: str, argtypes: list):
    """The C library's function ``name`` (returning int) with these argument types, or
    None where it has none (musl, macOS; Windows, where ``CDLL(None)`` is refused)."""
    try:
        fn = getattr(ctypes.CDLL(None), name)
    except (OSError, AttributeError, TypeError):  # pragma: no cover - not glibc
        return None
    fn.argtypes, fn.restype = argtypes, ctypes.c_int
    return fn


#: glibc's mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3


def keep_freed_memory(mmap_threshold: int = 1 << 28, trim_threshold: int = 1 << 30) -> bool:
    """Tell glibc's allocator (this process only) to serve blocks below
    ``mmap_threshold`` bytes from its heap and to give freed heap memory back to the OS
    only above ``trim_threshold`` bytes, so that the arrays a sampling allocates and
    frees again and again (tens of MB each at a million vertices) reuse memory already
    mapped instead of a fresh ``mmap`` each time, whose first-touch page faults and
    ``munmap`` are a large part of a SShaDe call at a million vertices (the
    figures: ``results/scaling``).

    Called in the samplings' forked workers only (:mod:`sshade.sampling`; they end with
    the pool), never in the caller's process, whose memory behaviour stays its own. A
    no-op returning False where the C library has no ``mallopt`` (not glibc).

    Returns
    -------
    bool, whether both settings were taken.
    """
    mallopt = _libc("mallopt", [ctypes.c_int, ctypes.c_int])
    if mallopt is None:
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, int(mmap_threshold)) and mallopt(_M_TRIM_THRESHOLD, int(trim_threshold)))


def release_freed() -> bool:
    """Give the memory this process has freed back to the OS (glibc ``malloc_trim(0)``,
    after a garbage collection), so that a PSS measured next counts live data, not what
    earlier work left in the allocator's heap. Returns whether ``malloc_trim`` was
    called (False without glibc)."""
    import gc
    gc.collect()
    trim = _libc("malloc_trim", [ctypes.c_size_t])
    if trim is None:
        return False
    trim(0)
    return True
