"""Whether the compiled kernels may start numba's threads.

Private: the threaded kernels (``parallel=True``) of :mod:`ctseg._cvt`, :mod:`ctseg._clip`
and :mod:`ctseg.projection` give the same results as their serial twins, bit for bit;
their callers pick one by :data:`enabled`.
"""

enabled = True
"""A worker process forked for slices turns this off (:func:`ctseg.volume._worker_init`):
the OpenMP runtime numba may use is not fork safe (a parallel kernel in a child of a
process that ran one aborts the child), and a worker per core leaves no core for threads
anyway."""


def pick(serial, threaded):
    """``threaded`` where threads are :data:`enabled`, else ``serial`` (kernels or tuples
    of kernels)."""
    return threaded if enabled else serial
