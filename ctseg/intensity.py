"""Gray-value normalisation and noise estimation (SPEC conventions, SPEC 7 defaults)."""
import numpy as np
from scipy.ndimage import maximum_filter, minimum_filter

from ._validate import as_image
from .params import DEFAULTS

GRAY_MAX = 255.0

REGION_BEYOND_SHARE = 0.25
"""A region (a 3 x 3 square of pixels or more, within a slice) lying wholly further than this
share of the percentile span beyond a rescale percentile may move that end of the map
(:data:`RING_NEAR_SHARE`). Noise moves a material's 3 x 3 extremes by about a noise sd, far
less than this; hot pixels and streaks 1-2 px wide hold no such square."""

RING_NEAR_SHARE = 0.3
"""... it does where the pixels around it (2-4 px from it) lie within this share of the span
of the same percentile: then the map would clip the region onto the gray of the material
around it (a steel pin in aluminium, 0.1% of a slice: the pin at 255, the aluminium at
229), leaving it neither an edge for the density map nor a level of its own. About the
level separation at that end of the scale; a region whose surroundings lie further inside
keeps its clipped contrast (a steel part in air and polymer)."""


def _region_extremes(v, lo, hi):
    """The map's ends ``(lo, hi)`` moved to the regions beyond them that
    :data:`REGION_BEYOND_SHARE` and :data:`RING_NEAR_SHARE` ask for."""
    size = (1,) * (v.ndim - 2) + (3, 3)
    span = hi - lo
    ends = [lo, hi]
    for side, squares in ((0, -maximum_filter(-v, size=size)), (1, minimum_filter(v, size=size))):
        sign = 1.0 if side else -1.0
        core = sign * (squares - ends[side]) > REGION_BEYOND_SHARE * span
        if not core.any():
            continue
        region = maximum_filter(core, size=size)  # the squares' pixels
        ring = maximum_filter(region, size=(1,) * (v.ndim - 2) + (9, 9)) & \
            ~maximum_filter(region, size=(1,) * (v.ndim - 2) + (5, 5))
        if ring.any() and sign * (np.median(v[ring]) - ends[side]) > -RING_NEAR_SHARE * span:
            ends[side] = float(squares[core].max() if side else squares[core].min())
    return ends


def gray_scale(values, rescale_low_pct=DEFAULTS.rescale_low_pct,
               rescale_high_pct=DEFAULTS.rescale_high_pct):
    """The robust map of gray values onto [0, 255]: ``(offset, factor)``.

    ``offset`` is the ``rescale_low_pct`` percentile and ``255 / factor`` the span up to
    the ``rescale_high_pct`` percentile (the true extremes where those collapse). Works on any array,
    so one map can serve every slice of a volume. Where a 3 x 3 square of pixels in a slice
    lies wholly beyond a percentile by more than :data:`REGION_BEYOND_SHARE` of the span
    between them (a small dense insert, a small void) and the pixels around it lie within
    :data:`RING_NEAR_SHARE` of the span of that percentile (the map would clip it onto the
    material around it), that end of the map moves to the furthest such square's nearest
    value, so the region keeps its contrast.

    Parameters
    ----------
    values : array_like
        Finite gray values of any shape.
    rescale_low_pct, rescale_high_pct : float

    Returns
    -------
    offset, factor : float
        ``factor`` is 0 for constant values.
    """
    v = np.asarray(values, dtype=np.float64)
    lo, hi = np.percentile(v, [rescale_low_pct, rescale_high_pct])
    if hi <= lo:  # percentiles collapse: fall back on the true extremes
        lo, hi = float(v.min()), float(v.max())
    elif v.ndim >= 2 and min(v.shape[-2:]) >= 3:
        reach = REGION_BEYOND_SHARE * (hi - lo)
        if v.min() < lo - reach or v.max() > hi + reach:  # else no square can reach
            lo, hi = _region_extremes(v, lo, hi)
    if hi <= lo:
        return float(lo), 0.0
    return float(lo), float(GRAY_MAX / (hi - lo))


def rescale_gray(image, rescale_low_pct=DEFAULTS.rescale_low_pct,
                 rescale_high_pct=DEFAULTS.rescale_high_pct, scale=None):
    """Map gray values robustly onto [0, 255].

    The paper's energy constants (lambda = 70, beta = 0.286, theta) assume 8-bit gray values.
    CT data come as uint16, float or Hounsfield units, so every energy term is computed on
    this rescaled copy; reported gray values stay in the input's units.

    Parameters
    ----------
    image : (rows, cols) array_like
        Gray image in any numeric dtype.
    rescale_low_pct, rescale_high_pct : float
        Percentiles mapped to 0 and 255; values beyond them are clipped, so a few hot
        pixels or metal streaks do not squash the materials into a narrow band.
    scale : (offset, factor), optional
        A map found elsewhere (:func:`gray_scale` of a whole volume); replaces the
        percentiles of this image.

    Returns
    -------
    scaled : (rows, cols) float64 ndarray
        Values in [0, 255].
    scale : tuple of float
        ``(offset, factor)`` with ``scaled = clip((image - offset) * factor, 0, 255)``;
        ``factor`` is 0 for a constant image.

    Raises
    ------
    InputError
        If the image is not a finite 2D numeric array.
    """
    img = as_image(image)
    offset, factor = gray_scale(img, rescale_low_pct, rescale_high_pct) if scale is None else map(float, scale)
    if factor == 0.0:
        return np.zeros_like(img), (offset, 0.0)
    return np.clip((img - offset) * factor, 0.0, GRAY_MAX), (offset, factor)


def estimate_noise(image):
    """Robust standard deviation of the pixel noise.

    Uses the median absolute deviation of differences of horizontally and vertically
    adjacent pixels; material edges touch few pixel pairs, so the median ignores them.
    For white noise of standard deviation s the estimate is s (differences have variance
    2 s^2). Reconstructed CT noise is correlated between neighbours, so on a real scan this
    is a noise *scale* rather than the exact per-pixel standard deviation.

    Parameters
    ----------
    image : (rows, cols) array_like

    Returns
    -------
    sigma : float
        Noise scale in the image's units (0 for a noiseless piecewise-constant image).
    """
    img = as_image(image)
    d = np.concatenate([np.diff(img, axis=0).ravel(), np.diff(img, axis=1).ravel()])
    mad = np.median(np.abs(d - np.median(d)))
    return float(1.4826 * mad / np.sqrt(2.0))
