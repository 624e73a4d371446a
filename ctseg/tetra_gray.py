"""3D stage 5 (SPEC 9.5): the exact volume-weighted gray value of each tetrahedron, its
transpose (per-voxel means of per-tetrahedron values) and the overlaps behind both."""
import numbers

import numpy as np

from ._overlap_rows import overlap_rows
from . import _threads
from ._overlap_sums import column_sums, row_sums, row_sums_parallel
from ._tet_clip import _overlaps
from ._validate import as_volume, check_spacing
from .errors import InputError, ParameterError

# how far (index units) a mesh vertex may stand outside the box of voxel centres
BOX_TOL = 1e-9


def _as_volume(volume):
    """``volume`` as a finite float64 3D array with at least 2 voxels a side."""
    if np.ndim(volume) != 3:
        raise InputError(f"volume: expected a 3D array (nz, ny, nx), got shape {np.shape(volume)}")
    _check_shape(np.shape(volume), "volume")
    return as_volume(volume).astype(np.float64, copy=False)


def _check_shape(shape, name="shape"):
    try:
        dims = tuple(shape)
    except TypeError:
        raise ParameterError(f"{name}: expected (nz, ny, nx), got {shape!r}") from None
    if len(dims) != 3 or not all(isinstance(d, numbers.Integral) and not isinstance(d, bool)
                                 for d in dims):
        raise ParameterError(f"{name}: expected 3 integers (nz, ny, nx), got {shape!r}")
    if min(dims) < 2:
        raise ParameterError(f"{name}: each side needs at least 2 voxels (the mesh spans the "
                             f"voxel centres), got {dims}")
    return tuple(int(d) for d in dims)


def _check_values(values, m):
    """``values`` as m finite float64 numbers."""
    try:
        vals = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError("values: cannot be read as numbers") from None
    if vals.shape != (m,):
        raise InputError(f"values: expected one per tetrahedron ({m}), got shape {vals.shape}")
    if not np.all(np.isfinite(vals)):
        raise InputError("values: NaN or infinite values")
    return vals


def _corners(points, tetrahedra, shape, spacing):
    """(m, 4, 3) C-contiguous corners in index units, checked and clamped to the box."""
    sp = check_spacing(spacing)
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError("points: cannot be read as an array of numbers") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points: expected shape (n, 3), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise InputError("points: NaN or infinite coordinates")
    tets = np.asarray(tetrahedra)
    if tets.ndim != 2 or tets.shape[1] != 4:
        raise InputError(f"tetrahedra: expected shape (m, 4), got {tets.shape}")
    if tets.size and not np.issubdtype(tets.dtype, np.integer):
        raise InputError(f"tetrahedra: expected integer vertex indices, got dtype {tets.dtype}")
    tets = tets.astype(np.int64)
    if tets.size and (tets.min() < 0 or tets.max() >= len(pts)):
        raise InputError(f"tetrahedra: vertex indices must lie in [0, {len(pts) - 1}], got "
                         f"[{tets.min()}, {tets.max()}]")
    nz, ny, nx = shape
    idx = pts / sp
    top = np.array([nx - 1, ny - 1, nz - 1], float)
    out = (idx < -BOX_TOL) | (idx > top + BOX_TOL)
    if out.any():
        n = int(np.flatnonzero(out.any(axis=1))[0])
        raise InputError(f"points: {int(out.any(axis=1).sum())} vertex(es) outside the box "
                         f"of voxel centres [0, {nx - 1}] x [0, {ny - 1}] x [0, {nz - 1}] "
                         f"(index units = points / spacing; first: vertex {n} at "
                         f"{idx[n].tolist()})")
    idx = np.clip(idx, 0.0, top)
    return np.ascontiguousarray(idx[tets])


def tetra_gray(volume, points, tetrahedra, spacing=(1.0, 1.0, 1.0)):
    """Volume-weighted mean gray value of each tetrahedron (SPEC 9.5).

    ``f(t) = sum_v V_v |c_v ∩ t| / sum_v |c_v ∩ t|`` over voxels v, where voxel (k, j, i)
    is the cube [i -/+ 1/2] x [j -/+ 1/2] x [k -/+ 1/2] in index units, clipped to the box
    of voxel centres [0, nx-1] x [0, ny-1] x [0, nz-1] (border voxels count half, edge
    voxels a quarter, corner voxels an eighth). The overlaps are exact up to rounding
    (:func:`voxel_overlaps`), so a tetrahedron smaller than a
    voxel still gets a value, and over a mesh that fills the box every voxel's volume is
    shared out exactly once: ``sum_t |t| f(t)`` is the integral of the piecewise-constant
    image over the box.

    Parameters
    ----------
    volume : (nz, ny, nx) array_like
        Gray values, any real units (the result is in the same units); at least 2 voxels
        a side.
    points : (n, 3) array_like
        Mesh vertices (x, y, z) in physical units: (i, j, k) index times ``spacing``,
        inside the box of voxel centres (up to 1e-9 index units; then clamped to it).
    tetrahedra : (m, 4) int array_like
        Vertex indices; either orientation.
    spacing : 3 floats > 0
        Voxel size (sx, sy, sz); the points are divided by it before clipping (a linear
        map: the volume ratios, hence the means, do not change).

    Returns
    -------
    gray : (m,) float64 ndarray

    Raises
    ------
    InputError
        A volume that is not a finite real 3D array, points or tetrahedra of the wrong
        shape or type, vertex indices out of range, points outside the box, or a
        tetrahedron that covers no volume (flat).
    ParameterError
        A spacing that is not 3 finite numbers > 0; fewer than 2 voxels along an axis.

    Example
    -------
    >>> import numpy as np
    >>> from ctseg.tetra_gray import tetra_gray
    >>> volume = np.zeros((2, 2, 2))
    >>> volume[1] = 80.0  # the upper slice, z = 1
    >>> points = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    >>> tetra_gray(volume, points, [[0, 1, 2, 3]]).round(6)  # 1/8 of it above z = 1/2
    array([10.])
    """
    vol = _as_volume(volume)
    P = _corners(points, tetrahedra, vol.shape, spacing)
    m = len(P)
    tet_vol = np.zeros(m)
    tet_w = np.zeros(m)
    _overlaps(P, *vol.shape, np.ascontiguousarray(vol.ravel()), np.zeros(0), tet_vol, tet_w,
              np.zeros(0), np.zeros(0))
    _check_filled(tet_vol)
    return tet_w / tet_vol


def _check_filled(tet_vol):
    if np.any(tet_vol <= 0):
        t = int(np.flatnonzero(tet_vol <= 0)[0])
        raise InputError(f"tetrahedra: {int((tet_vol <= 0).sum())} tetrahedron(s) cover no "
                         f"volume (flat; first: {t})")


def voxel_mean_of_tetrahedra(values, points, tetrahedra, shape, spacing=(1.0, 1.0, 1.0)):
    """Per voxel, the overlap-weighted mean of the values of the tetrahedra over it.

    ``g(v) = sum_t u_t |c_v ∩ t| / sum_t |c_v ∩ t|``: the transpose of
    :func:`tetra_gray` on the same exact overlaps (with ``A[t, v] = |c_v ∩ t|``,
    ``tetra_gray = D_t^-1 A V`` and this is ``D_v^-1 A^T u``, D the row and column sums),
    without holding the overlaps in memory. A voxel no tetrahedron overlaps gets 0 (a
    mean over nothing; ``covered`` tells those voxels apart).

    Parameters
    ----------
    values : (m,) array_like
        One finite value per tetrahedron.
    points, tetrahedra, spacing
        As for :func:`tetra_gray`.
    shape : (nz, ny, nx) ints
        The volume's shape.

    Returns
    -------
    mean : (nz, ny, nx) float64 ndarray
        0 where no tetrahedron overlaps the voxel.
    covered : (nz, ny, nx) float64 ndarray
        Volume of each voxel covered by the tetrahedra, index units: 1 inside, 1/2 on the
        box faces, 1/4 on its edges, 1/8 at its corners for a mesh that fills the box.

    Raises
    ------
    InputError
        As for :func:`tetra_gray`; values not one finite number per tetrahedron.
    ParameterError
        A bad ``shape`` or ``spacing``.

    Example
    -------
    >>> import numpy as np
    >>> from ctseg.tetra_gray import voxel_mean_of_tetrahedra
    >>> points = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    >>> mean, covered = voxel_mean_of_tetrahedra([5.0], points, [[0, 1, 2, 3]], (2, 2, 2))
    >>> float(mean[0, 0, 0]), float(mean[1, 1, 1]), round(float(covered.sum()) * 6, 12)
    (5.0, 0.0, 1.0)
    """
    dims = _check_shape(shape)
    P = _corners(points, tetrahedra, dims, spacing)
    vals = _check_values(values, len(P))
    n = dims[0] * dims[1] * dims[2]
    covered = np.zeros(n)
    weighted = np.zeros(n)
    if len(P):
        _overlaps(P, *dims, np.zeros(0), np.ascontiguousarray(vals), np.zeros(0), np.zeros(0),
                  covered, weighted)
    mean = np.divide(weighted, covered, out=np.zeros_like(weighted), where=covered > 0)
    return mean.reshape(dims), covered.reshape(dims)


def voxel_overlaps(points, tetrahedra, shape, spacing=(1.0, 1.0, 1.0)):
    """Exact volumes of every (tetrahedron, voxel) overlap.

    Each tetrahedron (in index units, ``points / spacing``) is shared out row by row of
    voxels: the volume of its piece in a row's prism below the plane ``x = c`` is the
    integral of ``(x - c) n_x`` over its faces clipped to the prism and the plane
    (divergence theorem), and a voxel gets the difference between its two planes
    (:mod:`ctseg._tet_clip`). Only the voxels a tetrahedron reaches are visited, and its
    overlaps sum to its volume up to rounding. A tetrahedron inside one voxel is one
    overlap. The voxel cubes are clipped to the box of voxel centres, as in
    :func:`tetra_gray`.

    Parameters
    ----------
    points, tetrahedra, spacing
        As for :func:`tetra_gray`.
    shape : (nz, ny, nx) ints
        The volume's shape.

    Returns
    -------
    tet, voxel : (q,) int64 ndarrays
        Tetrahedron index and flat voxel index ``(k * ny + j) * nx + i`` of each overlap,
        grouped by tetrahedron.
    overlap : (q,) float64 ndarray
        Overlap volume in index units (voxels; > 0). Times ``prod(spacing)`` in physical
        units.

    Raises
    ------
    InputError, ParameterError
        As for :func:`voxel_mean_of_tetrahedra`.

    Example
    -------
    >>> from ctseg.tetra_gray import voxel_overlaps
    >>> points = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    >>> tet, voxel, overlap = voxel_overlaps(points, [[0, 1, 2, 3]], (2, 2, 2))
    >>> voxel.tolist(), (overlap * 48).round(9).tolist()  # voxel 0 holds 1/8 of the box
    ([0, 1, 2, 4], [5.0, 1.0, 1.0, 1.0])
    """
    return VoxelOverlaps(points, tetrahedra, shape, spacing).rows()


def _row_sums():
    """The per-tetrahedron sums, threaded where threads are allowed (the same bits)."""
    return _threads.pick(row_sums, row_sums_parallel)


def _expected_cells(P):
    """Expected number of unit cells a tetrahedron (m, 4, 3) meets at a random offset:
    the volume of its Minkowski sum with the cell, ``V + sum_i A_i + sum_i L_i + 1``
    (A_i its shadow on the plane normal to axis i, L_i its extent along it)."""
    e = P[:, 1:] - P[:, :1]
    vol = np.abs(np.einsum("ij,ij->i", np.cross(e[:, 0], e[:, 1]), e[:, 2])) / 6.0
    shadow = np.zeros(len(P))
    for a, b, c in ((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)):  # each face's area vector
        shadow += 0.25 * np.abs(np.cross(P[:, b] - P[:, a], P[:, c] - P[:, a])).sum(axis=1)
    extent = (P.max(axis=1) - P.min(axis=1)).sum(axis=1)
    return vol + shadow + extent + 1.0


class VoxelOverlaps:
    """The exact (tetrahedron, voxel) overlaps of a mesh, computed once and kept, for
    every mean over the same mesh and volume shape.

    One pass of the clipping kernel (:func:`voxel_overlaps` explains it) instead of one
    per image: the 3D labelling takes five means over one mesh. Kept as compressed rows,
    about 12 bytes per overlap (some 100 per tetrahedron of 27 voxels: ~175 MB for a
    160^3 volume's 150 000 tetrahedra). Each mean sums the overlaps in the order the
    streaming kernel does, so :meth:`tetra_mean` equals :func:`tetra_gray` and
    :meth:`voxel_mean` equals :func:`voxel_mean_of_tetrahedra` bit for bit.

    Parameters
    ----------
    points, tetrahedra, spacing
        As for :func:`tetra_gray`.
    shape : (nz, ny, nx) ints
        The volume's shape.

    Attributes
    ----------
    shape : tuple
    start : (m + 1,) int64 ndarray
        The overlaps of tetrahedron t are ``start[t]:start[t + 1]`` of the two below.
    voxel : (q,) int32 ndarray (int64 beyond 2**31 voxels)
        Flat voxel index ``(k * ny + j) * nx + i``.
    overlap : (q,) float64 ndarray
        Volume, index units.

    Raises
    ------
    InputError, ParameterError
        As for :func:`voxel_overlaps`.

    Example
    -------
    >>> import numpy as np
    >>> points = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    >>> ov = VoxelOverlaps(points, [[0, 1, 2, 3]], (2, 2, 2))
    >>> volume = np.zeros((2, 2, 2)); volume[1] = 80.0
    >>> ov.tetra_mean(volume).round(6), ov.start.tolist()
    (array([10.]), [0, 4])
    """

    def __init__(self, points, tetrahedra, shape, spacing=(1.0, 1.0, 1.0)):
        dims = _check_shape(shape)
        P = _corners(points, tetrahedra, dims, spacing)
        self.shape = dims
        self.start, self.voxel, self.overlap = overlap_rows(P, dims, _expected_cells(P))
        self.tet_volume = _row_sums()(self.start, self.voxel, self.overlap, np.zeros(0))[0]

    @property
    def n_tetrahedra(self):
        return len(self.start) - 1

    def tet(self):
        """(q,) int64 ndarray: the tetrahedron of each overlap."""
        return np.repeat(np.arange(self.n_tetrahedra), np.diff(self.start))

    def rows(self, which=None):
        """``(tet, voxel, overlap)`` as :func:`voxel_overlaps` returns them (voxel as
        int64), of all tetrahedra or of ``which`` (indices, the order kept; ``tet`` then
        counts positions in ``which``)."""
        if which is None:
            return self.tet(), self.voxel.astype(np.int64), self.overlap
        which = np.asarray(which, np.int64)
        first = self.start[which]
        count = self.start[which + 1] - first
        before = np.cumsum(count) - count
        idx = np.arange(int(count.sum())) + np.repeat(first - before, count)
        return (np.repeat(np.arange(len(which)), count), self.voxel[idx].astype(np.int64),
                self.overlap[idx])

    def tetra_mean(self, volume):
        """:func:`tetra_gray` of ``volume`` (nz, ny, nx) on this mesh.

        Raises
        ------
        InputError
            Not a finite volume of this shape, or a tetrahedron that covers no volume.
        """
        vol = _as_volume(volume)
        if vol.shape != self.shape:
            raise InputError(f"volume: shape {vol.shape}, the overlaps are of {self.shape}")
        _check_filled(self.tet_volume)
        return np.divide(*_row_sums()(self.start, self.voxel, self.overlap,
                                    np.ascontiguousarray(vol.ravel()))[::-1])

    def voxel_mean(self, values):
        """:func:`voxel_mean_of_tetrahedra` of one value per tetrahedron: (mean, covered).

        Raises
        ------
        InputError
            Not one finite value per tetrahedron.
        """
        vals = _check_values(values, self.n_tetrahedra)
        covered, weighted = column_sums(self.start, self.voxel, self.overlap,
                                         np.ascontiguousarray(vals), int(np.prod(self.shape)))
        mean = np.divide(weighted, covered, out=np.zeros_like(weighted), where=covered > 0)
        return mean.reshape(self.shape), covered.reshape(self.shape)
