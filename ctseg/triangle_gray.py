"""Stage 5: exact area-weighted gray value of each triangle (paper 6, SPEC 5)."""
import numpy as np

from ._validate import as_image
from .errors import InputError

_MAXV = 8  # a triangle clipped by 4 half-planes has at most 7 vertices


def _clip_halfplane(P, n, axis, bound, keep_greater):
    """Sutherland-Hodgman clip of many convex polygons against one axis-aligned line.

    P: (N, M, 2) vertices, n: (N,) counts. Keeps the side coord >= bound (or <= bound).
    """
    N, M, _ = P.shape
    bound = np.asarray(bound, float).reshape(-1, 1)
    i = np.arange(M)
    valid = i[None, :] < n[:, None]
    nxt_idx = (i[None, :] + 1) % np.maximum(n, 1)[:, None]
    Q = np.take_along_axis(P, nxt_idx[:, :, None], axis=1)
    sgn = 1.0 if keep_greater else -1.0
    sc = (P[:, :, axis] - bound) * sgn
    sn = (Q[:, :, axis] - bound) * sgn
    inc, inn = sc >= 0, sn >= 0
    denom = np.where(sc != sn, sc - sn, 1.0)
    t = sc / denom
    X = P + t[:, :, None] * (Q - P)
    X[:, :, axis] = bound  # exact on the clip line (bound broadcasts per polygon)
    out = np.empty((N, 2 * M, 2))
    out[:, 0::2] = P
    out[:, 1::2] = X
    keep = np.empty((N, 2 * M), bool)
    keep[:, 0::2] = valid & inc
    keep[:, 1::2] = valid & (inc != inn)
    order = np.argsort(~keep, axis=1, kind="stable")
    out = np.take_along_axis(out, order[:, :, None], axis=1)[:, :_MAXV]
    return out, keep.sum(axis=1)


def _polygon_area(P, n):
    M = P.shape[1]
    i = np.arange(M)
    nxt_idx = (i[None, :] + 1) % np.maximum(n, 1)[:, None]
    Q = np.take_along_axis(P, nxt_idx[:, :, None], axis=1)
    cross = P[:, :, 0] * Q[:, :, 1] - Q[:, :, 0] * P[:, :, 1]
    cross = np.where(i[None, :] < n[:, None], cross, 0.0)
    return 0.5 * np.abs(cross.sum(axis=1))


def pixel_overlaps(points, triangles, shape, chunk=400_000):
    """Exact areas of every (triangle, pixel) overlap.

    The domain is the rectangle spanned by the pixel centres, [0, cols-1] x [0, rows-1]
    (the CVT pins sites to the corner pixel centres, SPEC 3), so each pixel's square
    [c-0.5, c+0.5] x [r-0.5, r+0.5] is first clipped to it: border pixels count half,
    corner pixels a quarter. Fully covered pixels are found by a corner test; only pixels
    cut by a triangle edge are clipped exactly (Sutherland-Hodgman, vectorised).

    Parameters
    ----------
    points : (n, 2) array_like
        Vertices (x, y) in pixel units, inside the domain.
    triangles : (m, 3) int array_like
        Counter-clockwise triangles.
    shape : (rows, cols)
    chunk : int
        Candidate pairs processed at once (bounds memory).

    Returns
    -------
    tri, pix : (k,) int64 ndarrays
        Triangle index and flat pixel index (row * cols + col) of each overlap.
    area : (k,) float64 ndarray
        Overlap area in pixel units (> 0).
    """
    rows, cols = int(shape[0]), int(shape[1])
    pts = np.asarray(points, float)
    tri = np.asarray(triangles, np.int64)
    P = pts[tri]  # (m, 3, 2)
    lo = np.clip(np.ceil(P.min(axis=1) - 0.5).astype(np.int64), 0, [cols - 1, rows - 1])
    hi = np.clip(np.floor(P.max(axis=1) + 0.5).astype(np.int64), 0, [cols - 1, rows - 1])
    nx = hi[:, 0] - lo[:, 0] + 1
    ny = hi[:, 1] - lo[:, 1] + 1
    counts = nx * ny
    # edge normals: inside when cross(b - a, p - a) >= 0 (counter-clockwise)
    A = P
    B = P[:, [1, 2, 0]]
    out_t, out_p, out_a = [], [], []
    starts = np.concatenate([[0], np.cumsum(counts)])
    total = int(starts[-1])
    tri_of = np.repeat(np.arange(len(tri)), counts)
    for s in range(0, total, chunk):
        e = min(total, s + chunk)
        t = tri_of[s:e]
        k = np.arange(s, e) - starts[t]
        c = lo[t, 0] + k % nx[t]
        r = lo[t, 1] + k // nx[t]
        x0 = np.maximum(c - 0.5, 0.0)
        x1 = np.minimum(c + 0.5, cols - 1.0)
        y0 = np.maximum(r - 0.5, 0.0)
        y1 = np.minimum(r + 0.5, rows - 1.0)
        cx = np.stack([x0, x1, x1, x0], axis=1)  # (N, 4) square corners
        cy = np.stack([y0, y0, y1, y1], axis=1)
        a, b = A[t], B[t]  # (N, 3, 2)
        ex = (b[:, :, 0] - a[:, :, 0])[:, :, None]
        ey = (b[:, :, 1] - a[:, :, 1])[:, :, None]
        side = ex * (cy[:, None, :] - a[:, :, 1, None]) - ey * (cx[:, None, :] - a[:, :, 0, None])
        inside_all = np.all(side >= 0, axis=(1, 2))
        outside_any = np.any(np.all(side <= 0, axis=2), axis=1) & ~inside_all
        area = np.where(inside_all, (x1 - x0) * (y1 - y0), 0.0)
        cut = ~inside_all & ~outside_any
        if cut.any():
            idx = np.flatnonzero(cut)
            poly = np.zeros((len(idx), _MAXV, 2))
            poly[:, :3] = P[t[idx]]
            cnt = np.full(len(idx), 3)
            poly, cnt = _clip_halfplane(poly, cnt, 0, x0[idx], True)
            poly, cnt = _clip_halfplane(poly, cnt, 0, x1[idx], False)
            poly, cnt = _clip_halfplane(poly, cnt, 1, y0[idx], True)
            poly, cnt = _clip_halfplane(poly, cnt, 1, y1[idx], False)
            area[idx] = np.where(cnt >= 3, _polygon_area(poly, cnt), 0.0)
        keep = area > 0
        out_t.append(t[keep])
        out_p.append((r * cols + c)[keep])
        out_a.append(area[keep])
    return np.concatenate(out_t), np.concatenate(out_p), np.concatenate(out_a)



def triangle_gray(image, points, triangles):
    """Area-weighted mean gray value of each triangle.

    ``f(t) = sum_j I_j |u_j ∩ t| / |t|`` over pixels u_j (pixel squares clipped to the
    domain, see :func:`pixel_overlaps`). Pixels cut by a triangle edge are subdivided
    exactly by polygon clipping, so a triangle smaller than a pixel still gets a value and
    every pixel's area is shared out exactly once.

    Parameters
    ----------
    image : (rows, cols) array_like
        Gray image, in any units (the result is in the same units).
    points : (n, 2) array_like
        Mesh vertices (x, y) in pixel units inside [0, cols-1] x [0, rows-1].
    triangles : (m, 3) int array_like
        Counter-clockwise triangles.

    Returns
    -------
    gray : (m,) float64 ndarray

    Raises
    ------
    InputError
        Bad image, points outside the image, or a triangle without area.

    References
    ----------
    Yang et al. 2014, section 6 ("the pixels on the edges of a triangle are subdivided").
    """
    img = as_image(image)
    pts = np.asarray(points, float)
    rows, cols = img.shape
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise InputError(f"points: expected shape (n, 2), got {pts.shape}")
    if (pts[:, 0].min() < -1e-9 or pts[:, 0].max() > cols - 1 + 1e-9
            or pts[:, 1].min() < -1e-9 or pts[:, 1].max() > rows - 1 + 1e-9):
        raise InputError("points: mesh vertices must lie inside the image domain")
    t, p, a = pixel_overlaps(pts, triangles, img.shape)
    m = len(triangles)
    area = np.bincount(t, a, m)
    if np.any(area <= 0):
        raise InputError("triangles: a triangle covers no image area (degenerate?)")
    return np.bincount(t, a * img.ravel()[p], m) / area
