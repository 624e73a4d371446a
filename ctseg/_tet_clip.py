"""Compiled kernels (numba) of the exact tetrahedron/voxel overlaps (SPEC 9.5).

The cells of one voxel row (fixed j and k, i running along x) share out a tetrahedron T
by the divergence theorem with the field ``(x - c, 0, 0)``, whose divergence is 1: the
volume of T's piece in the row's prism ``|y - j| <= 1/2, |z - k| <= 1/2`` below the plane
``x = c`` is the integral of ``(x - c) n_x`` over the boundary of that piece. The prism's
sides have ``n_x = 0`` and the cap on the plane has ``x - c = 0``, so only T's own faces
count, clipped to the prism and to ``x <= c``. Each face is clipped to the slab of k,
then to the row of j (convex polygons, one plane at a time), and cell i of the row gets
``V(i + 1/2) - V(i - 1/2)``; a face wholly below a plane adds its integral, kept from the
row's clipping (a fan of triangles), a face wholly above adds nothing. No polyhedron is
ever built, and no buffer can overflow: one clip makes at most 2n vertices of n (a
crossing and a kept vertex per edge), even where rounding leaves a polygon slightly
non-convex, and the buffers hold that bound after each clip.

Only the cells a tetrahedron reaches are visited: the slabs of its own extent in z, the
rows of each slab's clipped faces' extent in y, the cells of each row's extent in x, all
as ``floor(lo + 1/2)`` to ``ceil(hi - 1/2)``, so a plane a face only touches opens no
cell. A cell whose difference is not positive (a touch, or rounding on a piece of some
1e-17 voxels) is left out. The volumes are exact up to rounding: a tetrahedron's
overlaps sum to its volume and the overlaps of a voxel to its share of the box to about
1e-15 relative.

Private: :mod:`ctseg.tetra_gray` is the entry point.
"""
import numpy as np
from numba import njit

# outward faces (counter-clockwise seen from outside) of a positively oriented
# tetrahedron (0, 1, 2, 3)
_FACES = ((0, 2, 1), (0, 3, 2), (0, 1, 3), (1, 2, 3))
# vertices a face's polygon may have after its z clips (slab), its y clips (row) and its x
# clip (the scratch buffer, also the first clip's target of each pair): 3 x 2^clips
_MAX_SLAB = 12
_MAX_ROW = 48
_MAX_TMP = 96


@njit(cache=True)
def _cell_range(lo, hi, size):
    """Cells [a, b] that the extent [lo, hi] reaches along an axis of ``size`` cells (cell
    i spans i -/+ 1/2)."""
    a = min(max(int(np.floor(lo + 0.5)), 0), size - 1)
    b = min(max(int(np.ceil(hi - 0.5)), 0), size - 1)
    return a, b


@njit(cache=True)
def _clip(src, n, dst, axis, c, below):
    """Polygon ``src[:n]`` clipped to ``x_axis <= c`` (``below``) or ``>= c``, into
    ``dst``; returns its vertex count. New vertices get ``x_axis = c`` exactly."""
    if n == 0:
        return 0
    m = 0
    p = n - 1
    sp = src[p, axis] - c
    pin = sp <= 0.0 if below else sp >= 0.0
    for i in range(n):
        sq = src[i, axis] - c
        qin = sq <= 0.0 if below else sq >= 0.0
        if pin != qin:
            w = sp / (sp - sq)
            for d in range(3):
                dst[m, d] = src[p, d] + w * (src[i, d] - src[p, d])
            dst[m, axis] = c
            m += 1
        if qin:
            for d in range(3):
                dst[m, d] = src[i, d]
            m += 1
        p = i
        sp = sq
        pin = qin
    return m


@njit(cache=True)
def _moments(poly, n, c):
    """``(integral of n_x dA, integral of (x - c) n_x dA)`` over polygon ``poly[:n]``
    (a fan from its first vertex; n_x dA is the x part of the oriented area)."""
    area = 0.0
    moment = 0.0
    ay, az, ax = poly[0, 1], poly[0, 2], poly[0, 0] - c
    for i in range(1, n - 1):
        t = 0.5 * ((poly[i, 1] - ay) * (poly[i + 1, 2] - az)
                   - (poly[i, 2] - az) * (poly[i + 1, 1] - ay))
        area += t
        moment += t * (ax + poly[i, 0] - c + poly[i + 1, 0] - c)
    return area, moment / 3.0


@njit(cache=True)
def _below(rows, rn, nf, area, moment, xlo, xhi, c, tmp):
    """Volume of the row's piece of the tetrahedron below the plane ``x = c``, from the
    row's ``nf`` clipped faces (``moment`` their integrals of ``x n_x dA``)."""
    v = 0.0
    for f in range(nf):
        if xlo[f] >= c:
            continue
        if xhi[f] <= c:
            v += moment[f] - c * area[f]
            continue
        m = _clip(rows[f], rn[f], tmp, 0, c, True)
        if m >= 3:
            v += _moments(tmp, m, c)[1]
    return v


@njit(cache=True)
def _tet_cells(corners, nz, ny, nx, cells, vols, work):
    """Every (flat voxel index, overlap volume) of one tetrahedron, in index units.

    ``corners`` (4, 3) lie inside the box; ``cells`` and ``vols`` hold at least as many
    entries as the tetrahedron's range of cells (:func:`_span`); ``work`` is
    :func:`_work`'s. Returns the number written.
    """
    tri, slab, rows, tmp, sn, rn, area, moment, xlo, xhi, loc, fylo, fyhi = work
    # local origin: an integer corner, so that the planes stay exact and the volumes are
    # formed from small numbers
    o0 = int(np.floor(min(corners[0, 0], corners[1, 0], corners[2, 0], corners[3, 0])))
    o1 = int(np.floor(min(corners[0, 1], corners[1, 1], corners[2, 1], corners[3, 1])))
    o2 = int(np.floor(min(corners[0, 2], corners[1, 2], corners[2, 2], corners[3, 2])))
    for v in range(4):
        loc[v, 0] = corners[v, 0] - o0
        loc[v, 1] = corners[v, 1] - o1
        loc[v, 2] = corners[v, 2] - o2
    z0, z1 = _cell_range(min(loc[0, 2], loc[1, 2], loc[2, 2], loc[3, 2]),
                         max(loc[0, 2], loc[1, 2], loc[2, 2], loc[3, 2]), nz - o2)
    y0, y1 = _cell_range(min(loc[0, 1], loc[1, 1], loc[2, 1], loc[3, 1]),
                         max(loc[0, 1], loc[1, 1], loc[2, 1], loc[3, 1]), ny - o1)
    x0, x1 = _cell_range(min(loc[0, 0], loc[1, 0], loc[2, 0], loc[3, 0]),
                         max(loc[0, 0], loc[1, 0], loc[2, 0], loc[3, 0]), nx - o0)
    a0, a1, a2 = loc[1, 0] - loc[0, 0], loc[1, 1] - loc[0, 1], loc[1, 2] - loc[0, 2]
    b0, b1, b2 = loc[2, 0] - loc[0, 0], loc[2, 1] - loc[0, 1], loc[2, 2] - loc[0, 2]
    c0, c1, c2 = loc[3, 0] - loc[0, 0], loc[3, 1] - loc[0, 1], loc[3, 2] - loc[0, 2]
    det = a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0)
    if det == 0.0:
        return 0
    if z0 == z1 and y0 == y1 and x0 == x1:  # inside one cell
        cells[0] = ((z0 + o2) * ny + y0 + o1) * nx + x0 + o0
        vols[0] = abs(det) / 6.0
        return 1
    for f in range(4):  # the faces, outward (vertices 1 and 2 swapped if negative)
        for q in range(3):
            v = _FACES[f][q]
            if det < 0.0 and (v == 1 or v == 2):
                v = 3 - v
            for d in range(3):
                tri[f, q, d] = loc[v, d]
    count = 0
    for k in range(z0, z1 + 1):
        ylo = np.inf
        yhi = -np.inf
        for f in range(4):
            m = _clip(tri[f], 3, tmp, 2, k - 0.5, False)
            sn[f] = _clip(tmp, m, slab[f], 2, k + 0.5, True)
            fylo[f] = np.inf
            fyhi[f] = -np.inf
            for q in range(sn[f]):
                fylo[f] = min(fylo[f], slab[f, q, 1])
                fyhi[f] = max(fyhi[f], slab[f, q, 1])
            ylo = min(ylo, fylo[f])
            yhi = max(yhi, fyhi[f])
        if ylo > yhi:
            continue
        j0, j1 = _cell_range(ylo, yhi, ny - o1)
        for j in range(j0, j1 + 1):
            nf = 0
            lo = np.inf
            hi = -np.inf
            for f in range(4):
                if fyhi[f] <= j - 0.5 or fylo[f] >= j + 0.5:
                    continue  # misses the row, or only touches it
                m = _clip(slab[f], sn[f], tmp, 1, j - 0.5, False)
                m = _clip(tmp, m, rows[nf], 1, j + 0.5, True)
                if m < 3:
                    continue
                fl = rows[nf, 0, 0]
                fh = fl
                for q in range(1, m):
                    fl = min(fl, rows[nf, q, 0])
                    fh = max(fh, rows[nf, q, 0])
                lo = min(lo, fl)
                hi = max(hi, fh)
                area[nf], moment[nf] = _moments(rows[nf], m, 0.0)
                if area[nf] == 0.0:
                    continue  # parallel to x (or flat): no share of any volume
                rn[nf] = m
                xlo[nf] = fl
                xhi[nf] = fh
                nf += 1
            if nf == 0:
                continue
            i0, i1 = _cell_range(lo, hi, nx - o0)
            base = ((k + o2) * ny + j + o1) * nx + o0
            before = 0.0
            for i in range(i0, i1 + 1):
                if i < i1:
                    below = _below(rows, rn, nf, area, moment, xlo, xhi, i + 0.5, tmp)
                else:  # the whole row piece
                    below = 0.0
                    for f in range(nf):
                        below += moment[f] - (i + 0.5) * area[f]
                vol = below - before
                before = below
                if vol > 0.0:
                    cells[count] = base + i
                    vols[count] = vol
                    count += 1
    return count


@njit(cache=True)
def _work():
    """The work buffers of :func:`_tet_cells`."""
    return (np.empty((4, 3, 3)), np.empty((4, _MAX_SLAB, 3)), np.empty((4, _MAX_ROW, 3)),
            np.empty((_MAX_TMP, 3)), np.empty(4, np.int64), np.empty(4, np.int64), np.empty(4),
            np.empty(4), np.empty(4), np.empty(4), np.empty((4, 3)), np.empty(4), np.empty(4))


@njit(cache=True)
def _span(corners):
    """Upper bound of the cells a tetrahedron (4, 3) reaches: its cell range's box."""
    span = 1
    for d in range(3):
        lo = min(corners[0, d], corners[1, d], corners[2, d], corners[3, d])
        hi = max(corners[0, d], corners[1, d], corners[2, d], corners[3, d])
        span *= int(np.ceil(hi - 0.5)) - int(np.floor(lo + 0.5)) + 2
    return span


@njit(cache=True)
def _cells_of(corners, nz, ny, nx, cells, vols, work):
    """:func:`_tet_cells` of one tetrahedron, the cell lists grown first where its range
    of cells might not fit: (cells, vols, count)."""
    span = _span(corners)
    if span > cells.shape[0]:
        cells = np.empty(2 * span, np.int64)
        vols = np.empty(2 * span)
    return cells, vols, _tet_cells(corners, nz, ny, nx, cells, vols, work)


@njit(cache=True)
def _overlaps(P, nz, ny, nx, img, values, tet_vol, tet_w, vox_vol, vox_w):
    """Visit every (tetrahedron, voxel) overlap of positive volume, without keeping them.

    ``P`` (m, 4, 3): the corners in index units, inside the box. With an image
    (``img.size > 0``, flat): add each overlap's volume to ``tet_vol`` and volume x gray
    to ``tet_w`` (per tetrahedron). With per-tetrahedron ``values``: add each overlap's
    volume to ``vox_vol`` and volume x value to ``vox_w`` (per flat voxel). Returns the
    number of overlaps.
    """
    m = P.shape[0]
    work = _work()
    cells = np.empty(64, np.int64)
    vols = np.empty(64)
    count = 0
    for t in range(m):
        cells, vols, n = _cells_of(P[t], nz, ny, nx, cells, vols, work)
        for q in range(n):
            c = cells[q]
            a = vols[q]
            if img.shape[0] > 0:
                tet_vol[t] += a
                tet_w[t] += a * img[c]
            if values.shape[0] > 0:
                vox_vol[c] += a
                vox_w[c] += a * values[t]
        count += n
    return count


@njit(cache=True, nogil=True)
def _record(P, nz, ny, nx, t0, start, voxel, overlap):
    """Write the overlaps of tetrahedra ``t0, t0 + 1, ...`` into compressed rows: those of
    tetrahedron t at ``start[t]:start[t + 1]`` of ``voxel`` (flat voxel index) and
    ``overlap`` (volume), ``start[t0]`` set on entry.

    Returns the next tetrahedron to do: ``m`` when all are done, less when ``voxel`` is
    full (call again from there with larger buffers).
    """
    m = P.shape[0]
    work = _work()
    cells = np.empty(64, np.int64)
    vols = np.empty(64)
    count = start[t0]
    for t in range(t0, m):
        cells, vols, n = _cells_of(P[t], nz, ny, nx, cells, vols, work)
        if count + n > voxel.shape[0]:
            return t
        for q in range(n):
            voxel[count + q] = cells[q]
            overlap[count + q] = vols[q]
        count += n
        start[t + 1] = count
    return m
