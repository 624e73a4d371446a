"""How the 3D mode's large arrays get their memory (private).

A volume's working arrays (128 MiB each at 256^3, float64) are allocated and freed
hundreds of times in one job. By default each is a fresh mapping: glibc maps every block
above its mmap threshold (32 MiB at most) on its own and unmaps it when freed, so each new
array faults all its pages in again; and numpy advises the kernel to back arrays over
4 MiB with transparent huge pages, which a kernel that defragments on that advice (THP
``defrag`` 'madvise', a common default) pays for with compaction stalls at the faults.
Within :func:`bulk_allocations` glibc keeps large blocks on its heap and reuses them (no
mmap, no trimming) and numpy gives no advice; afterwards both are as before and the
freed heap goes back to the system (``malloc_trim``). Without glibc only numpy's advice
is turned off. The arrays' values do not depend on where their memory lies: results are
the same bit for bit (README, *Accuracy in 3D*, for the time it saves).
"""
import contextlib
import ctypes
import sys
import threading

_M_TRIM_THRESHOLD, _M_MMAP_MAX = -1, -4
"""mallopt's parameter numbers (glibc's malloc.h)."""

_GLIBC_DEFAULTS = {_M_TRIM_THRESHOLD: 128 * 1024, _M_MMAP_MAX: 65536}
"""glibc's documented defaults, restored afterwards (glibc has no call that reads them;
once set, its thresholds stay fixed instead of adapting, as ``MALLOC_*_`` variables fix
them)."""

_BULK = {_M_TRIM_THRESHOLD: 2 ** 31 - 1, _M_MMAP_MAX: 0}

_lock = threading.Lock()
_depth = 0
_saved_advice = None


def _glibc():
    """The process's C library where it is glibc (``mallopt`` and ``malloc_trim``), else
    None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None)
        libc.gnu_get_libc_version  # noqa: B018 (glibc only: musl has no such call)
        libc.mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
        libc.malloc_trim.argtypes = (ctypes.c_size_t,)
    except (OSError, AttributeError):
        return None
    return libc


def _hugepage_setter():
    """numpy's switch of its huge-page advice (numpy 2: ``numpy._core``; 1.x:
    ``numpy.core``), None where it has none."""
    for name in ("numpy._core.multiarray", "numpy.core.multiarray"):
        try:
            module = __import__(name, fromlist=["_set_madvise_hugepage"])
            return module._set_madvise_hugepage
        except (ImportError, AttributeError):
            continue
    return None


_LIBC = _glibc()
_SET_ADVICE = _hugepage_setter()


@contextlib.contextmanager
def bulk_allocations():
    """Within the block, large arrays reuse the heap and get no huge-page advice (see the
    module's doc); nested and concurrent blocks restore the settings when the last ends.
    Usable as a decorator.

    Example
    -------
    >>> import numpy as np
    >>> with bulk_allocations():
    ...     float(np.ones(10_000_000).sum())
    10000000.0
    """
    global _depth, _saved_advice
    with _lock:
        if _depth == 0:
            if _SET_ADVICE is not None:
                _saved_advice = _SET_ADVICE(False)
            if _LIBC is not None:
                for param, value in _BULK.items():
                    _LIBC.mallopt(param, value)
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                if _LIBC is not None:
                    for param, value in _GLIBC_DEFAULTS.items():
                        _LIBC.mallopt(param, value)
                    _LIBC.malloc_trim(0)
                if _SET_ADVICE is not None:
                    _SET_ADVICE(bool(_saved_advice))


def release_free_heap():
    """Inside :func:`bulk_allocations`: return the heap's free pages to the system now (so
    that the peak memory of the stage that starts next is its own); elsewhere nothing."""
    if _depth and _LIBC is not None:
        _LIBC.malloc_trim(0)
