"""Compiled kernel (numba) of the full voxel assignment of :mod:`ctseg.cvt3d`: every voxel's
nearest and second-nearest site and third-nearest distance, exactly, searched block by
block.

Neighbouring voxels share their nearest sites. A block of voxels (about half a site-grid
cell on a side) searches once for the sites that can be among any of its voxels' three
nearest, and each voxel then scans only those: if q is the block's centre and r its half
diagonal, a voxel p of the block has its third-nearest site within d3(q) + r (the third
nearest of q are that close to p), so each of its three nearest lies within
d3(q) + 2 r of q. The scan keeps the three best by (distance, index), whatever the order
of the candidates, with the distances computed as :func:`ctseg._cvt3d._three_nearest_3d`
computes them: the same labels and bounds, bit for bit.

Private: :func:`ctseg.cvt3d.lloyd_cvt_3d` is the entry point.
"""
import numpy as np
from numba import njit, prange

from ._cvt3d import _down, _scan, _site_grid_3d, _three_nearest_3d, _up

_BLOCK_CELLS = 0.5
"""A block's edge, in site-grid cells (at least one voxel): larger blocks search less
often and scan more candidates per voxel."""

_REACH_SLACK = 1e-9
"""Relative widening of the candidates' radius: the triangle inequality holds exactly,
its floating-point evaluation to within round-off."""


@njit(cache=True)
def _axis_blocks(size, s, h):
    """Block length (voxels) along an axis of ``size`` voxels ``s`` apart."""
    return max(1, min(size, int(round(_BLOCK_CELLS * h / s))))


@njit(cache=True)
def _cell_span(lo, hi, h, g):
    """The site-grid cells along one axis that hold the coordinates in [lo, hi]."""
    a = 0 if lo <= 0.0 else min(int(lo / h), g - 1)
    b = g - 1 if hi == np.inf else min(max(int(hi / h), 0), g - 1)
    return a, b


@njit(cache=True)
def _gather(qx, qy, qz, reach, h, gx, gy, gz, start, items, coords, c_items, c_coords):
    """Copy the sites within ``reach`` of (qx, qy, qz) (all of them when it is inf) into
    ``c_items``, ``c_coords``; returns their count."""
    x0, x1 = _cell_span(qx - reach, qx + reach, h, gx)
    y0, y1 = _cell_span(qy - reach, qy + reach, h, gy)
    z0, z1 = _cell_span(qz - reach, qz + reach, h, gz)
    r2 = reach * reach
    m = 0
    for zz in range(z0, z1 + 1):
        for yy in range(y0, y1 + 1):
            row = (zz * gy + yy) * gx
            for t in range(start[row + x0], start[row + x1 + 1]):
                dx = coords[t, 0] - qx
                dy = coords[t, 1] - qy
                dz = coords[t, 2] - qz
                if dx * dx + dy * dy + dz * dz <= r2:
                    c_items[m] = items[t]
                    c_coords[m, 0] = coords[t, 0]
                    c_coords[m, 1] = coords[t, 1]
                    c_coords[m, 2] = coords[t, 2]
                    m += 1
    return m


@njit(cache=True, parallel=True)
def _assign_3d(nz, ny, nx, sx, sy, sz, sites, labels, second, u, l2, l3):
    """Exact nearest site (labels, distance u), second nearest (second, distance l2) and
    third-nearest distance (l3) of every voxel centre, ties to the lower site index
    (z-slabs of blocks in parallel: each voxel's result is its own, so the thread count
    changes nothing)."""
    h, gx, gy, gz, start, items, coords = _site_grid_3d(sites, (nx - 1) * sx, (ny - 1) * sy,
                                                        (nz - 1) * sz)
    bx, by, bz = _axis_blocks(nx, sx, h), _axis_blocks(ny, sy, h), _axis_blocks(nz, sz, h)
    n = sites.shape[0]
    for kb in prange((nz + bz - 1) // bz):
        c_items = np.empty(n, np.int64)
        c_coords = np.empty((n, 3))
        k0, k1 = kb * bz, min((kb + 1) * bz, nz)
        for j0 in range(0, ny, by):
            j1 = min(j0 + by, ny)
            for i0 in range(0, nx, bx):
                i1 = min(i0 + bx, nx)
                ex, ey, ez = (i1 - 1 - i0) * sx, (j1 - 1 - j0) * sy, (k1 - 1 - k0) * sz
                qx, qy, qz = i0 * sx + 0.5 * ex, j0 * sy + 0.5 * ey, k0 * sz + 0.5 * ez
                d3 = _three_nearest_3d(qx, qy, qz, h, gx, gy, gz, start, items, coords)[4]
                reach = (d3 + np.sqrt(ex * ex + ey * ey + ez * ez)) * (1.0 + _REACH_SLACK)
                m = _gather(qx, qy, qz, reach, h, gx, gy, gz, start, items, coords,
                            c_items, c_coords)
                for k in range(k0, k1):
                    for j in range(j0, j1):
                        for i in range(i0, i1):
                            best = _scan(i * sx, j * sy, k * sz, c_coords, c_items, 0, m,
                                         (np.inf, -1, np.inf, -1, np.inf, -1))
                            v = (k * ny + j) * nx + i
                            labels[v] = best[1]
                            second[v] = best[3]
                            u[v] = _up(np.sqrt(best[0]))
                            l2[v] = _down(np.sqrt(best[2]))
                            l3[v] = _down(np.sqrt(best[4]))
