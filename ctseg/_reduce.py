"""Sums over long vectors that give the same bits on every machine.

Private. numpy hands ``u @ v`` (and ``np.cov``, ``np.dot``) on long vectors to the BLAS,
and OpenBLAS splits a long dot product over its threads: the partial sums, so the last
bits, follow the machine's thread count, and the result of a segmentation could follow
them too (a 512 x 512 slice gave another mesh with ``OPENBLAS_NUM_THREADS=1``). Its
threads also spin for a while after each call, taking the cores from numba's. numpy's
own loops (``einsum`` without ``optimize``, ``sum``) run in one thread in a fixed order.
"""
import numpy as np


def dot(u, v):
    """Inner product of two 1D float arrays, in numpy's own loop (no BLAS)."""
    return float(np.einsum("i,i->", u, v))


def weighted_variance(v, w):
    """``np.cov(v, aweights=w)`` (unbiased for reliability weights), without BLAS."""
    v = np.asarray(v, float)
    w = np.asarray(w, float)
    sw = float(np.sum(w))
    d = v - dot(w, v) / sw
    return dot(w, d * d) / (sw - dot(w, w) / sw)
