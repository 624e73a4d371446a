"""Compiled kernels (numba) of :mod:`ctseg.cvt3d`: the exact nearest-site search on a 3D
site grid, the voxel assignment kept up to date by Hamerly-style bounds on the two
nearest sites, and the per-region sums (the first, full assignment: :mod:`ctseg._assign3d`).

Voxel (k, j, i) is the point (i sx, j sy, k sz); flat index (k ny + j) nx + i. Private:
:func:`ctseg.cvt3d.lloyd_cvt_3d` is the entry point.

The per-voxel state (labels, second: int32; u, l2, l3: float32) is half the bytes of
int64 / float64: the update of the bounds is a pass over it every iteration, bound by
memory. The bounds are rounded outwards when stored (u up, l2 and l3 down: :func:`_up`,
:func:`_down`), so they stay bounds and the labels stay exact.
"""
import numpy as np
from numba import njit, prange

from ._cvt import _block_margin

_REACH = 1
_REACH2 = 3
"""Cells: the ring of sites beyond _REACH and within this is bounded by its own largest
drift (one fast site far away then lowers no bound)."""
"""Cells: the drift of the sites that started this near a voxel's cell lowers its bound
on the other sites; a farther site counts as the block's margin less the largest drift.
A small block keeps that bound local: fewer voxels are searched again."""


_OUTWARD = 2.0 ** -22
"""Relative widening of a bound stored as float32 (whose rounding is at most 2 ** -24)."""


@njit(cache=True)
def _up(x):
    """x widened upwards, so that its float32 rounding is still >= x."""
    if x == np.inf:
        return x
    return x + abs(x) * _OUTWARD + 1e-30


@njit(cache=True)
def _down(x):
    """x widened downwards, so that its float32 rounding is still <= x."""
    if x == np.inf:
        return x
    return x - abs(x) * _OUTWARD - 1e-30


@njit(cache=True)
def _nearest_many_3d(points, sites):
    """Index of the nearest site of each point (ties to the lower index); coordinates >= 0."""
    ext = np.empty(3)
    for a in range(3):
        ext[a] = sites[:, a].max()
        if points.shape[0]:
            ext[a] = max(ext[a], points[:, a].max())
    h, gx, gy, gz, start, items, coords = _site_grid_3d(sites, ext[0], ext[1], ext[2])
    out = np.empty(points.shape[0], np.int64)
    for i in range(points.shape[0]):
        out[i] = _three_nearest_3d(points[i, 0], points[i, 1], points[i, 2], h, gx, gy, gz,
                                   start, items, coords)[0]
    return out


@njit(cache=True)
def _site_grid_3d(sites, width, height, depth):
    """Bucket the sites into a uniform grid of cubic cells, about one site per cell.

    Returns the cell size, the grid's shape, each cell's first slot (``start``), each
    slot's site (``items``: ascending within a cell) and each slot's coordinates
    (``coords``): a cell's sites, and a row of cells', lie side by side in memory."""
    n = sites.shape[0]
    tiny = 1e-12 * max(max(width, height), max(depth, 1e-300))
    h = max(np.cbrt(max(width, tiny) * max(height, tiny) * max(depth, tiny) / n), 1e-300)
    while (int(width / h) + 1) * (int(height / h) + 1) * (int(depth / h) + 1) > 4 * n + 64:
        h *= 1.25  # a flat or thin box: keep the cell count near the site count
    gx = int(width / h) + 1
    gy = int(height / h) + 1
    gz = int(depth / h) + 1
    cell = np.empty(n, np.int64)
    for k in range(n):
        cx = min(max(int(sites[k, 0] / h), 0), gx - 1)
        cy = min(max(int(sites[k, 1] / h), 0), gy - 1)
        cz = min(max(int(sites[k, 2] / h), 0), gz - 1)
        cell[k] = (cz * gy + cy) * gx + cx
    nc = gx * gy * gz
    start = np.zeros(nc + 1, np.int64)
    for k in range(n):
        start[cell[k] + 1] += 1
    for c in range(nc):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    items = np.empty(n, np.int64)
    for k in range(n):  # ascending k within each cell
        items[fill[cell[k]]] = k
        fill[cell[k]] += 1
    coords = np.empty((n, 3))
    for t in range(n):
        for a in range(3):
            coords[t, a] = sites[items[t], a]
    return h, gx, gy, gz, start, items, coords


@njit(cache=True)
def _three_nearest_3d(x, y, z, h, gx, gy, gz, start, items, coords):
    """Nearest and second-nearest site of (x, y, z), their distances, and the distance of
    the third nearest (inf if there are only two sites), exactly.

    Ties go to the lower site index. Cells are visited in cubic shells around the point's
    cell until the shell's inner distance exceeds the third-best distance. A row of a
    shell's cells is one run of :func:`_site_grid_3d`'s slots, its sites side by side, so
    the search reads memory in order instead of through the site index.
    """
    cx = min(max(int(x / h), 0), gx - 1)
    cy = min(max(int(y / h), 0), gy - 1)
    cz = min(max(int(z / h), 0), gz - 1)
    best = (np.inf, -1, np.inf, -1, np.inf, -1)
    r = 0
    while True:
        for zz in range(max(cz - r, 0), min(cz + r, gz - 1) + 1):
            z_edge = zz == cz - r or zz == cz + r
            for yy in range(max(cy - r, 0), min(cy + r, gy - 1) + 1):
                row = (zz * gy + yy) * gx
                if z_edge or yy == cy - r or yy == cy + r:  # the block's whole row
                    best = _scan(x, y, z, coords, items, start[row + max(cx - r, 0)],
                                 start[row + min(cx + r, gx - 1) + 1], best)
                else:  # inside the shell: its two end cells
                    if cx - r >= 0:
                        best = _scan(x, y, z, coords, items, start[row + cx - r],
                                     start[row + cx - r + 1], best)
                    if r > 0 and cx + r < gx:
                        best = _scan(x, y, z, coords, items, start[row + cx + r],
                                     start[row + cx + r + 1], best)
        m = min(_block_margin(x, cx, r, h, gx), _block_margin(y, cy, r, h, gy),
                _block_margin(z, cz, r, h, gz))
        if m == np.inf or (best[5] >= 0 and m > 0 and m * m >= best[4]):
            break
        r += 1
    return best[1], np.sqrt(best[0]), best[3], np.sqrt(best[2]), np.sqrt(best[4])


@njit(cache=True, inline="always")
def _scan(x, y, z, coords, items, lo, hi, best):
    """The three best (squared distance, site) after slots lo..hi-1 (ties: lower site)."""
    b1, i1, b2, i2, b3, i3 = best
    for t in range(lo, hi):
        dx = coords[t, 0] - x
        dy = coords[t, 1] - y
        dz = coords[t, 2] - z
        d = dx * dx + dy * dy + dz * dz
        if d > b3:
            continue
        k = items[t]
        if d < b1 or (d == b1 and k < i1):
            b3, i3 = b2, i2
            b2, i2 = b1, i1
            b1, i1 = d, k
        elif d < b2 or (d == b2 and k < i2):
            b3, i3 = b2, i2
            b2, i2 = d, k
        elif d < b3 or (d == b3 and k < i3):
            b3, i3 = d, k
    return b1, i1, b2, i2, b3, i3


_SUM_SLABS = 4
"""z-slabs of :func:`_region_sums_3d`, summed apart (in parallel) and then in order: a
fixed count, so the sums do not depend on the thread count."""


@njit(cache=True, parallel=True)
def _region_sums_3d(labels, w, n, nz, ny, nx, sx, sy, sz, centre):
    """Per region: weight W, weighted sums of (p - centre) and Q = sum w |p - centre|^2."""
    part = np.zeros((_SUM_SLABS, 5, n))
    for b in prange(_SUM_SLABS):
        sums = part[b]
        for k in range(b * nz // _SUM_SLABS, (b + 1) * nz // _SUM_SLABS):
            dz = k * sz - centre[2]
            for j in range(ny):
                dy = j * sy - centre[1]
                for i in range(nx):
                    v = (k * ny + j) * nx + i
                    r = labels[v]
                    wi = w[v]
                    dx = i * sx - centre[0]
                    sums[0, r] += wi
                    sums[1, r] += wi * dx
                    sums[2, r] += wi * dy
                    sums[3, r] += wi * dz
                    sums[4, r] += wi * (dx * dx + dy * dy + dz * dz)
    out = part[0].copy()
    for b in range(1, _SUM_SLABS):
        out += part[b]
    return out


@njit(cache=True)
def _own_feature_sums_3d(idx, coords, voxel_feature, labels, w, site_feature, n):
    """Per region, over the voxels ``idx`` (of box faces and edges) of its own site's
    feature only (``voxel_feature`` each voxel's feature, ``site_feature`` each site's, -1
    for none; all zero: every region over one feature): the weight and the weighted sums
    of the coordinates ``coords``, summed in voxel order (as np.bincount sums)."""
    sums = np.zeros((4, n))
    for t in range(idx.shape[0]):
        v = idx[t]
        r = labels[v]
        if site_feature[r] != voxel_feature[t]:
            continue
        wi = w[v]
        sums[0, r] += wi
        sums[1, r] += wi * coords[t, 0]
        sums[2, r] += wi * coords[t, 1]
        sums[3, r] += wi * coords[t, 2]
    return sums


@njit(cache=True)
def _local_drift_3d(old_sites, drift, h, gx, gy, gz, reach):
    """Per grid cell: the largest drift among the sites that started within `reach` cells
    of it (Chebyshev): the cells' own largest drifts, then a running maximum along x, y
    and z in turn (a maximum over a box is one over each axis in turn)."""
    nc = gx * gy * gz
    top = np.zeros(nc)
    for k in range(old_sites.shape[0]):
        cx = min(max(int(old_sites[k, 0] / h), 0), gx - 1)
        cy = min(max(int(old_sites[k, 1] / h), 0), gy - 1)
        cz = min(max(int(old_sites[k, 2] / h), 0), gz - 1)
        c = (cz * gy + cy) * gx + cx
        top[c] = max(top[c], drift[k])
    out = np.zeros(nc)
    _running_max(top, out, 1, gx, reach)
    _running_max(out, top, gx, gy, reach)
    _running_max(top, out, gx * gy, gz, reach)
    return out


@njit(cache=True)
def _running_max(src, dst, stride, size, reach):
    """dst[c]: the largest src within ``reach`` cells of c along the axis whose cells are
    ``stride`` apart in the flat grid and ``size`` long."""
    for c in range(src.shape[0]):
        a = (c // stride) % size
        m = 0.0
        for t in range(max(a - reach, 0), min(a + reach + 1, size)):
            m = max(m, src[c + (t - a) * stride])
        dst[c] = m


@njit(cache=True)
def _reach_margin_3d(size, s, h, g, reach):
    """:func:`_block_margin` and the grid cell of every voxel coordinate along one axis."""
    out = np.empty(size)
    cell = np.empty(size, np.int64)
    for i in range(size):
        cell[i] = min(int(i * s / h), g - 1)
        out[i] = _block_margin(i * s, cell[i], reach, h, g)
    return out, cell


@njit(cache=True, parallel=True)
def _reassign_3d(nz, ny, nx, sx, sy, sz, old_sites, sites, drift, labels, second, u, l2, l3):
    """Bounds after the sites moved by `drift`: re-find only voxels whose bounds fail.

    Per voxel: its nearest site (labels) with u >= its distance, a second site (second)
    with l2 <= its distance, and l3 <= the distance of every other site. u grows by the own
    site's drift, l2 shrinks by the second's. A site that started within _REACH grid cells
    of the voxel's cell came at most the largest drift among those sites closer; one
    within _REACH2 cells (but not _REACH) was at least max(l3, the inner block's margin)
    away and came at most the largest drift of those; any other was at least max(l3, the
    outer block's margin) away and came at most the largest drift overall: l3 becomes the
    smallest of the three. Stored bounds are rounded outwards (float32). Where
    u >= min(l2, l3), the two sites' distances are computed: if the nearer of them is
    nearer than l3 it is the nearest (the two may swap: a voxel near the bisector of its
    two nearest sites needs no search); else the voxel is searched again. Equality
    counts as a failed bound, so that an exact tie always goes to the lower site index,
    as a search would give it. Slices run in parallel (a voxel's update reads and writes
    only its own state). Returns the number of voxels searched.
    """
    h, gx, gy, gz, start, items, coords = _site_grid_3d(sites, (nx - 1) * sx, (ny - 1) * sy,
                                                        (nz - 1) * sz)
    b1 = _local_drift_3d(old_sites, drift, h, gx, gy, gz, _REACH)
    b2 = _local_drift_3d(old_sites, drift, h, gx, gy, gz, _REACH2)
    far = drift.max()
    mx, cell_x = _reach_margin_3d(nx, sx, h, gx, _REACH)
    my, cell_y = _reach_margin_3d(ny, sy, h, gy, _REACH)
    mz, cell_z = _reach_margin_3d(nz, sz, h, gz, _REACH)
    mx2 = _reach_margin_3d(nx, sx, h, gx, _REACH2)[0]
    my2 = _reach_margin_3d(ny, sy, h, gy, _REACH2)[0]
    mz2 = _reach_margin_3d(nz, sz, h, gz, _REACH2)[0]
    searched = 0
    for k in prange(nz):
        z = k * sz
        for j in range(ny):
            y = j * sy
            row_cell = (cell_z[k] * gy + cell_y[j]) * gx
            myz = min(my[j], mz[k])
            myz2 = min(my2[j], mz2[k])
            for i in range(nx):
                v = (k * ny + j) * nx + i
                c = row_cell + cell_x[i]
                s1 = labels[v]
                s2 = second[v]
                ui = u[v] + drift[s1]
                li2 = l2[v] - drift[s2]
                # the other sites: near ones by l3 and their drift, a ring farther by the
                # inner block's margin and the ring's drift, the rest by the outer margin
                old3 = l3[v]
                li3 = min(old3 - b1[c], min(max(old3, min(mx[i], myz)) - b2[c],
                                            max(old3, min(mx2[i], myz2)) - far))
                if ui >= li2 or ui >= li3:  # equality: a tie, which the lower index wins
                    x = i * sx
                    ui = _dist(sites, s1, x, y, z)
                    li2 = _dist(sites, s2, x, y, z)
                    if li2 < ui or (li2 == ui and s2 < s1):
                        s1, s2 = s2, s1
                        ui, li2 = li2, ui
                    if ui >= li3:
                        s1, ui, s2, li2, li3 = _three_nearest_3d(x, y, z, h, gx, gy, gz,
                                                                 start, items, coords)
                        searched += 1
                    labels[v] = s1
                    second[v] = s2
                u[v] = _up(ui)
                l2[v] = _down(li2)
                l3[v] = _down(li3)
    return searched


@njit(cache=True)
def _dist(sites, k, x, y, z):
    dx = sites[k, 0] - x
    dy = sites[k, 1] - y
    dz = sites[k, 2] - z
    return np.sqrt(dx * dx + dy * dy + dz * dz)
