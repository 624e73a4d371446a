"""Image geometry without VTK: the slice index maps of a volume (which array axis a slice
runs along, a slice as an image, its pixel coordinates back in the volume)."""
import numpy as np

from .errors import ParameterError

AXES = {"z": 0, "y": 1, "x": 2}
"""Slice axis name -> axis of the (nz, ny, nx) array (VTK's k, j, i)."""


def slice_axis(axis):
    """Numpy axis (0, 1, 2) of a slice axis given as 'z'/'y'/'x' or 0/1/2 (numpy order)."""
    if isinstance(axis, str) and axis.lower() in AXES:
        return AXES[axis.lower()]
    if isinstance(axis, (int, np.integer)) and not isinstance(axis, bool) and 0 <= axis <= 2:
        return int(axis)
    raise ParameterError(f"axis: expected 'z', 'y' or 'x' (or 0, 1, 2), got {axis!r}")


def volume_slice(volume, axis, k):
    """Slice ``k`` along ``axis`` of an (nz, ny, nx) volume as a (rows, cols) image.

    Along z the slice is ``volume[k]`` (rows = y, cols = x); along y it is
    ``volume[:, k, :]`` (rows = z, cols = x); along x ``volume[:, :, k]`` (rows = z,
    cols = y). :func:`slice_to_volume_index` maps its pixel coordinates back.
    """
    return np.take(volume, k, axis=slice_axis(axis))


def slice_to_volume_index(points, axis, k):
    """Points (x=col, y=row) of slice ``k`` -> (i, j, k) index coordinates of the volume
    (VTK's order: i along x, j along y, k along z)."""
    pts = np.asarray(points, float).reshape(-1, 2)
    col, row, pos = pts[:, 0], pts[:, 1], np.full(len(pts), float(k))
    ax = slice_axis(axis)
    if ax == 0:
        return np.column_stack([col, row, pos])
    if ax == 1:
        return np.column_stack([col, pos, row])
    return np.column_stack([pos, col, row])




class ImageGeometry:
    """Index-to-world map of an image: ``world = origin + direction @ (index * spacing)``.

    Indices are (i, j, k) in VTK's order (i along the columns, j along the rows, k along
    the slices). The VTK layer (:mod:`ctseg.filters.convert`) reads and writes it on
    vtkImageData and in field data; nothing here needs VTK.

    Parameters
    ----------
    origin : 3 floats
        World position of index (0, 0, 0).
    spacing : 3 floats
        Index step in world units along i, j, k (finite, > 0).
    direction : (3, 3) array_like
        Columns: the world directions of i, j and k.

    Raises
    ------
    InputError
        Wrong lengths, a non-finite or non-positive spacing, a singular direction.

    Example
    -------
    >>> g = ImageGeometry(origin=(1, 0, 0), spacing=(0.5, 0.5, 2))
    >>> g.to_world([[2, 4, 1]]).tolist()
    [[2.0, 2.0, 2.0]]
    """

    def __init__(self, origin=(0.0, 0.0, 0.0), spacing=(1.0, 1.0, 1.0), direction=None):
        from .errors import InputError

        try:
            self.origin = tuple(float(v) for v in np.asarray(origin, float).ravel())
            self.spacing = tuple(float(v) for v in np.asarray(spacing, float).ravel())
            self.direction = (np.eye(3) if direction is None
                              else np.asarray(direction, float).reshape(3, 3))
        except (TypeError, ValueError) as exc:
            raise InputError(f"geometry: not numbers of the right shape ({exc})") from None
        if len(self.origin) != 3 or len(self.spacing) != 3:
            raise InputError("geometry: origin and spacing need 3 values each")
        if not all(np.isfinite(self.origin)):
            raise InputError(f"geometry: origin must be finite, got {self.origin}")
        if not all(np.isfinite(self.spacing)) or min(self.spacing) <= 0:
            raise InputError(f"geometry: spacing must be finite and > 0, got {self.spacing}")
        if not np.all(np.isfinite(self.direction)) or abs(np.linalg.det(self.direction)) < 1e-12:
            raise InputError("geometry: the direction matrix must be finite and invertible")

    def __repr__(self):
        return (f"ImageGeometry(origin={self.origin}, spacing={self.spacing}, "
                f"direction={self.direction.tolist()})")

    def __eq__(self, other):
        if not isinstance(other, ImageGeometry):
            return NotImplemented
        return (self.origin == other.origin and self.spacing == other.spacing
                and np.array_equal(self.direction, other.direction))

    __hash__ = None

    def to_world(self, ijk):
        """(n, 3) index coordinates (i, j, k), fractional allowed -> (n, 3) world points."""
        ijk = np.asarray(ijk, float)
        return np.asarray(self.origin) + (ijk * np.asarray(self.spacing)) @ self.direction.T

    def to_index(self, xyz):
        """(n, 3) world points -> (fractional) index coordinates (i, j, k)."""
        xyz = np.asarray(xyz, float) - np.asarray(self.origin)
        return np.linalg.solve(self.direction, xyz.T).T / np.asarray(self.spacing)
