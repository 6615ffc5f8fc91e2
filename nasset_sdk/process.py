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

:func:`single_threaded_blas` is scoped instead: the reference renderer's ``load_scene`` and ``render`` hold numpy's
BLAS to one thread while they run, and give it back afterwards (docs/benchmarks.md#blas-threads).
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import sys
import threading

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


#: (get, set) thread-count functions of the OpenBLAS builds numpy and scipy wheels bundle, by symbol name
_OPENBLAS_SYMBOLS = (("openblas_get_num_threads64_", "openblas_set_num_threads64_"),
                     ("openblas_get_num_threads", "openblas_set_num_threads"),
                     ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"),
                     ("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"))
_blas_lock = threading.Lock()
_blas_depth = 0
_blas_saved: list = []  # [(set function, thread count before)] while _blas_depth > 0


def _loaded_openblas() -> list:
    """(get, set) ctypes functions of each OpenBLAS library mapped into this process (Linux: ``/proc/self/maps``;
    elsewhere none); each library's functions looked up once."""
    try:
        with open("/proc/self/maps") as f:
            paths = {line.split(None, 5)[5].strip() for line in f if "openblas" in line.lower() and line.count(" ") >= 5}
    except (OSError, IndexError):
        return []
    for path in paths - _blas_functions.keys():
        _blas_functions[path] = _openblas_functions(path)
    return [_blas_functions[p] for p in sorted(paths) if _blas_functions[p] is not None]


_blas_functions: dict = {}  # library path -> its (get, set) thread-count functions, or None


def _openblas_functions(path: str):
    """(get, set) thread-count functions of the OpenBLAS library at ``path`` (already loaded: the same handle, nothing is
    initialised again), or None where it has neither naming."""
    try:
        lib = ctypes.CDLL(path)
    except OSError:
        return None
    for get_name, set_name in _OPENBLAS_SYMBOLS:
        if hasattr(lib, get_name) and hasattr(lib, set_name):
            get, put = getattr(lib, get_name), getattr(lib, set_name)
            get.restype, get.argtypes, put.restype, put.argtypes = ctypes.c_int, (), None, (ctypes.c_int,)
            return get, put
    return None


@contextlib.contextmanager
def single_threaded_blas():
    """numpy's BLAS (OpenBLAS) on one thread while the block runs, as before it afterwards.

    The renderers' wavefronts multiply [n, 3] rows by 3 x 3 matrices and vectors. OpenBLAS splits such products
    over its threads, which then wait for the next one by spinning on ``sched_yield``: on the dense-hair bench that
    kept a second core busy in the kernel for the whole render (2.3 s of system time in a 2.6 s render on one
    render thread), and with two render threads it took the core the second one needed (docs/benchmarks.md#blas-threads).
    The results do not depend on the thread count (the products split by rows). Nested and concurrent blocks share
    one setting; the last to leave restores the counts. Without OpenBLAS in the process this does nothing."""
    global _blas_depth
    with _blas_lock:
        if _blas_depth == 0:
            _blas_saved[:] = [(put, get()) for get, put in _loaded_openblas()]
            for put, _ in _blas_saved:
                put(1)
        _blas_depth += 1
    try:
        yield
    finally:
        with _blas_lock:
            _blas_depth -= 1
            if _blas_depth == 0:
                for put, count in _blas_saved:
                    put(count)
                _blas_saved.clear()
