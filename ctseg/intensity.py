"""Gray-value normalisation and noise estimation (SPEC conventions, SPEC 7 defaults)."""
import numpy as np

from ._validate import as_image
from .params import DEFAULTS

GRAY_MAX = 255.0


def gray_scale(values, rescale_low_pct=DEFAULTS.rescale_low_pct,
               rescale_high_pct=DEFAULTS.rescale_high_pct):
    """The robust map of gray values onto [0, 255]: ``(offset, factor)``.

    ``offset`` is the ``rescale_low_pct`` percentile and ``255 / factor`` the span up to
    the ``rescale_high_pct`` percentile (the true extremes where those collapse). Works on any array,
    so one map can serve every slice of a volume.

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
