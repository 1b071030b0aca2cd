"""Freed memory kept for the next frame, not handed back to the kernel and faulted in again.

A participant that handles camera frames allocates and frees buffers of a megabyte or more at
every step (a frame's bytes, numpy's temporaries). glibc's malloc hands such blocks back to the
kernel once more than about twice the largest block lies free at the top of the heap, so the
next step faults every page in again: the perception participant took 560 page faults a frame,
a third of its CPU time in the kernel. ``keep_freed_memory`` raises both of glibc's thresholds
(blocks under 32 MiB come from the heap; up to 128 MiB of free heap is kept) for the process;
``coupler.server.run`` calls it, so every participant program and the OpenRails mock get it. A
user's own ``MALLOC_MMAP_THRESHOLD_`` or ``MALLOC_TRIM_THRESHOLD_`` wins; on another C library
(musl, macOS) nothing changes.
"""

from __future__ import annotations

import ctypes
import os

MMAP_THRESHOLD = 32 << 20
"""Blocks smaller than this come from the heap, not from a mapping of their own."""
TRIM_THRESHOLD = 128 << 20
"""Free memory at the top of the heap kept up to this much."""
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters


def keep_freed_memory() -> bool:
    """Set glibc's thresholds for this process; whether they were set (False: not glibc, or
    the environment sets them already)."""
    if "MALLOC_MMAP_THRESHOLD_" in os.environ or "MALLOC_TRIM_THRESHOLD_" in os.environ:
        return False
    try:
        libc = ctypes.CDLL(None)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    if not hasattr(libc, "gnu_get_libc_version"):
        return False  # not glibc (musl's mallopt does nothing)
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(
        mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD)
    )
