"""Compiled kernels (numba) of the sums over a mesh's kept voxel overlaps (the compressed
rows of :class:`ctseg.tetra_gray.VoxelOverlaps`): per tetrahedron (its rows, in parallel:
each tetrahedron's sum is its own, in the same order) and per voxel.

Each sums the overlaps in the order :func:`ctseg._tet_clip._overlaps` visits them, so the
means equal those of the streaming kernel bit for bit. Private:
:class:`ctseg.tetra_gray.VoxelOverlaps` is the entry point.
"""
import numpy as np
from numba import njit, prange


@njit(cache=True)
def _row_sum(start, voxel, overlap, img, t, vol, w):
    for q in range(start[t], start[t + 1]):
        a = overlap[q]
        vol[t] += a
        if img.shape[0] > 0:
            w[t] += a * img[voxel[q]]


@njit(cache=True)
def row_sums(start, voxel, overlap, img):
    """Per tetrahedron: the overlap volume and the volume x gray of ``img`` (flat; the
    volume alone when empty)."""
    m = start.shape[0] - 1
    vol = np.zeros(m)
    w = np.zeros(m)
    for t in range(m):
        _row_sum(start, voxel, overlap, img, t, vol, w)
    return vol, w


@njit(cache=True, parallel=True)
def row_sums_parallel(start, voxel, overlap, img):
    """:func:`row_sums`, tetrahedra in parallel."""
    m = start.shape[0] - 1
    vol = np.zeros(m)
    w = np.zeros(m)
    for t in prange(m):
        _row_sum(start, voxel, overlap, img, t, vol, w)
    return vol, w


@njit(cache=True)
def column_sums(start, voxel, overlap, values, n):
    """Per voxel (of ``n``): the overlap volume and the volume x value of the tetrahedra,
    in tetrahedron order."""
    vol = np.zeros(n)
    w = np.zeros(n)
    for t in range(start.shape[0] - 1):
        for q in range(start[t], start[t + 1]):
            c = voxel[q]
            a = overlap[q]
            vol[c] += a
            w[c] += a * values[t]
    return vol, w
