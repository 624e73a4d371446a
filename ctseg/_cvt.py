"""Compiled kernels (numba) of :mod:`ctseg.cvt`: the exact nearest-site search on a site
grid, the pixel assignment with Hamerly's bounds, and the per-region sums.

Private: :func:`ctseg.lloyd_cvt` is the entry point.
"""
import numpy as np
from numba import njit, prange

# Profiling showed Lloyd's per-iteration pixel passes (bound updates, KD-tree re-queries,
# region sums) at 3.0 of 5.0 s for 512 x 512 / 1000 sites in numpy; one fused pass per
# iteration does the same work exactly.

_REACH = 2  # cells: sites farther than this cannot come near a pixel within one iteration
_ROWS = 16  # rows per block of the parallel kernels: many blocks per thread even out the load



@njit(cache=True)
def _nearest_many(points, sites):
    """Index of the nearest site of each point (ties to the lower index); coordinates >= 0."""
    width = max(points[:, 0].max(), sites[:, 0].max()) if points.shape[0] else sites[:, 0].max()
    height = max(points[:, 1].max(), sites[:, 1].max()) if points.shape[0] else sites[:, 1].max()
    h, gx, gy, start, items = _site_grid(sites, width, height)
    out = np.empty(points.shape[0], np.int64)
    for i in range(points.shape[0]):
        out[i] = _two_nearest(points[i, 0], points[i, 1], sites, h, gx, gy, start, items)[0]
    return out


@njit(cache=True)
def _site_grid(sites, width, height):
    """Bucket the sites into a uniform grid of about one site per cell."""
    n = sites.shape[0]
    h = max(np.sqrt(max(width, 1.0) * max(height, 1.0) / n), 1e-9)
    gx = int(width / h) + 1
    gy = int(height / h) + 1
    cell = np.empty(n, np.int64)
    for k in range(n):
        cx = min(max(int(sites[k, 0] / h), 0), gx - 1)
        cy = min(max(int(sites[k, 1] / h), 0), gy - 1)
        cell[k] = cy * gx + cx
    start = np.zeros(gx * gy + 1, np.int64)
    for k in range(n):
        start[cell[k] + 1] += 1
    for c in range(gx * gy):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    items = np.empty(n, np.int64)
    for k in range(n):  # ascending k within each cell
        items[fill[cell[k]]] = k
        fill[cell[k]] += 1
    return h, gx, gy, start, items


@njit(cache=True)
def _two_nearest(x, y, sites, h, gx, gy, start, items):
    """Nearest and second-nearest site of (x, y) and their distances, exactly.

    Ties go to the lower site index, so the answer does not depend on the visiting order.
    Cells are visited in square rings around the point's cell until the ring's inner
    distance exceeds the second-best distance.
    """
    cx = min(max(int(x / h), 0), gx - 1)
    cy = min(max(int(y / h), 0), gy - 1)
    b1 = np.inf
    b2 = np.inf
    i1 = -1
    i2 = -1
    r = 0
    while True:
        for yy in range(cy - r, cy + r + 1):
            if yy < 0 or yy >= gy:
                continue
            edge_row = yy == cy - r or yy == cy + r
            step = 1 if edge_row else 2 * r
            xx = cx - r
            while xx <= cx + r:
                if 0 <= xx < gx:
                    c = yy * gx + xx
                    for t in range(start[c], start[c + 1]):
                        k = items[t]
                        dx = sites[k, 0] - x
                        dy = sites[k, 1] - y
                        d = dx * dx + dy * dy
                        if d < b1 or (d == b1 and k < i1):
                            b2 = b1
                            i2 = i1
                            b1 = d
                            i1 = k
                        elif d < b2 or (d == b2 and k < i2):
                            b2 = d
                            i2 = k
                xx += step
        # distance from the point to the cells not yet visited
        mx = _block_margin(x, cx, r, h, gx)
        my = _block_margin(y, cy, r, h, gy)
        m = min(mx, my)
        if m == np.inf or (i2 >= 0 and m > 0 and m * m >= b2):
            break
        r += 1
    return i1, np.sqrt(b1), i2, np.sqrt(b2)


@njit(cache=True)
def _assign_rows(y0, y1, cols, sites, h, gx, gy, start, items, labels, u, l):
    """Exact nearest (labels, u) and second-nearest distance (l) of the pixel centres of
    rows y0 <= y < y1."""
    for i in range(y0 * cols, y1 * cols):
        y, x = divmod(i, cols)
        i1, d1, _, d2 = _two_nearest(float(x), float(y), sites, h, gx, gy, start, items)
        labels[i] = i1
        u[i] = d1
        l[i] = d2


@njit(cache=True)
def _assign(rows, cols, sites, labels, u, l):
    """:func:`_assign_rows` of every row."""
    h, gx, gy, start, items = _site_grid(sites, cols - 1.0, rows - 1.0)
    _assign_rows(0, rows, cols, sites, h, gx, gy, start, items, labels, u, l)


@njit(cache=True, parallel=True)
def _assign_parallel(rows, cols, sites, labels, u, l):
    """:func:`_assign`, blocks of rows in parallel (each pixel's result is its own)."""
    h, gx, gy, start, items = _site_grid(sites, cols - 1.0, rows - 1.0)
    for b in prange((rows + _ROWS - 1) // _ROWS):
        _assign_rows(b * _ROWS, min((b + 1) * _ROWS, rows), cols, sites, h, gx, gy, start,
                     items, labels, u, l)


@njit(cache=True)
def _region_sums(labels, w, n, rows, cols, cx, cy):
    """Per region: weight W, weighted coordinate sums Sx, Sy, and Q = sum w |p - centre|^2."""
    sums = np.zeros((4, n))
    for y in range(rows):
        dy = y - cy
        for x in range(cols):
            i = y * cols + x
            k = labels[i]
            wi = w[i]
            sums[0, k] += wi
            sums[1, k] += wi * x
            sums[2, k] += wi * y
            dx = x - cx
            sums[3, k] += wi * (dx * dx + dy * dy)
    return sums


@njit(cache=True)
def _local_drift(old_sites, drift, h, gx, gy, reach):
    """Per grid cell: the largest drift, its site, and the second largest drift among the
    sites that started within `reach` cells of it (Chebyshev)."""
    top1 = np.zeros(gx * gy)
    top1_site = np.full(gx * gy, -1)
    top2 = np.zeros(gx * gy)
    for k in range(old_sites.shape[0]):
        cx = min(max(int(old_sites[k, 0] / h), 0), gx - 1)
        cy = min(max(int(old_sites[k, 1] / h), 0), gy - 1)
        c = cy * gx + cx
        if drift[k] > top1[c]:
            top2[c] = top1[c]
            top1[c] = drift[k]
            top1_site[c] = k
        elif drift[k] > top2[c]:
            top2[c] = drift[k]
    b1 = np.zeros(gx * gy)
    b1_site = np.full(gx * gy, -1)
    b2 = np.zeros(gx * gy)
    for cy in range(gy):
        for cx in range(gx):
            m1 = 0.0
            s1 = -1
            m2 = 0.0
            for yy in range(max(cy - reach, 0), min(cy + reach + 1, gy)):
                for xx in range(max(cx - reach, 0), min(cx + reach + 1, gx)):
                    c = yy * gx + xx
                    if top1[c] > m1:
                        m2 = max(m1, top2[c])
                        m1 = top1[c]
                        s1 = top1_site[c]
                    else:
                        m2 = max(m2, top1[c])
            b1[cy * gx + cx] = m1
            b1_site[cy * gx + cx] = s1
            b2[cy * gx + cx] = m2
    return b1, b1_site, b2


@njit(cache=True)
def _block_margin(v, c, reach, h, g):
    """Along one axis: distance from coordinate v (in cell c) to the edge of the block of
    cells within `reach` of c, on the sides where the grid goes on (inf where it does not)."""
    m = np.inf
    if c - reach > 0:
        m = min(m, v - (c - reach) * h)
    if c + reach < g - 1:
        m = min(m, (c + reach + 1) * h - v)
    return m


@njit(cache=True)
def _reach_margin(size, h, g, reach):
    """:func:`_block_margin` of every pixel coordinate 0..size-1 along one axis."""
    out = np.empty(size)
    for x in range(size):
        out[x] = _block_margin(x, min(int(x / h), g - 1), reach, h, g)
    return out


@njit(cache=True)
def _reassign_setup(rows, cols, old_sites, sites, drift):
    """The site grid, the local drift bounds and the block margins :func:`_reassign_rows`
    reads."""
    h, gx, gy, start, items = _site_grid(sites, cols - 1.0, rows - 1.0)
    b1, b1_site, b2 = _local_drift(old_sites, drift, h, gx, gy, _REACH)
    mx = _reach_margin(cols, h, gx, _REACH)
    my = _reach_margin(rows, h, gy, _REACH)
    cell_x = np.empty(cols, np.int64)
    for x in range(cols):
        cell_x[x] = min(int(x / h), gx - 1)
    return h, gx, gy, start, items, b1, b1_site, b2, drift.max(), mx, my, cell_x


@njit(cache=True)
def _reassign_rows(y0, y1, cols, sites, drift, labels, u, l, setup):
    """Hamerly's step after the sites moved by `drift`, on rows y0 <= y < y1: re-find
    only pixels whose bounds fail.

    u >= distance to the own site, l <= distance to any other site. A site that started
    within _REACH grid cells of the pixel's cell came at most the largest drift among
    those sites closer (the second largest if the largest is the pixel's own site); any
    other site is at least the block's margin minus the largest drift overall away. Most
    sites stop moving long before the last ones, so these local bounds fail far less
    often than Hamerly's global one. Returns the number of pixels searched.
    """
    h, gx, gy, start, items, b1, b1_site, b2, far, mx, my, cell_x = setup
    searched = 0
    for y in range(y0, y1):
        row_cell = min(int(y / h), gy - 1) * gx
        for x in range(cols):
            i = y * cols + x
            c = row_cell + cell_x[x]
            k = labels[i]
            ui = u[i] + drift[k]
            li = min(l[i] - (b2[c] if k == b1_site[c] else b1[c]), min(mx[x], my[y]) - far)
            if ui > li:
                dx = sites[k, 0] - x
                dy = sites[k, 1] - y
                ui = np.sqrt(dx * dx + dy * dy)
                if ui > li:
                    i1, d1, _, d2 = _two_nearest(float(x), float(y), sites, h, gx, gy, start,
                                                 items)
                    labels[i] = i1
                    ui = d1
                    li = d2
                    searched += 1
            u[i] = ui
            l[i] = li
    return searched


@njit(cache=True)
def _reassign(rows, cols, old_sites, sites, drift, labels, u, l):
    """:func:`_reassign_rows` of every row."""
    setup = _reassign_setup(rows, cols, old_sites, sites, drift)
    return _reassign_rows(0, rows, cols, sites, drift, labels, u, l, setup)


@njit(cache=True, parallel=True)
def _reassign_parallel(rows, cols, old_sites, sites, drift, labels, u, l):
    """:func:`_reassign`, blocks of rows in parallel (a pixel's update reads and writes
    only its own state)."""
    setup = _reassign_setup(rows, cols, old_sites, sites, drift)
    searched = 0
    for b in prange((rows + _ROWS - 1) // _ROWS):
        searched += _reassign_rows(b * _ROWS, min((b + 1) * _ROWS, rows), cols, sites, drift,
                                   labels, u, l, setup)
    return searched
