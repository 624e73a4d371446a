"""Compiled kernel (numba) of :func:`ctseg.blur.estimate_blur`: the voxels next to a level
change, in one pass instead of a 3 x 3 x 3 maximum and minimum filter and their
difference (the same mask: the largest and smallest value of a neighbourhood differ where
one value in it differs from the voxel's own).

Private: :func:`ctseg.blur.estimate_blur` is the entry point.
"""
from numba import njit, prange


@njit(cache=True)
def _differs(lev, k, j, i):
    """Whether the 3 x 3 x 3 neighbourhood of voxel (k, j, i), clipped to the array (as
    ``mode='nearest'`` repeats the border), holds a value other than its own."""
    nz, ny, nx = lev.shape
    v = lev[k, j, i]
    for kk in range(max(k - 1, 0), min(k + 2, nz)):
        for jj in range(max(j - 1, 0), min(j + 2, ny)):
            for ii in range(max(i - 1, 0), min(i + 2, nx)):
                if lev[kk, jj, ii] != v:
                    return True
    return False


@njit(cache=True)
def _mark_slice(lev, out, k):
    """Mark the voxels of slice k next to a level change (:func:`_differs`)."""
    for j in range(lev.shape[1]):
        for i in range(lev.shape[2]):
            out[k, j, i] = _differs(lev, k, j, i)


@njit(cache=True)
def level_changes(lev, out):
    """:func:`_mark_slice` for every slice of ``lev`` (nz, ny, nx), into ``out``."""
    for k in range(lev.shape[0]):
        _mark_slice(lev, out, k)


@njit(cache=True, parallel=True)
def level_changes_parallel(lev, out):
    """:func:`level_changes`, slices in parallel (a voxel's result is its own)."""
    for k in prange(lev.shape[0]):
        _mark_slice(lev, out, k)
