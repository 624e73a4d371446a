"""Stage 1: the gradient density map that steers the CVT (paper 5.1, SPEC 1; in 3D SPEC 9.1),
and the flat pixels and voxels (away from edges) that measure the material levels."""
import numpy as np
from scipy import ndimage

from . import _gradient, _ramp, _threads
from ._validate import as_image, as_volume, check_spacing
from .errors import InputError
from .params import AUTO, DEFAULTS, check


SMALL_FEATURE_PX = 16
"""Edges (density at least half its range, 8-connected) whose bounding box is at most this
many pixels a side are a small closed feature's (a pin, a pore, a small grain) for
``density_small_boost``."""

SMALL_FEATURE_REACH_PX = 2
"""... and the pixels within this many steps (4-connected) of them are boosted too."""


def density_map(image, density_sigma_px=DEFAULTS.density_sigma_px,
                density_floor=DEFAULTS.density_floor,
                density_saturation=DEFAULTS.density_saturation,
                density_ridge=DEFAULTS.density_ridge,
                density_small_boost=DEFAULTS.density_small_boost):
    """Per-pixel density rho from the smoothed gradient magnitude.

    ``rho = floor + min(1, g / g_ref)`` with ``g = |grad(G_sigma * I)|``, sigma =
    ``density_sigma_px`` and floor = ``density_floor``. Large rho near
    material boundaries draws CVT sites there, so small triangles hug the boundaries; the
    floor keeps sites in flat regions. rho is uniform on each pixel (paper eq. 4).

    With ``density_saturation=1``, ``g_ref = max g`` (the paper's and SPEC 1's
    normalisation; with ``density_ridge=0`` this is the paper's map).
    On industrial scans this starves weak boundaries: a steel edge has ten to twenty times
    the gradient of a polymer/air or aluminium/air edge, so those edges get a density barely
    above the floor and few sites. The default ``'auto'`` saturates instead at
    ``g_ref = max(10 * median(g), 0.02 * max(g))``: the median gradient measures the noise
    (most pixels are inside a material), so every edge well above the noise gets the full
    density whatever its contrast. A number sets ``g_ref`` as a fraction of ``max(g)``.
    ``density_ridge > 0`` multiplies by ``(g / local max of g)**ridge`` over a (2 sigma + 1)-pixel
    window: each edge's density becomes a narrow ridge on the edge line, whatever its
    contrast, so the CVT puts one row of sites on the boundary instead of a band of
    sites across it (a band makes zig-zag triangles straddling the boundary).
    In 'auto' mode the noise gradient ``g_noise = 2 * median(g)`` is also subtracted,
    ``rho = floor + clip((g - g_noise) / (g_ref - g_noise), 0, 1)`` with
    ``g_ref = max(10 * g_noise, 0.02 * max(g))``, so that flat noisy regions fall back to
    the floor instead of drawing sites away from the boundaries.
    Last, the density of a small closed feature's edges (:data:`SMALL_FEATURE_PX`) and of
    the pixels :data:`SMALL_FEATURE_REACH_PX` around them is multiplied by
    ``density_small_boost``: a CVT's sites follow the square root of the density in 2D,
    so a pin or pore of radius 3 px, 19 px of edge, gets the 4-5 sites of any 19 px of
    edge, a pentagon; with 4, twice as many. Off by default (1).

    Parameters
    ----------
    image : (rows, cols) array_like
        Gray image (any units: the result is normalised).
    density_sigma_px : float, optional
        Standard deviation of the Gaussian pre-smoothing, in pixels (0 disables it).
    density_floor : float, optional
        Density added everywhere, > 0.
    density_saturation : 'auto' or float in (0, 1], optional
        How the gradient is normalised (see above).
    density_ridge : float, optional
        Exponent of the ridge sharpening (0 = off, the paper's map).
    density_small_boost : float, optional
        Multiplier of small closed features' density (1 = off).

    Returns
    -------
    rho : (rows, cols) float64 ndarray
        Values in [floor, floor + 1], up to ``density_small_boost`` times that on small
        features; a constant image gives ``floor`` everywhere.

    Raises
    ------
    InputError
        If the image is not a finite 2D numeric array of at least 2 x 2 pixels.
    ParameterError
        A parameter outside its range in :mod:`ctseg.params`.

    References
    ----------
    Yang et al. 2014, section 5.1 and eq. (4).

    Example
    -------
    >>> import numpy as np
    >>> img = np.zeros((32, 32)); img[:, 16:] = 100.0
    >>> rho = density_map(img)
    >>> bool(rho[:, 15:17].mean() > rho[:, :8].mean())
    True
    """
    rho = _gradient_density(image, density_sigma_px, density_floor, density_saturation, density_ridge)
    boost = check("density_small_boost", density_small_boost)
    return _boost_small_features(rho, density_floor, boost) if boost != 1.0 else rho


def _gradient_density(image, density_sigma_px, density_floor, density_saturation, density_ridge):
    """:func:`density_map` without the small features' boost (what the flat pixels see)."""
    img = as_image(image)
    sigma = check("density_sigma_px", density_sigma_px)
    floor = check("density_floor", density_floor)
    saturation = check("density_saturation", density_saturation)
    ridge = check("density_ridge", density_ridge)
    # Normalise first so that huge value ranges (1e30) cannot overflow the gradient.
    span = float(img.max() - img.min())
    if span == 0.0:
        return np.full(img.shape, floor)
    img = (img - img.min()) / span
    smooth = ndimage.gaussian_filter(img, sigma, mode="nearest") if sigma > 0 else img
    gy, gx = np.gradient(smooth)
    mag = np.hypot(gx, gy)
    return _rho_from_gradient(mag, floor, saturation, ridge, 2 * int(np.ceil(max(sigma, 0.5))) + 1)


def _boost_small_features(rho, floor, boost):
    """``rho`` with the small closed features' edges and surroundings multiplied by
    ``boost`` (:func:`density_map`)."""
    edge = rho - floor >= 0.5
    regions, n = ndimage.label(edge, np.ones((3, 3), bool))
    if n == 0:
        return rho
    small = np.zeros(n + 1, bool)
    small[1:] = [max(r.stop - r.start, c.stop - c.start) <= SMALL_FEATURE_PX
                 for r, c in ndimage.find_objects(regions)]
    near = small[regions]
    if not near.any():
        return rho
    near = ndimage.binary_dilation(near, iterations=SMALL_FEATURE_REACH_PX)
    out = rho.copy()
    out[near] *= boost
    return out


def _rho_from_gradient(mag, floor, saturation, ridge, size, scale=None):
    """The normalisation and ridge sharpening shared by the 2D and 3D maps: rho from the
    gradient magnitude ``mag``; ``size`` is the ridge window (an int or one per axis);
    ``scale``: :func:`_gradient_scale` of ``mag`` if the caller has it already."""
    if mag.max() == 0.0:
        return np.full(mag.shape, floor)
    g_noise, g_ref = _gradient_scale(mag, saturation) if scale is None else scale
    strength = np.clip((mag - g_noise) / (g_ref - g_noise), 0.0, 1.0)
    if ridge:
        local = ndimage.maximum_filter(mag, size=size, mode="nearest")
        strength = strength * (mag / np.maximum(local, 1e-300)) ** ridge
    return floor + strength


def _gradient_scale(mag, saturation):
    """(g_noise, g_ref) of a gradient magnitude map with a nonzero maximum: the noise
    gradient subtracted and the gradient that gets the full density (see
    :func:`density_map`)."""
    peak = float(mag.max())
    if saturation == AUTO:
        g_noise = 2.0 * float(np.median(mag))
        return g_noise, max(10.0 * g_noise, 0.02 * peak)
    return 0.0, saturation * peak


def density_volume(volume, spacing=(1.0, 1.0, 1.0), density_sigma_px=DEFAULTS.density_sigma_px,
                   density_floor=DEFAULTS.density_floor,
                   density_saturation=DEFAULTS.density_saturation,
                   density_ridge=DEFAULTS.density_ridge):
    """Per-voxel density rho of a volume: :func:`density_map`'s rule in 3D (SPEC 9.1).

    The volume is min-max normalised, smoothed by a Gaussian of physical standard
    deviation ``density_sigma_px`` times the smallest spacing (so sigma is
    ``density_sigma_px`` voxels along the finest axis and ``density_sigma_px * min(spacing)
    / spacing_axis`` voxels along each axis: the same physical blur in every direction);
    ``g`` is the gradient magnitude per physical unit (central differences with the
    spacings). Saturation (``'auto'``: noise ``g_noise = 2 median(g)`` subtracted, full
    density at ``max(10 g_noise, 0.02 max g)``; a number: that fraction of ``max g``), the
    floor and the ridge sharpening (``(g / local max of g)**ridge`` over a window of
    ``2 ceil(max(sigma_axis, 0.5)) + 1`` voxels along each axis) are those of
    :func:`density_map`. With spacing (1, 1, 1) each slice of a volume that is constant
    along z gets exactly what :func:`density_map` gives the slice, up to rounding.

    Parameters
    ----------
    volume : (nz, ny, nx) array_like
        Gray volume (any units: the result is normalised); voxel (k, j, i) is at
        (x, y, z) = (i sx, j sy, k sz).
    spacing : (3,) array_like, optional
        Voxel spacing (sx, sy, sz) along x, y, z, each > 0.
    density_sigma_px : float, optional
        Gaussian pre-smoothing in voxels of the finest axis (0 disables it).
    density_floor : float, optional
        Density added everywhere, > 0.
    density_saturation : 'auto' or float in (0, 1], optional
        How the gradient is normalised (see :func:`density_map`).
    density_ridge : float, optional
        Exponent of the ridge sharpening (0 = off).

    Returns
    -------
    rho : (nz, ny, nx) float64 ndarray
        Values in [floor, floor + 1]; a constant volume gives ``floor`` everywhere.

    Raises
    ------
    InputError
        If the volume is not a finite 3D numeric array with every side >= 2.
    ParameterError
        A bad spacing, or a parameter outside its range in :mod:`ctseg.params`.

    Example
    -------
    >>> import numpy as np
    >>> vol = np.zeros((8, 16, 16)); vol[:, :, 8:] = 100.0
    >>> rho = density_volume(vol, spacing=(0.5, 0.5, 1.5))
    >>> rho.shape, bool(rho[:, :, 7:9].mean() > rho[:, :, :4].mean())
    ((8, 16, 16), True)
    """
    vol, sp, sigma, floor, saturation, ridge = _checked_volume(
        volume, spacing, density_sigma_px, density_floor, density_saturation, density_ridge)
    span = float(vol.max() - vol.min())
    if span == 0.0:
        return np.full(vol.shape, floor)
    mag, size = _volume_gradient((vol - vol.min()) / span, sp, sigma)
    return _rho_from_gradient(mag, floor, saturation, ridge, size)


def _checked_volume(volume, spacing, density_sigma_px, density_floor, density_saturation,
                    density_ridge):
    """:func:`density_volume`'s arguments validated: (float64 volume, spacing, sigma,
    floor, saturation, ridge)."""
    if np.ndim(volume) != 3:
        raise InputError(f"volume: expected a 3D array (nz, ny, nx), got shape {np.shape(volume)}")
    return (as_volume(volume, min_side=2).astype(np.float64, copy=False), check_spacing(spacing),
            check("density_sigma_px", density_sigma_px), check("density_floor", density_floor),
            check("density_saturation", density_saturation), check("density_ridge", density_ridge))


def _volume_gradient(vol, sp, sigma):
    """The gradient magnitude of a volume smoothed by ``sigma`` voxels of the finest axis
    (:func:`density_volume`'s rule), and the ridge window (voxels along z, y, x)."""
    sigma_zyx = sigma * sp.min() / sp[::-1]  # voxels along z, y, x
    smooth = ndimage.gaussian_filter(vol, tuple(sigma_zyx), mode="nearest") if sigma > 0 else vol
    mag = np.empty(smooth.shape)
    _threads.pick(_gradient.gradient_magnitude, _gradient.gradient_magnitude_parallel)(
        np.ascontiguousarray(smooth), mag, float(sp[2]), float(sp[1]), float(sp[0]))
    return mag, tuple(2 * int(np.ceil(max(s, 0.5))) + 1 for s in sigma_zyx)


def flat_pixels(image, flat_sigma_px=DEFAULTS.flat_sigma_px, density_floor=DEFAULTS.density_floor,
                density_saturation=DEFAULTS.density_saturation):
    """Pixels away from material edges: the un-sharpened density below half its range.

    These pixels measure the material gray levels (:func:`ctseg.levels.material_levels`);
    the ridge sharpening of the density is left out because it thins the edge bands.

    Parameters
    ----------
    image : (rows, cols) array_like
    flat_sigma_px : float
        Smoothing of the gradient (as ``density_sigma_px`` in :func:`density_map`).
    density_floor, density_saturation
        As in :func:`density_map`.

    Returns
    -------
    flat : (rows, cols) bool ndarray

    Example
    -------
    >>> img = np.zeros((20, 20)); img[:, 10:] = 1.0
    >>> flat = flat_pixels(img)
    >>> bool(flat[:, 0].all()), bool(flat[:, 9:11].any())
    (True, False)
    """
    strength = _gradient_density(image, flat_sigma_px, density_floor, density_saturation, 0.0)
    return (strength - density_floor) < 0.5


def _flat_and_scale(smooth, floor, saturation):
    """One smoothed slice's flat pixels (:func:`flat_pixels`' rule) and the (noise, full
    density) gradients :func:`density_map` normalises its gradient with."""
    gy, gx = np.gradient(smooth)
    mag = np.hypot(gx, gy)
    if mag.max() == 0.0:
        return np.ones(mag.shape, bool), 0.0, np.inf
    scale = _gradient_scale(mag, saturation)  # a median: once per slice
    return (_rho_from_gradient(mag, floor, saturation, 0.0, 1, scale) - floor) < 0.5, *scale


def flat_voxels(stack, flat_sigma_px=DEFAULTS.flat_sigma_px, density_floor=DEFAULTS.density_floor,
                density_saturation=DEFAULTS.density_saturation, across=True):
    """Voxels of a stack of slices away from material edges: :func:`flat_pixels` in each
    slice and, with ``across``, away from ramps across the slices.

    A voxel of an interior slice k is on a ramp when its gray lies between those of the
    same pixel in slices k - 1 and k + 1 (both steps of one sign, each slice smoothed in
    plane by ``flat_sigma_px``) and the smaller step, less slice k's noise gradient, is at
    least half of slice k's full-density gradient (the in-plane rule of
    :func:`density_map`, applied to the steps along z). Such a voxel is partial volume
    between slices: a face parallel to the slices, blurred across two or three of them,
    looks flat in every slice yet has an intermediate gray. A sharp step (independently
    reconstructed slices, or a face on a slice boundary) has one small step and stays flat,
    and so do the first and last slices.

    Parameters
    ----------
    stack : (nz, rows, cols) array_like
        Consecutive slices.
    flat_sigma_px, density_floor, density_saturation
        As in :func:`flat_pixels`.
    across : bool, optional
        Also leave out the ramp voxels across the slices.

    Returns
    -------
    flat : (nz, rows, cols) bool ndarray

    Example
    -------
    >>> vol = np.zeros((6, 32, 32)); vol[4:, 8:24, 8:24] = 1.0
    >>> vol[3, 8:24, 8:24] = 0.5   # the block's lower face, blurred across slice 3
    >>> flat_voxels(vol)[:, 16, 16].tolist()
    [True, True, True, False, True, True]
    >>> flat_voxels(vol, across=False)[:, 16, 16].tolist()
    [True, True, True, True, True, True]
    """
    vol = np.asarray(stack, dtype=np.float64)
    sigma = check("flat_sigma_px", flat_sigma_px)
    floor = check("density_floor", density_floor)
    saturation = check("density_saturation", density_saturation)
    if vol.ndim != 3:
        raise InputError(f"stack: expected a 3D array (nz, rows, cols), got shape {vol.shape}")
    span = float(vol.max() - vol.min()) if vol.size else 0.0
    if span == 0.0:
        return np.ones(vol.shape, bool)
    vol = (vol - vol.min()) / span  # common units, so that huge ranges cannot overflow
    smooth = ndimage.gaussian_filter(vol, (0, sigma, sigma), mode="nearest") if sigma > 0 else vol
    flat = np.empty(vol.shape, bool)
    noise, full = np.empty(len(vol)), np.empty(len(vol))
    for k, sl in enumerate(smooth):
        flat[k], noise[k], full[k] = _flat_and_scale(sl, floor, saturation)
    if not across or len(vol) < 3:
        return flat
    _threads.pick(_ramp.clear_ramps, _ramp.clear_ramps_parallel)(
        np.ascontiguousarray(smooth), noise, full, flat)
    return flat
