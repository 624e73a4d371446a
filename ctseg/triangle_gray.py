"""Stage 5: exact area-weighted gray value of each triangle (paper 6, SPEC 5)."""
import numpy as np

from . import _clip, _threads
from ._clip import _corners
from ._validate import as_image
from .errors import InputError


def triangle_gray(image, points, triangles):
    """Area-weighted mean gray value of each triangle.

    ``f(t) = sum_j I_j |u_j ∩ t| / |t|`` over pixels u_j (pixel squares clipped to the
    domain, see :func:`ctseg.raster.pixel_overlaps`). Pixels cut by a triangle edge are
    subdivided exactly by polygon clipping, so a triangle smaller than a pixel still gets a
    value and every pixel's area is shared out exactly once.

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

    Example
    -------
    >>> import numpy as np
    >>> from ctseg import triangle_gray
    >>> image = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [90.0, 90.0, 90.0]])
    >>> points = np.array([[0, 0], [2, 0], [0, 2], [2, 2]], float)
    >>> triangles = np.array([[0, 1, 3], [0, 3, 2]])  # counter-clockwise in (x, y)
    >>> triangle_gray(image, points, triangles).round(3)  # the bright row is half inside
    array([ 5.625, 39.375])
    """
    img = as_image(image)
    pts = np.asarray(points, float)
    rows, cols = img.shape
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise InputError(f"points: expected shape (n, 2), got {pts.shape}")
    if (pts[:, 0].min() < -1e-9 or pts[:, 0].max() > cols - 1 + 1e-9
            or pts[:, 1].min() < -1e-9 or pts[:, 1].max() > rows - 1 + 1e-9):
        raise InputError("points: mesh vertices must lie inside the image domain")
    P = _corners(pts, triangles)
    area = np.zeros(len(P))
    weighted = np.zeros(len(P))
    sums = _threads.pick(_clip._triangle_sums, _clip._triangle_sums_parallel)
    sums(P, rows, cols, np.ascontiguousarray(img.ravel()), area, weighted)
    if np.any(area <= 0):
        raise InputError("triangles: a triangle covers no image area (degenerate?)")
    return weighted / area


def pixel_mean_of_triangles(values, points, triangles, shape):
    """Per pixel, the area-weighted mean of the values of the triangles over it.

    The transpose of :func:`triangle_gray`, on the same exact overlaps
    (:func:`ctseg.raster.pixel_overlaps`), without holding them all in memory.

    Parameters
    ----------
    values : (m,) array_like
        One value per triangle.
    points : (n, 2) array_like
    triangles : (m, 3) int array_like
    shape : (rows, cols)

    Returns
    -------
    mean : (rows, cols) float64 ndarray
        0 where no triangle overlaps the pixel.
    covered : (rows, cols) float64 ndarray
        Area of each pixel covered by the triangles (1 inside, 1/2 on the border lines,
        1/4 at the corners for a mesh over the whole image).
    """
    values = np.ascontiguousarray(values, dtype=np.float64)
    if values.shape != (len(triangles),):
        raise InputError(f"values: expected one per triangle ({len(triangles)}), got shape "
                         f"{values.shape}")
    P = _corners(points, triangles)
    rows, cols = int(shape[0]), int(shape[1])
    covered = np.zeros(rows * cols)
    weighted = np.zeros(rows * cols)
    sums = _threads.pick(_clip._pixel_sums, _clip._pixel_sums_parallel)
    sums(P, rows, cols, values, covered, weighted)
    mean = np.divide(weighted, covered, out=np.zeros_like(weighted), where=covered > 0)
    return mean.reshape(rows, cols), covered.reshape(rows, cols)
