"""Compiled kernel (numba) of :func:`ctseg.density.flat_voxels`: the ramp voxels across
the slices, in one pass over the stack instead of a dozen numpy temporaries of its size
(the voxel-wise arithmetic is the same, so the mask is the same bit for bit).

Private: :func:`ctseg.density.flat_voxels` is the entry point.
"""
from numba import njit, prange


@njit(cache=True)
def _sign(x):
    if x > 0.0:
        return 1
    if x < 0.0:
        return -1
    return 0


@njit(cache=True)
def _clear_slice(smooth, noise, full, flat, k):
    """Clear the ramp voxels of interior slice k in ``flat``: both steps along z of one
    sign (the upper one nonzero), and the smaller step less the slice's noise gradient at
    least half the slice's full-density gradient less the noise."""
    half = 0.5 * (full[k] - noise[k])
    for j in range(smooth.shape[1]):
        for i in range(smooth.shape[2]):
            up = smooth[k + 1, j, i] - smooth[k, j, i]
            down = smooth[k, j, i] - smooth[k - 1, j, i]
            if up != 0.0 and _sign(up) == _sign(down):
                if min(abs(up), abs(down)) - noise[k] >= half:
                    flat[k, j, i] = False


@njit(cache=True)
def clear_ramps(smooth, noise, full, flat):
    """:func:`_clear_slice` for every interior slice, in order."""
    for k in range(1, smooth.shape[0] - 1):
        _clear_slice(smooth, noise, full, flat, k)


@njit(cache=True, parallel=True)
def clear_ramps_parallel(smooth, noise, full, flat):
    """:func:`clear_ramps`, slices in parallel (a voxel's result is its own)."""
    for k in prange(1, smooth.shape[0] - 1):
        _clear_slice(smooth, noise, full, flat, k)
