"""Process-wide settings that the ``nasset`` command applies to its own process.

A library must not change its host process, so nothing here runs on import: the ``nasset`` console
script (:func:`nasset_sdk.cli.console_main`) and the benchmark scripts call :func:`tune_allocator`,
and a program embedding the SDK may call it too.

The renderer and the bakers work in numpy wavefronts: per vertex, hundreds of temporaries of
0.1-30 MiB are made and freed. glibc serves blocks above its mmap threshold (128 KiB at start,
raised on the fly up to 32 MiB) with fresh ``mmap`` pages and returns heap memory above its trim
threshold to the kernel, so the same pages are faulted in and zeroed again on every wavefront.
Measured on the 8dna near-field bench (docs/benchmarks.md#allocator): renders 1.155x faster (median of
19 rounds) with less spread between runs, at the same peak memory.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

#: blocks below this many bytes come from the heap (glibc's largest allowed mmap threshold on 64-bit)
MMAP_THRESHOLD = 32 * 1024 * 1024
#: free memory at the heap's top kept for reuse before it is returned to the kernel
TRIM_THRESHOLD = 128 * 1024 * 1024
#: glibc ``mallopt`` parameter numbers (malloc.h)
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: environment variables through which a user sets these thresholds themselves (glibc reads them at start);
#: where any is set, :func:`tune_allocator` leaves the allocator alone
USER_SETTINGS = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "GLIBC_TUNABLES")


def _glibc():
    """The process's glibc (``ctypes.CDLL``), or None on another platform or C library."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    except OSError:
        return None
    return libc if hasattr(libc, "gnu_get_libc_version") and hasattr(libc, "mallopt") else None


def tune_allocator() -> bool:
    """Keep numpy's short-lived arrays on glibc's heap: mmap threshold :data:`MMAP_THRESHOLD`, trim threshold
    :data:`TRIM_THRESHOLD` (fixed values also switch off glibc's moving threshold).

    Returns True where applied; False (nothing changed) off glibc, or where the user set the allocator through
    one of :data:`USER_SETTINGS`."""
    if any(name in os.environ for name in USER_SETTINGS):
        return False
    libc = _glibc()
    if libc is None:
        return False
    libc.mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    libc.mallopt.restype = ctypes.c_int
    return bool(libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
