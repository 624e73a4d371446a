"""Meshes to pixels: the exact triangle/pixel overlaps and the label images they give
(of a slice, on a finer grid, of a volume)."""
import numpy as np

from .errors import MeshCheckError

from ._clip import _corners, _overlaps


def pixel_overlaps(points, triangles, shape):
    """Exact areas of every (triangle, pixel) overlap.

    The domain is the rectangle spanned by the pixel centres, [0, cols-1] x [0, rows-1]
    (the CVT pins sites to the corner pixel centres, SPEC 3), so each pixel's square
    [c-0.5, c+0.5] x [r-0.5, r+0.5] is first clipped to it: border pixels count half,
    corner pixels a quarter. Pixels whose square lies inside the triangle (corner test)
    count whole; only pixels cut by a triangle edge are clipped exactly
    (Sutherland-Hodgman).

    Parameters
    ----------
    points : (n, 2) array_like
        Vertices (x, y) in pixel units, inside the domain.
    triangles : (m, 3) int array_like
        Counter-clockwise triangles.
    shape : (rows, cols)

    Returns
    -------
    tri, pix : (k,) int64 ndarrays
        Triangle index and flat pixel index (row * cols + col) of each overlap.
    area : (k,) float64 ndarray
        Overlap area in pixel units (> 0).
    """
    P = _corners(points, triangles)
    rows, cols = int(shape[0]), int(shape[1])
    none = np.zeros(0, np.int64)
    k = _overlaps(P, rows, cols, none, none, np.zeros(0))
    t, p, a = np.empty(k, np.int64), np.empty(k, np.int64), np.empty(k)
    _overlaps(P, rows, cols, t, p, a)
    return t, p, a


def label_image(points, triangles, material, shape):
    """Rasterise per-triangle labels: each pixel takes the label covering most of its area.

    Parameters
    ----------
    points : (n, 2) array_like
        Mesh vertices (x, y) in pixel units inside [0, cols-1] x [0, rows-1].
    triangles : (m, 3) int array_like
        Counter-clockwise triangles.
    material : (m,) int array_like
        Label (>= 0) of each triangle.
    shape : (rows, cols)

    Returns
    -------
    labels : (rows, cols) int64 ndarray
        Per pixel, the label of the largest area over it (:func:`pixel_overlaps`); of
        equal areas, the lower label.

    Example
    -------
    >>> import numpy as np
    >>> from ctseg.raster import label_image
    >>> points = np.array([[0, 0], [1.4, 0], [3, 0], [0, 3], [1.4, 3], [3, 3]], float)
    >>> triangles = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    >>> label_image(points, triangles, [0, 0, 1, 1], (4, 4))
    array([[0, 0, 1, 1],
           [0, 0, 1, 1],
           [0, 0, 1, 1],
           [0, 0, 1, 1]])
    """
    rows, cols = int(shape[0]), int(shape[1])
    mat = np.asarray(material, np.int64)
    k = int(mat.max()) + 1
    t, p, a = pixel_overlaps(points, triangles, (rows, cols))
    acc = np.bincount(p * k + mat[t], a, rows * cols * k).reshape(rows * cols, k)
    return acc.argmax(axis=1).reshape(rows, cols)


def subpixel_label_image(points, triangles, material, shape, supersample):
    """Rasterise per-triangle labels on a grid ``supersample`` times finer than the image.

    Fine pixel (i, j) is the square of side 1/supersample whose centre is at image pixel
    coordinates ``((j + 0.5) / s - 0.5, (i + 0.5) / s - 0.5)``: the sub-pixels of the
    phantoms' fine truth. The mesh spans the rectangle of the image's pixel centres, so the
    outer half pixel is not covered.

    Parameters
    ----------
    points, triangles, material, shape
        As for :func:`label_image` (``shape`` is the image's, not the fine grid's).
    supersample : int
        Sub-pixels per pixel side.

    Returns
    -------
    labels : (rows * s, cols * s) int64 ndarray
    covered : (rows * s, cols * s) bool ndarray
        Sub-pixels at least half inside the mesh (the others hold label 0).
    """
    s = int(supersample)
    fine = (int(shape[0]) * s, int(shape[1]) * s)
    pts = (np.asarray(points, float) + 0.5) * s - 0.5
    mat = np.asarray(material, np.int64)
    k = int(mat.max()) + 1
    t, p, a = pixel_overlaps(pts, triangles, fine)
    acc = np.bincount(p * k + mat[t], a, fine[0] * fine[1] * k).reshape(-1, k)
    return acc.argmax(axis=1).reshape(fine), (acc.sum(axis=1) >= 0.5 - 1e-9).reshape(fine)


def volume_labels(vseg, shape):
    """Per-voxel material labels of a volume segmentation (each slice rasterised).

    Parameters
    ----------
    vseg : ctseg.volume.VolumeSegmentation
        Or any object with ``slices`` (one mesh with ``points``, ``triangles``,
        ``material`` and ``shape`` per slice) and ``axis`` (the numpy axis sliced).
    shape : (nz, ny, nx)
        Shape of the volume.

    Returns
    -------
    labels : (nz, ny, nx) int64 ndarray
        :func:`label_image` of each slice; 0 where no slice was segmented.
    """
    out = np.zeros(shape, np.int64)
    for k, seg in enumerate(vseg.slices):
        lab = label_image(seg.points, seg.triangles, seg.material, seg.shape)
        idx = [slice(None)] * 3
        idx[vseg.axis] = k
        out[tuple(idx)] = lab
    return out


CANDIDATES_PER_CHUNK = 4_000_000
"""(tetrahedron, voxel) pairs tested at once: bounds the memory of :func:`tetra_label_volume`."""

BARY_TOL = 1e-9
"""Barycentric slack: a voxel centre on a face (or the box) counts as inside."""


def tetra_label_volume(points, tetrahedra, material, shape, spacing=(1.0, 1.0, 1.0)):
    """Label every voxel centre with the material of the tetrahedron it lies in.

    Voxel (k, j, i) has its centre at (i, j, k) x spacing, the coordinates of the
    tetrahedra of :class:`ctseg.pipeline3d.TetraSegmentation`. Each tetrahedron tests
    the voxel centres of its bounding box by their barycentric coordinates; a centre on a
    face shared by two tetrahedra takes the later one's material.

    Parameters
    ----------
    points : (n, 3) array_like
    tetrahedra : (m, 4) int array_like
    material : (m,) int array_like
    shape : (nz, ny, nx)
    spacing : (3,) array_like

    Returns
    -------
    labels : (nz, ny, nx) int64 ndarray

    Raises
    ------
    MeshCheckError
        Voxel centres no tetrahedron holds (the tetrahedra do not fill the box).

    Example
    -------
    >>> from ctseg.tetrahedra import delaunay_tetrahedra
    >>> c = np.array([[x, y, z] for x in (0, 2) for y in (0, 1) for z in (0, 1)], float)
    >>> mesh = delaunay_tetrahedra(np.vstack([c, [[1.0, 0.5, 0.5]]]), (2, 1, 1))
    >>> mat = (mesh.points[mesh.tetrahedra].mean(axis=1)[:, 0] > 1).astype(int)
    >>> lab = tetra_label_volume(mesh.points, mesh.tetrahedra, mat, (5, 5, 9), (0.25,) * 3)
    >>> lab[2, 2, [1, 7]].tolist()  # voxel centres (0.25, 0.5, 0.5) and (1.75, 0.5, 0.5)
    [0, 1]
    """
    shape = tuple(int(s) for s in shape)
    pts = np.asarray(points, float) / np.asarray(spacing, float)
    tets = np.asarray(tetrahedra, np.int64).reshape(-1, 4)
    mat = np.asarray(material, np.int64)
    P = pts[tets]  # (m, 4, 3), index units
    top = np.array(shape[::-1]) - 1
    lo = np.clip(np.ceil(P.min(axis=1) - 1e-7), 0, top).astype(np.int64)
    hi = np.clip(np.floor(P.max(axis=1) + 1e-7), 0, top).astype(np.int64)
    dims = np.maximum(hi - lo + 1, 0)
    count = dims.prod(axis=1)
    edges = P[:, 1:] - P[:, :1]  # (m, 3, 3): rows b-a, c-a, d-a
    det = np.linalg.det(edges)
    ok = np.abs(det) > 0
    inv = np.zeros_like(edges)
    inv[ok] = np.linalg.inv(np.transpose(edges[ok], (0, 2, 1)))
    labels = np.full(shape, -1, np.int64)
    flat = labels.reshape(-1)
    nx, ny = shape[2], shape[1]
    cum = np.cumsum(count)
    start = 0
    while start < len(tets):
        base = cum[start - 1] if start else 0
        stop = max(start + 1, int(np.searchsorted(cum, base + CANDIDATES_PER_CHUNK, "right")))
        t = np.repeat(np.arange(start, stop), count[start:stop])
        local = np.arange(len(t)) - np.repeat(cum[start:stop] - count[start:stop] - base,
                                              count[start:stop])
        d = dims[t]
        ijk = lo[t] + np.column_stack([local % d[:, 0], (local // d[:, 0]) % d[:, 1],
                                       local // (d[:, 0] * d[:, 1])])
        lam = np.einsum("nij,nj->ni", inv[t], ijk - P[t, 0])
        inside = ok[t] & np.all(lam >= -BARY_TOL, axis=1) & (lam.sum(axis=1) <= 1 + BARY_TOL)
        v = ijk[inside]
        flat[(v[:, 2] * ny + v[:, 1]) * nx + v[:, 0]] = mat[t[inside]]
        start = stop
    missing = int(np.sum(labels < 0))
    if missing:
        raise MeshCheckError(f"tetrahedra: {missing} voxel centre(s) lie in no tetrahedron")
    return labels
