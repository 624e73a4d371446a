"""Compiled kernels (numba) of the exact triangle/pixel overlaps: Sutherland-Hodgman
clipping of a triangle by a pixel square, and the visit of every (triangle, pixel) overlap.

Private: :func:`ctseg.triangle_gray`, :func:`ctseg.triangle_gray.pixel_mean_of_triangles`
and :func:`ctseg.raster.pixel_overlaps` are the entry points. The sums have a threaded
kernel each (:data:`ctseg._threads.enabled`) that adds in the serial order, so both give
the same bits: per triangle, the pixels in row-major order; per pixel, the triangles in
index order.
"""
import numpy as np
from numba import njit, prange

# a triangle clipped by 4 half-planes has at most 7 vertices in exact arithmetic; one clip
# makes at most 2n of n even where rounding leaves the polygon slightly non-convex, and
# numba does not check bounds: room for 3 x 2^4
_MAXV = 48


def _corners(points, triangles):
    """(m, 3, 2) float64 corner coordinates of the triangles, C-contiguous."""
    pts = np.asarray(points, float)
    return np.ascontiguousarray(pts[np.asarray(triangles, np.int64)])  # (m, 3, 2)


_BAND_ROWS = 8  # rows per band of the threaded per-pixel sums: many bands per thread
_TRIANGLE_BLOCK = 64  # triangles per task of the threaded per-triangle sums (one scratch each)


# Compiled (numba): the vectorised clipping cost 1.2 of 5.0 s end to end at 512 x 512 /
# 1000 sites, mostly sorting and gathering fixed-size vertex arrays.
@njit(cache=True)
def _clip_area(P, x0, x1, y0, y1, buf):
    """Area of triangle P (3, 2) inside the box [x0, x1] x [y0, y1] (Sutherland-Hodgman);
    ``buf`` is (4, _MAXV) scratch, passed in because an allocation per cut pixel cost more
    than the clipping."""
    ax = buf[0]
    ay = buf[1]
    bx = buf[2]
    by = buf[3]
    for v in range(3):
        ax[v] = P[v, 0]
        ay[v] = P[v, 1]
    n = 3
    for side in range(4):
        axis = side // 2  # 0: x, 1: y
        bound = (x0, x1, y0, y1)[side]
        sgn = 1.0 if side % 2 == 0 else -1.0  # keep coord >= bound, then <= bound
        m = 0
        for v in range(n):
            w = (v + 1) % n
            pc = ax[v] if axis == 0 else ay[v]
            pn = ax[w] if axis == 0 else ay[w]
            sc = (pc - bound) * sgn
            sn = (pn - bound) * sgn
            if sc >= 0:
                bx[m] = ax[v]
                by[m] = ay[v]
                m += 1
            if (sc >= 0) != (sn >= 0):
                t = sc / (sc - sn)
                if axis == 0:
                    bx[m] = bound
                    by[m] = ay[v] + t * (ay[w] - ay[v])
                else:
                    bx[m] = ax[v] + t * (ax[w] - ax[v])
                    by[m] = bound
                m += 1
        n = m
        if n < 3:
            return 0.0
        for v in range(n):
            ax[v] = bx[v]
            ay[v] = by[v]
    s = 0.0
    for v in range(n):
        w = (v + 1) % n
        s += ax[v] * ay[w] - ax[w] * ay[v]
    return 0.5 * abs(s)


@njit(cache=True)
def _pixel_box(Pt, rows, cols):
    """Rows lo_r..hi_r and columns lo_c..hi_c of the pixels triangle Pt may overlap."""
    lo_c = min(max(int(np.ceil(min(Pt[0, 0], Pt[1, 0], Pt[2, 0]) - 0.5)), 0), cols - 1)
    hi_c = min(max(int(np.floor(max(Pt[0, 0], Pt[1, 0], Pt[2, 0]) + 0.5)), 0), cols - 1)
    lo_r = min(max(int(np.ceil(min(Pt[0, 1], Pt[1, 1], Pt[2, 1]) - 0.5)), 0), rows - 1)
    hi_r = min(max(int(np.floor(max(Pt[0, 1], Pt[1, 1], Pt[2, 1]) + 0.5)), 0), rows - 1)
    return lo_r, hi_r, lo_c, hi_c


@njit(cache=True)
def _overlap_area(Pt, r, c, rows, cols, buf):
    """Area of pixel (r, c)'s square, clipped to the domain, inside triangle Pt."""
    y0 = max(r - 0.5, 0.0)
    y1 = min(r + 0.5, rows - 1.0)
    x0 = max(c - 0.5, 0.0)
    x1 = min(c + 0.5, cols - 1.0)
    # edge functions at the square's corners: inside when cross(b - a, p - a) >= 0
    inside = True
    for e in range(3):
        ex = Pt[(e + 1) % 3, 0] - Pt[e, 0]
        ey = Pt[(e + 1) % 3, 1] - Pt[e, 1]
        n_in = 0
        n_out = 0
        for q in range(4):
            qx = x0 if q == 0 or q == 3 else x1
            qy = y0 if q < 2 else y1
            s = ex * (qy - Pt[e, 1]) - ey * (qx - Pt[e, 0])
            if s >= 0:
                n_in += 1
            if s <= 0:
                n_out += 1
        if n_out == 4:
            return 0.0
        if n_in < 4:
            inside = False
    if inside:
        return (x1 - x0) * (y1 - y0)
    return _clip_area(Pt, x0, x1, y0, y1, buf)


@njit(cache=True)
def _overlaps(P, rows, cols, t_out, p_out, a_out):
    """Visit every (triangle, pixel) overlap of positive area: with output arrays of the
    right length fill them, else only count. Returns the number of overlaps."""
    fill = t_out.shape[0] > 0
    buf = np.empty((4, _MAXV))
    count = 0
    for t in range(P.shape[0]):
        lo_r, hi_r, lo_c, hi_c = _pixel_box(P[t], rows, cols)
        for r in range(lo_r, hi_r + 1):
            for c in range(lo_c, hi_c + 1):
                a = _overlap_area(P[t], r, c, rows, cols, buf)
                if a <= 0:
                    continue
                if fill:
                    t_out[count] = t
                    p_out[count] = r * cols + c
                    a_out[count] = a
                count += 1
    return count


@njit(cache=True)
def _triangle_sum(P, t, rows, cols, img, buf):
    """Overlap area and area x gray of triangle t."""
    lo_r, hi_r, lo_c, hi_c = _pixel_box(P[t], rows, cols)
    area = 0.0
    weighted = 0.0
    for r in range(lo_r, hi_r + 1):
        for c in range(lo_c, hi_c + 1):
            a = _overlap_area(P[t], r, c, rows, cols, buf)
            if a > 0:
                area += a
                weighted += a * img[r * cols + c]
    return area, weighted


@njit(cache=True)
def _triangle_sums(P, rows, cols, img, area, weighted):
    """Per triangle, the overlap area and area x gray (``img`` flat)."""
    buf = np.empty((4, _MAXV))
    for t in range(P.shape[0]):
        area[t], weighted[t] = _triangle_sum(P, t, rows, cols, img, buf)


@njit(cache=True, parallel=True)
def _triangle_sums_parallel(P, rows, cols, img, area, weighted):
    """:func:`_triangle_sums`, triangles in parallel (each triangle's sums are its own)."""
    n = P.shape[0]
    n_blocks = (n + _TRIANGLE_BLOCK - 1) // _TRIANGLE_BLOCK
    for b in prange(n_blocks):
        buf = np.empty((4, _MAXV))
        for t in range(b * _TRIANGLE_BLOCK, min(n, (b + 1) * _TRIANGLE_BLOCK)):
            area[t], weighted[t] = _triangle_sum(P, t, rows, cols, img, buf)


@njit(cache=True)
def _band_sums(P, rows, cols, values, r_lo, r_hi, pix_area, pix_weighted, buf):
    """Per pixel of rows r_lo..r_hi-1, the overlap area and area x value of the triangles
    over it, added in triangle order."""
    for t in range(P.shape[0]):
        lo_r, hi_r, lo_c, hi_c = _pixel_box(P[t], rows, cols)
        for r in range(max(lo_r, r_lo), min(hi_r + 1, r_hi)):
            for c in range(lo_c, hi_c + 1):
                a = _overlap_area(P[t], r, c, rows, cols, buf)
                if a > 0:
                    pix_area[r * cols + c] += a
                    pix_weighted[r * cols + c] += a * values[t]


@njit(cache=True)
def _pixel_sums(P, rows, cols, values, pix_area, pix_weighted):
    """Per pixel, the overlap area and area x per-triangle value (flat outputs, zeroed)."""
    _band_sums(P, rows, cols, values, 0, rows, pix_area, pix_weighted, np.empty((4, _MAXV)))


@njit(cache=True, parallel=True)
def _pixel_sums_parallel(P, rows, cols, values, pix_area, pix_weighted):
    """:func:`_pixel_sums`, bands of rows in parallel: a pixel lies in one band, where its
    triangles are added in the same order."""
    n_bands = (rows + _BAND_ROWS - 1) // _BAND_ROWS
    for b in prange(n_bands):
        _band_sums(P, rows, cols, values, b * _BAND_ROWS, min(rows, b * _BAND_ROWS + _BAND_ROWS),
                   pix_area, pix_weighted, np.empty((4, _MAXV)))
