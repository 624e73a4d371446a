"""Compiled kernel (numba) of :func:`ctseg.density.density_volume`: the gradient magnitude
of a volume in one pass, instead of numpy's three gradient arrays and the temporaries of
their squares (six arrays of the volume's size).

The arithmetic is :func:`numpy.gradient`'s with uniform spacing and ``edge_order=1``
(central differences over twice the spacing inside, one-sided ones on the faces) and then
``sqrt(gx * gx + gy * gy + gz * gz)`` in that order: the same bits.

Private: :func:`ctseg.density.density_volume` is the entry point.
"""
import math

from numba import njit, prange


@njit(cache=True)
def _diff(a, b, i, n, d):
    """numpy.gradient along one axis at index i of n, from the values a (at i - 1, or i on
    the first face) and b (at i + 1, or i on the last face)."""
    if i == 0 or i == n - 1:
        return (b - a) / d
    return (b - a) / (2.0 * d)


@njit(cache=True)
def _magnitude_slice(f, out, k, sz, sy, sx):
    nz, ny, nx = f.shape
    k0, k1 = max(k - 1, 0), min(k + 1, nz - 1)
    for j in range(ny):
        j0, j1 = max(j - 1, 0), min(j + 1, ny - 1)
        for i in range(nx):
            i0, i1 = max(i - 1, 0), min(i + 1, nx - 1)
            gz = _diff(f[k0, j, i], f[k1, j, i], k, nz, sz)
            gy = _diff(f[k, j0, i], f[k, j1, i], j, ny, sy)
            gx = _diff(f[k, j, i0], f[k, j, i1], i, nx, sx)
            out[k, j, i] = math.sqrt(gx * gx + gy * gy + gz * gz)


@njit(cache=True)
def gradient_magnitude(f, out, sz, sy, sx):
    """|grad f| of a volume (nz, ny, nx), every side >= 2, spacings along z, y, x."""
    for k in range(f.shape[0]):
        _magnitude_slice(f, out, k, sz, sy, sx)


@njit(cache=True, parallel=True)
def gradient_magnitude_parallel(f, out, sz, sy, sx):
    """:func:`gradient_magnitude`, slices in parallel (a voxel's value is its own)."""
    for k in prange(f.shape[0]):
        _magnitude_slice(f, out, k, sz, sy, sx)
