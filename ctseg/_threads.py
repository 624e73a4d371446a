"""Whether the compiled kernels may start numba's threads, and Python threads.

Private: the threaded kernels (``parallel=True``) of :mod:`ctseg._cvt`, :mod:`ctseg._clip`
and :mod:`ctseg.projection` give the same results as their serial twins, bit for bit;
their callers pick one by :data:`enabled`. Independent calls that release the GIL
(:mod:`ctseg._overlap_rows`' chunks, :func:`ctseg.blur.estimate_blur`'s blurs) run
side by side by :func:`thread_map`.
"""
from concurrent.futures import ThreadPoolExecutor

import numba

enabled = True
"""A worker process forked for slices turns this off (:func:`ctseg.volume._worker_init`):
the OpenMP runtime numba may use is not fork safe (a parallel kernel in a child of a
process that ran one aborts the child), and a worker per core leaves no core for threads
anyway."""


def pick(serial, threaded):
    """``threaded`` where threads are :data:`enabled`, else ``serial`` (kernels or tuples
    of kernels)."""
    return threaded if enabled else serial


def thread_map(fn, items):
    """``[fn(x) for x in items]``, on as many Python threads as numba's where threads are
    :data:`enabled` (for work that releases the GIL: compiled ``nogil`` kernels, ndimage
    filters); the order of the results is the order of ``items``."""
    items = list(items)
    n = min(numba.get_num_threads(), len(items)) if enabled else 1
    if n <= 1:
        return [fn(x) for x in items]
    with ThreadPoolExecutor(n) as pool:
        return list(pool.map(fn, items))


def workers():
    """How many threads a library call that takes a ``workers`` count may use (scipy's
    cKDTree queries): numba's where threads are :data:`enabled`, else 1."""
    return numba.get_num_threads() if enabled else 1
