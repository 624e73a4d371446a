"""The tetrahedron/voxel overlap kernel before the face-integral one of
:mod:`ctseg._tet_clip`, kept as benchmarks/overlap_rows.py's baseline: each tetrahedron
held as a convex polyhedron (Powell and Abel's r3d representation, J. Comput. Phys. 297,
2015) and split by every voxel plane it crosses, z, then y, then x, each cell's piece's
volume from a walk over its faces. The same overlaps up to rounding.
"""
import numpy as np
from numba import njit

# a tetrahedron cut by the 6 planes of a cell has at most 10 faces, so 2 * 10 - 4 = 16
# vertices; during a split the crossing edges (at most 3/2 * 16) add two vertices each
_MAXV = 64

# neighbours of the 4 vertices of a positively oriented tetrahedron, counter-clockwise
# seen from outside: walking a face (the next neighbour after the one we came from)
# visits the outward faces (0, 2, 1), (0, 3, 2), (0, 1, 3), (1, 2, 3)
_TET_NBRS = ((2, 3, 1), (0, 3, 2), (1, 3, 0), (0, 2, 1))


@njit(cache=False)
def _init_tet(corners, negative, pos, nb):
    """Load tetrahedron ``corners`` (4, 3) into the polyhedron buffers (vertices 1 and 2
    swapped when ``negative``ly oriented); returns 4."""
    for v in range(4):
        src = 3 - v if negative and (v == 1 or v == 2) else v
        for d in range(3):
            pos[v, d] = corners[src, d]
            nb[v, d] = _TET_NBRS[v][d]
    return 4


@njit(cache=False)
def _copy(pos, nb, n, out_pos, out_nb):
    for v in range(n):
        for d in range(3):
            out_pos[v, d] = pos[v, d]
            out_nb[v, d] = nb[v, d]
    return n


@njit(cache=False)
def _split(pos, nb, n, axis, c, bpos, bnb, side, newid):
    """Split polyhedron (pos, nb, n) by the plane ``x_axis = c``, in place.

    The part below goes to (bpos, bnb); the part above is left in (pos, nb), whose
    buffers must hold the crossing vertices while they are made. ``side`` and ``newid``
    are work buffers. Returns the vertex counts (below, above); 0 for an empty part,
    (-1, -1) if the buffers are too small.
    """
    n_above = 0
    n_below = 0
    for v in range(n):
        s = pos[v, axis] - c
        side[v] = 1 if s < 0 else 0  # 1: below
        n_above += s > 0
        n_below += s < 0
    if n_above == 0:
        return _copy(pos, nb, n, bpos, bnb), 0
    if n_below == 0:
        return 0, n
    if 4 * n > pos.shape[0]:  # n + 2 * crossing edges (at most 3 n / 2) might not fit
        crossing = 0
        for v in range(n):
            for p in range(3):
                crossing += side[v] == 0 and side[nb[v, p]] == 1
        if n + 2 * crossing > pos.shape[0]:  # cannot happen for convex pieces
            return -1, -1
    m = n
    for vcur in range(n):
        if side[vcur] == 1:
            continue
        for p in range(3):
            vnext = nb[vcur, p]
            if vnext >= n or side[vnext] == 0:
                continue
            wa = c - pos[vnext, axis]  # > 0
            wb = pos[vcur, axis] - c  # >= 0
            for d in range(3):
                x = (wa * pos[vcur, d] + wb * pos[vnext, d]) / (wa + wb)
                pos[m, d] = x
                pos[m + 1, d] = x
            pos[m, axis] = c
            pos[m + 1, axis] = c
            # m: the copy above, joined to vcur; m + 1: the copy below, joined to vnext
            nb[m, 0] = vcur
            nb[vcur, p] = m
            side[m] = 0
            nb[m + 1, 0] = vnext
            for q in range(3):
                if nb[vnext, q] == vcur:
                    nb[vnext, q] = m + 1
                    break
            side[m + 1] = 1
            m += 2
    # link the new vertices around the cap: walk the face from each to the next new one
    for vstart in range(n, m):
        vcur = vstart
        vnext = nb[vcur, 0]
        while True:
            q = 0
            while nb[vnext, q] != vcur:
                q += 1
            vcur = vnext
            vnext = nb[vcur, (q + 1) % 3]
            if vcur >= n:
                break
        nb[vstart, 2] = vcur
        nb[vcur, 1] = vstart
    nbl = 0
    nab = 0
    for v in range(m):
        if side[v] == 1:
            newid[v] = nbl
            nbl += 1
        else:
            newid[v] = nab
            nab += 1
    # the part above compacts forwards in place: vertex v moves to newid[v] <= v, a slot
    # already read
    for v in range(m):
        w = newid[v]
        if side[v] == 1:
            for d in range(3):
                bpos[w, d] = pos[v, d]
                bnb[w, d] = newid[nb[v, d]]
        else:
            for d in range(3):
                pos[w, d] = pos[v, d]
                nb[w, d] = newid[nb[v, d]]
    return nbl, nab


@njit(cache=False)
def _volume(pos, nb, n, mark):
    """Volume of the polyhedron: a triangle fan over each face (walked counter-clockwise
    seen from outside), ``det(a, b, c) / 6`` each."""
    for v in range(n):
        for d in range(3):
            mark[v, d] = False
    six = 0.0
    for vs in range(n):
        for ps in range(3):
            if mark[vs, ps]:
                continue
            mark[vs, ps] = True
            ax, ay, az = pos[vs, 0], pos[vs, 1], pos[vs, 2]
            vcur = vs
            vnext = nb[vs, ps]
            first = True
            while vnext != vs:
                q = 0
                while nb[vnext, q] != vcur:
                    q += 1
                bx, by, bz = pos[vnext, 0] - ax, pos[vnext, 1] - ay, pos[vnext, 2] - az
                vprev = vcur
                vcur = vnext
                pn = (q + 1) % 3
                mark[vcur, pn] = True
                vnext = nb[vcur, pn]
                if first:
                    first = False
                    continue
                # triangle (a, prev, cur): a . ((prev - a) x (cur - a)) / 6
                px, py, pz = pos[vprev, 0] - ax, pos[vprev, 1] - ay, pos[vprev, 2] - az
                six += ax * (py * bz - pz * by) + ay * (pz * bx - px * bz) \
                    + az * (px * by - py * bx)
    return six / 6.0


@njit(cache=False)
def _cell_range(pos, n, axis, size):
    """Cells [lo, hi] a polyhedron reaches along ``axis`` (cell i spans i -/+ 1/2);
    (0, -1) when it reaches none."""
    lo = pos[0, axis]
    hi = pos[0, axis]
    for v in range(1, n):
        lo = min(lo, pos[v, axis])
        hi = max(hi, pos[v, axis])
    a = min(max(int(np.floor(lo + 0.5)), 0), size - 1)
    b = min(max(int(np.ceil(hi - 0.5)), 0), size - 1)
    return a, b


@njit(cache=False)
def _tet_cells(corners, nz, ny, nx, cells, vols, pos_buf, nb_buf, side, newid, mark):
    """Every (flat voxel index, overlap volume) of one tetrahedron, in index units.

    ``corners`` (4, 3) lie inside the box; ``cells`` and ``vols`` hold at least as many
    entries as the tetrahedron's range of cells; ``pos_buf`` (4, _MAXV, 3) float64 and
    ``nb_buf`` (4, _MAXV, 3) int64 hold the polyhedra. Returns the number written, -1 if
    a piece outgrew the buffers.
    """
    # local origin: an integer corner, so that the planes stay exact and the volumes are
    # formed from small numbers
    o = np.empty(3, np.int64)
    for d in range(3):
        o[d] = int(np.floor(min(corners[0, d], corners[1, d], corners[2, d], corners[3, d])))
    loc = np.empty((4, 3))
    for v in range(4):
        for d in range(3):
            loc[v, d] = corners[v, d] - o[d]
    # in local coordinates: cell i spans [i - 1/2, i + 1/2], the box ends at cell n - 1 - o
    z0, z1 = _cell_range(loc, 4, 2, nz - o[2])
    y0, y1 = _cell_range(loc, 4, 1, ny - o[1])
    x0, x1 = _cell_range(loc, 4, 0, nx - o[0])
    if z0 > z1 or y0 > y1 or x0 > x1:
        return 0
    e = np.empty((3, 3))
    for v in range(3):
        for d in range(3):
            e[v, d] = loc[v + 1, d] - loc[0, d]
    det = (e[0, 0] * (e[1, 1] * e[2, 2] - e[1, 2] * e[2, 1])
           - e[0, 1] * (e[1, 0] * e[2, 2] - e[1, 2] * e[2, 0])
           + e[0, 2] * (e[1, 0] * e[2, 1] - e[1, 1] * e[2, 0]))
    if det == 0.0:
        return 0
    if z0 == z1 and y0 == y1 and x0 == x1:  # inside one cell
        cells[0] = ((z0 + o[2]) * ny + y0 + o[1]) * nx + x0 + o[0]
        vols[0] = abs(det) / 6.0
        return 1
    # the sweep, one level per axis (z, y, x): level L cuts its rest polyhedron in place at
    # its next plane, the piece below going to buffer L + 1 (level L + 1's rest; after x,
    # the cell's piece); the last piece along an axis stays where it lies, so level L's
    # rest is in one of the buffers 0..L; one call site of _split keeps the compiled code
    # small
    size = (nz - o[2], ny - o[1], nx - o[0])
    cur = np.zeros(3, np.int64)  # buffer of each level's rest
    nrest = np.zeros(3, np.int64)
    idx = np.zeros(3, np.int64)
    end = np.zeros(3, np.int64)
    nrest[0] = _init_tet(loc, det < 0.0, pos_buf[0], nb_buf[0])
    idx[0] = z0
    end[0] = z1
    level = 0
    count = 0
    while level >= 0:
        if nrest[level] == 0 or idx[level] > end[level]:
            level -= 1
            continue
        axis = 2 - level
        r = cur[level]
        if idx[level] < end[level]:
            dst = level + 1  # never a rest buffer of this level: those are 0..level
            npiece, nrest[level] = _split(pos_buf[r], nb_buf[r], nrest[level], axis,
                                          idx[level] + 0.5, pos_buf[dst], nb_buf[dst],
                                          side, newid)
            if npiece < 0:
                return -1
        else:  # the last cell along the axis: the rest is the piece, where it lies
            dst = r
            npiece = nrest[level]
            nrest[level] = 0
        idx[level] += 1
        if npiece == 0:
            continue
        if level < 2:
            level += 1
            cur[level] = dst
            nrest[level] = npiece
            idx[level], end[level] = _cell_range(pos_buf[dst], npiece, 2 - level, size[level])
            continue
        vol = _volume(pos_buf[dst], nb_buf[dst], npiece, mark)
        if vol > 0.0:
            cells[count] = ((idx[0] - 1 + o[2]) * ny + idx[1] - 1 + o[1]) * nx + idx[2] - 1 + o[0]
            vols[count] = vol
            count += 1
    return count


@njit(cache=False)
def _work():
    """The work buffers of :func:`_tet_cells` (the cell lists grow as needed)."""
    return (np.empty((4, _MAXV, 3)), np.empty((4, _MAXV, 3), np.int64), np.empty(_MAXV, np.int64),
            np.empty(_MAXV, np.int64), np.empty((_MAXV, 3), np.bool_), np.empty(64, np.int64),
            np.empty(64))


@njit(cache=False)
def _span(corners):
    """Upper bound of the cells a tetrahedron (4, 3) reaches: its cell range's box."""
    span = 1
    for d in range(3):
        lo = min(corners[0, d], corners[1, d], corners[2, d], corners[3, d])
        hi = max(corners[0, d], corners[1, d], corners[2, d], corners[3, d])
        span *= int(np.ceil(hi - 0.5)) - int(np.floor(lo + 0.5)) + 2
    return span


@njit(cache=False, nogil=True)
def _record(P, nz, ny, nx, t0, start, voxel, overlap):
    """Write the overlaps of tetrahedra ``t0, t0 + 1, ...`` into compressed rows: those of
    tetrahedron t at ``start[t]:start[t + 1]`` of ``voxel`` (flat voxel index) and
    ``overlap`` (volume), ``start[t0]`` set on entry.

    Returns the next tetrahedron to do: ``m`` when all are done, less when ``voxel`` is
    full (call again from there with larger buffers), -1 - t if tetrahedron t outgrew the
    polyhedron buffers.
    """
    m = P.shape[0]
    pos_buf, nb_buf, side, newid, mark, cells, vols = _work()
    count = start[t0]
    for t in range(t0, m):
        span = _span(P[t])
        if span > cells.shape[0]:
            cells = np.empty(2 * span, np.int64)
            vols = np.empty(2 * span)
        n = _tet_cells(P[t], nz, ny, nx, cells, vols, pos_buf, nb_buf, side, newid, mark)
        if n < 0:
            return -1 - t
        if count + n > voxel.shape[0]:
            return t
        for q in range(n):
            voxel[count + q] = cells[q]
            overlap[count + q] = vols[q]
        count += n
        start[t + 1] = count
    return m
