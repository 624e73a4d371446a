"""Blur correction of the triangle grays before the final labelling (not in the paper).

A reconstructed slice is the material map seen through the scanner's point-spread function
(detector, focal spot, reconstruction filter): every edge is smeared over a pixel or two.
Next to steel, whose gray is ten times the others', that tail alone lifts a 3-5 px air gap
to a polymer's gray, and triangles that touch the metal read too bright; a thin triangle
loses part of its own signal to its neighbours. Once a first labelling exists, the smear
it predicts can be taken off: with ``L`` the image of the labelled levels and ``G`` a
Gaussian point-spread function fitted to the image, a triangle reads ``mean(G * L)`` where
its level is, and a change of its own level by ``d`` changes what it reads by ``w d``
(``w < 1``: the share of its own signal the blur leaves in it). The level that explains
what it reads is therefore ``level + (gray - mean(G * L)) / w``; the triangles are labelled
once more with those grays.
"""
import numpy as np
from scipy import ndimage

from . import _threads
from ._level_changes import level_changes, level_changes_parallel
from ._validate import as_image, as_volume, check_number
from .errors import ParameterError
from .graph import connected_pieces
from .params import DEFAULTS, check
from .tetra_gray import VoxelOverlaps, tetra_gray, voxel_mean_of_tetrahedra  # noqa: F401 (example)
from .tetrahedra import tetra_volumes
from .triangle_gray import pixel_mean_of_triangles, triangle_gray
from .triangulation import triangle_areas

_FIT_SLICES = 64
"""A volume with at least twice this many slices is fitted on every ``nz // _FIT_SLICES``-th
slice: the one number fitted needs no more voxels, and each blur is computed on those
slices alone."""
_FIT_MIN_VOXELS = 100_000
"""Fewer band voxels than this on those slices (level changes between them only, as at
an interface across z): every slice is fitted."""


def _fit_slices(nz):
    """The slices (axis 0) of a volume whose band voxels the blur fit compares."""
    stride = max(1, nz // _FIT_SLICES)
    return np.arange(stride // 2, nz, stride)


def _blurred_slices(volume, sigma, slices):
    """``gaussian_filter(volume, sigma, mode="nearest")[slices]``, computed on those slices
    only (the Gaussian is separable: along axis 0 a weighted sum of nearby slices)."""
    radius = int(4.0 * sigma + 0.5)  # ndimage's kernel: truncate 4, normalised
    offsets = np.arange(-radius, radius + 1)
    weights = np.exp(-0.5 * (offsets / sigma) ** 2)
    weights /= weights.sum()
    out = np.zeros((len(slices),) + volume.shape[1:])
    for off, w in zip(offsets, weights):
        out += w * volume[np.clip(slices + off, 0, len(volume) - 1)]
    for axis in range(1, volume.ndim):
        out = ndimage.gaussian_filter1d(out, sigma, axis=axis, mode="nearest")
    return out


def region_levels(material, gray, area, adjacency):
    """Gray of each triangle's region: the area-weighted median gray of the connected
    triangles of its material it belongs to.

    The median ignores the region's edge triangles, which are mixed with the neighbours;
    a region's own value (not its material's level) keeps a region that reads darker
    than its material, such as the cap of a steel ball cut by the slice, from predicting
    a blur it does not cause.

    Parameters
    ----------
    material : (m,) int array_like
    gray : (m,) array_like
    area : (m,) array_like
    adjacency : (k, 2) int array_like
        Pairs of triangles sharing an edge.

    Returns
    -------
    (m,) float64 ndarray
    """
    material = np.asarray(material)
    gray = np.asarray(gray, float)
    area = np.asarray(area, float)
    adjacency = np.asarray(adjacency, np.int64).reshape(-1, 2)
    m = len(material)
    same = material[adjacency[:, 0]] == material[adjacency[:, 1]]
    a, b = adjacency[same, 0], adjacency[same, 1]
    _, region = connected_pieces(np.column_stack([a, b]), m)
    order = np.lexsort((gray, region))  # by region, then by gray
    reg, w = region[order], area[order]
    cum = np.cumsum(w)
    start = np.searchsorted(reg, reg, side="left")
    within = cum - np.where(start > 0, cum[start - 1], 0.0)  # cumulative area in the region
    # the first triangle of each region whose cumulative area reaches half the region's
    reached = np.flatnonzero(within >= 0.5 * np.bincount(reg, w)[reg])
    _, first = np.unique(reg[reached], return_index=True)
    return gray[order][reached[first]][region]


def level_image(points, triangles, level, shape):
    """Rasterise one gray level per triangle: each pixel takes the area-weighted mean of
    the levels of the triangles over it (partial coverage kept, as a scanner would see it).

    Parameters
    ----------
    points : (n, 2) array_like
        Mesh vertices (x, y) in pixel units.
    triangles : (m, 3) array_like
    level : (m,) array_like
        Gray of each triangle's material.
    shape : (rows, cols)

    Returns
    -------
    (rows, cols) float64 ndarray
        Pixels no triangle overlaps hold the nearest covered pixel's value.
    """
    level = np.asarray(level, float)
    if level.shape != (len(triangles),):
        raise ParameterError(f"level: expected one value per triangle ({len(triangles)}), "
                             f"got shape {level.shape}")
    out, covered = pixel_mean_of_triangles(level, points, triangles, shape)
    empty = covered <= 0
    if empty.any() and not empty.all():
        idx = ndimage.distance_transform_edt(empty, return_distances=False, return_indices=True)
        out = out[tuple(idx)]
    return out


def estimate_blur(image, levels_image, band_px=3, blur_max_px=DEFAULTS.blur_max_px):
    """Standard deviation (px) of the Gaussian that best turns a level image into the image.

    Minimises the mean squared difference between ``image`` and
    ``gaussian_filter(levels_image, s)`` over the pixels within ``band_px`` of a level
    change (elsewhere blur changes nothing and only noise is compared): a 0.5 px grid on
    [0, ``blur_max_px``], scanned upwards until the misfit has risen twice in a row past
    its smallest value (it has one minimum), then two parabola fits around its best point
    (to within about 0.02 px of a fine search on the simulated slices). A volume of
    ``nz >= 128`` slices is compared on every ``nz // 64``-th slice only, where those
    hold 100 000 band voxels or more.

    Parameters
    ----------
    image : (rows, cols) or (nz, ny, nx) array_like
        The slice or volume, in the same units as the levels.
    levels_image : array_like, the shape of ``image``
        What it would be without blur (:func:`level_image` of a labelling).
    band_px : int
        Half width of the band around level changes.
    blur_max_px : float
        Upper end of the search.

    Returns
    -------
    sigma : float
        In [0, blur_max_px]; 0 when the level image has no edge.

    Raises
    ------
    InputError
        If either image is not a finite 2D or 3D array.
    ParameterError
        If the shapes differ or ``band_px``, ``blur_max_px`` are out of range.
    """
    if np.ndim(image) == 3:  # a volume: the same fit with a 3D Gaussian (voxel units)
        img = as_volume(image).astype(np.float64, copy=False)
        lev = as_volume(levels_image, "levels_image").astype(np.float64, copy=False)
    else:
        img = as_image(image)
        lev = as_image(levels_image, "levels_image")
    if lev.shape != img.shape:
        raise ParameterError(f"levels_image: shape {lev.shape} differs from the image's {img.shape}")
    band_px = check_number(band_px, "band_px", low=1, integer=True)
    max_px = check("blur_max_px", blur_max_px)
    change = np.empty(lev.shape, bool)
    _threads.pick(level_changes, level_changes_parallel)(
        np.ascontiguousarray(lev).reshape((-1,) + lev.shape[-2:]), change.reshape((-1,) + lev.shape[-2:]))
    if not change.any():
        return 0.0
    band = ndimage.binary_dilation(change, iterations=band_px)
    slices = _fit_slices(len(lev)) if lev.ndim == 3 else None  # None: every slice, uncopied
    if slices is not None and (len(slices) == len(lev)
                               or np.count_nonzero(band[slices]) < _FIT_MIN_VOXELS):
        slices = None
    if slices is not None:
        band, img = band[slices], img[slices]
    target = img[band]

    seen = {}  # the first parabola's three points are grid points: blur each width once

    def fit(s):
        if slices is None:
            model = ndimage.gaussian_filter(lev, s, mode="nearest") if s > 0 else lev
        else:
            model = _blurred_slices(lev, s, slices) if s > 0 else lev[slices]
        return float(np.mean((target - model[band]) ** 2))

    def misfits(widths):  # the new ones side by side (ndimage releases the GIL)
        new = [float(s) for s in dict.fromkeys(widths) if float(s) not in seen]
        seen.update(zip(new, _threads.thread_map(fit, new)))
        return [seen[float(s)] for s in widths]

    def parabola(xs):  # vertex of the parabola through three equally spaced points
        c0, c1, c2 = misfits(xs)
        h = xs[1] - xs[0]
        curv = c0 - 2.0 * c1 + c2
        if curv <= 0:
            return xs[int(np.argmin([c0, c1, c2]))]
        return float(np.clip(xs[1] + 0.5 * h * (c0 - c2) / curv, xs[0], xs[2]))

    # a 0.5 px grid, then two parabola steps around its best point (the misfit is smooth,
    # with one minimum near the true blur): 10 blurs instead of a fine grid's 16. The grid
    # is scanned upwards, two widths at a time, and stops once the misfit has risen twice
    # in a row past its smallest value: the wide blurs, the slowest, are seldom needed
    grid = np.arange(0.0, max_px + 1e-9, 0.5)
    seen_grid, k = [], 0
    starts = [0] + list(range(3, len(grid), 2))  # width 0 needs no blur: three at first
    for lo, hi in zip(starts, starts[1:] + [len(grid)]):
        seen_grid += misfits(grid[lo:hi])
        k = int(np.argmin(seen_grid))
        if len(seen_grid) > k + 2 and seen_grid[k + 2] > seen_grid[k + 1] > seen_grid[k]:
            break
    k = min(max(k, 1), len(grid) - 2)
    v = parabola(grid[k - 1:k + 2])
    v = max(v, 0.1)
    return float(max(parabola(np.array([v - 0.1, v, v + 0.1])), 0.0))


def self_weight(points, triangles, sigma):
    """Share of a triangle's own signal that a Gaussian blur leaves inside it.

    ``1 - P sigma / (sqrt(2 pi) A)`` for perimeter P and area A: across a straight edge a
    Gaussian of standard deviation sigma carries ``sigma / sqrt(2 pi)`` per unit length
    out (exact for edges long against sigma; corners make it a slight overestimate of the
    loss). Negative for slivers thinner than the blur; callers put a floor under it.

    Parameters
    ----------
    points : (n, 2) array_like
    triangles : (m, 3) array_like
    sigma : float
        Blur standard deviation, px.

    Returns
    -------
    (m,) float64 ndarray
    """
    points = np.asarray(points, float)
    triangles = np.asarray(triangles, np.int64)
    p = points[triangles]
    perimeter = sum(np.hypot(*(p[:, (i + 1) % 3] - p[:, i]).T) for i in range(3))
    area = np.abs(triangle_areas(points, triangles))
    return 1.0 - perimeter * float(sigma) / (np.sqrt(2.0 * np.pi) * np.maximum(area, 1e-300))


def blur_corrected_gray(gray, points, triangles, level, image, sigma=None,
                        blur_min_self_weight=DEFAULTS.blur_min_self_weight,
                        blur_max_px=DEFAULTS.blur_max_px):
    """Triangle grays with the blur a labelling predicts taken off.

    ``level + (gray - mean_t(G_sigma * L)) / w``, where ``L = level_image(level)``,
    ``mean_t`` is the exact area-weighted mean over triangle t (as ``gray`` was measured)
    and ``w = max(self_weight, blur_min_self_weight)``. If the image is exactly ``G_sigma * L``,
    every triangle gets back its level.

    Parameters
    ----------
    gray : (m,) array_like
        Triangle mean grays (:func:`ctseg.triangle_gray`), the units of ``image``.
    points, triangles
        The mesh.
    level : (m,) array_like
        Level of each triangle's material in a first labelling.
    image : (rows, cols) array_like
        The slice the grays were measured on (for ``sigma``).
    sigma : float, optional
        Point-spread standard deviation (px); default :func:`estimate_blur`.
    blur_min_self_weight : float
        Floor of the self weight, in (0, 1] (1: no amplification): thin triangles' grays
        are noisy and their predicted blur least certain, so their deviation is amplified
        at most ``1 / blur_min_self_weight`` times.
    blur_max_px : float
        Largest point-spread sd :func:`estimate_blur` considers.

    Returns
    -------
    corrected : (m,) ndarray
    sigma : float
        The standard deviation used.

    Example
    -------
    >>> import numpy as np
    >>> from scipy import ndimage
    >>> from ctseg import delaunay_mesh, triangle_gray
    >>> ys, xs = np.mgrid[0:33:4, 0:33:4]
    >>> mesh = delaunay_mesh(np.column_stack([xs.ravel(), ys.ravel()]).astype(float))
    >>> cx = mesh.points[mesh.triangles].mean(axis=1)[:, 0]
    >>> level = np.where(cx < 16, 0.0, 100.0)
    >>> image = ndimage.gaussian_filter(level_image(mesh.points, mesh.triangles, level, (33, 33)), 1.0)
    >>> gray = triangle_gray(image, mesh.points, mesh.triangles)
    >>> fixed, sigma = blur_corrected_gray(gray, mesh.points, mesh.triangles, level, image, sigma=1.0)
    >>> bool(np.allclose(fixed, level))
    True
    """
    img = as_image(image)
    min_self_weight = check("blur_min_self_weight", blur_min_self_weight)
    gray = np.asarray(gray, float)
    if gray.shape != (len(triangles),):
        raise ParameterError(f"gray: expected one value per triangle ({len(triangles)}), "
                             f"got shape {gray.shape}")
    lev = level_image(points, triangles, level, img.shape)
    if sigma is None:
        sigma = estimate_blur(img, lev, blur_max_px=blur_max_px)
    sigma = check_number(sigma, "sigma", low=0.0)
    blurred = ndimage.gaussian_filter(lev, sigma, mode="nearest") if sigma > 0 else lev
    predicted = triangle_gray(blurred, points, triangles)
    w = np.maximum(self_weight(points, triangles, sigma), min_self_weight)
    return np.asarray(level, float) + (gray - predicted) / w, float(sigma)


def self_weight_3d(points, tetrahedra, sigma):
    """Share of a tetrahedron's own signal that a Gaussian blur leaves inside it:
    ``1 - S sigma / (sqrt(2 pi) V)`` for surface area S and volume V (the 2D rule of
    :func:`self_weight` one dimension up; all in voxel units)."""
    points = np.asarray(points, float)
    p = points[np.asarray(tetrahedra, np.int64)]
    # edges from vertex 0 serve three faces (one gather, not one per face)
    e1, e2, e3 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    twice_area = (np.linalg.norm(np.cross(p[:, 2] - p[:, 1], p[:, 3] - p[:, 1]), axis=1)
                  + np.linalg.norm(np.cross(e3, e2), axis=1)
                  + np.linalg.norm(np.cross(e1, e3), axis=1)
                  + np.linalg.norm(np.cross(e1, e2), axis=1))
    vol = np.abs(tetra_volumes(points, tetrahedra))
    return 1.0 - 0.5 * twice_area * float(sigma) / (np.sqrt(2.0 * np.pi) * np.maximum(vol, 1e-300))


def blur_corrected_gray_3d(gray, points, tetrahedra, level, volume, spacing=(1.0, 1.0, 1.0),
                           sigma=None, blur_min_self_weight=DEFAULTS.blur_min_self_weight,
                           blur_max_px=DEFAULTS.blur_max_px, overlaps=None):
    """Tetrahedron grays with the blur a labelling predicts taken off: the rule of
    :func:`blur_corrected_gray` in 3D, with :func:`ctseg.tetra_gray.voxel_mean_of_tetrahedra`
    (:meth:`ctseg.tetra_gray.VoxelOverlaps.voxel_mean`) for the level volume, a Gaussian
    in voxel units and :func:`self_weight_3d`.

    Parameters
    ----------
    gray : (m,) array_like
        Tetrahedron mean grays, the units of ``volume``.
    points, tetrahedra
        The mesh, points in physical units (index x spacing).
    level : (m,) array_like
    volume : (nz, ny, nx) array_like
    spacing : (3,) array_like
    sigma, blur_min_self_weight, blur_max_px
        As in :func:`blur_corrected_gray`.
    overlaps : ctseg.tetra_gray.VoxelOverlaps, optional
        The mesh's voxel overlaps, if computed already (the same results, without
        clipping the tetrahedra twice more).

    Returns
    -------
    corrected : (m,) ndarray
    sigma : float
        Voxels.

    Example
    -------
    >>> from ctseg.tetrahedra import delaunay_tetrahedra
    >>> rng = np.random.default_rng(0)
    >>> c = np.array([[x, y, z] for x in (0, 15) for y in (0, 15) for z in (0, 15)], float)
    >>> mesh = delaunay_tetrahedra(np.vstack([c, rng.uniform(0, 15, (300, 3))]), (15, 15, 15))
    >>> level = np.where(mesh.points[mesh.tetrahedra].mean(axis=1)[:, 0] < 7, 0.0, 100.0)
    >>> sharp, _ = voxel_mean_of_tetrahedra(level, mesh.points, mesh.tetrahedra, (16, 16, 16))
    >>> vol = ndimage.gaussian_filter(sharp, 1.0, mode="nearest")
    >>> gray = tetra_gray(vol, mesh.points, mesh.tetrahedra)
    >>> fixed, s = blur_corrected_gray_3d(gray, mesh.points, mesh.tetrahedra, level, vol, sigma=1.0)
    >>> bool(np.allclose(fixed, level))
    True
    """
    vol = as_volume(volume).astype(np.float64, copy=False)
    sp = np.asarray(spacing, float)
    min_self_weight = check("blur_min_self_weight", blur_min_self_weight)
    gray = np.asarray(gray, float)
    if gray.shape != (len(tetrahedra),):
        raise ParameterError(f"gray: expected one value per tetrahedron ({len(tetrahedra)}), "
                             f"got shape {gray.shape}")
    if overlaps is None:
        overlaps = VoxelOverlaps(points, tetrahedra, vol.shape, sp)
    lev, _ = overlaps.voxel_mean(np.asarray(level, float))
    if sigma is None:
        sigma = estimate_blur(vol, lev, blur_max_px=blur_max_px)
    sigma = check_number(sigma, "sigma", low=0.0)
    blurred = ndimage.gaussian_filter(lev, sigma, mode="nearest") if sigma > 0 else lev
    predicted = overlaps.tetra_mean(blurred)
    w = np.maximum(self_weight_3d(np.asarray(points, float) / sp, tetrahedra, sigma), min_self_weight)
    return np.asarray(level, float) + (gray - predicted) / w, float(sigma)
