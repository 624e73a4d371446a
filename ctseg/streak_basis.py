"""The shapes of the metal streak artifact and their least-squares weights.

The basis images of :mod:`ctseg.beam_hardening`: FBP of powers and products of the
parallel-beam path lengths through the metal (and through the other materials), computed on
a coarser grid and interpolated back, and the closed-form fit of their weights that makes
each material's pixels flattest. Split from :mod:`ctseg.beam_hardening` (which re-exports
these names) to keep each module short.
"""
import numpy as np
from scipy import ndimage

from ._reduce import dot
from ._validate import check_number
from .errors import ParameterError
from .params import DEFAULTS, CorrectionParams
from .projection import filtered_backprojection, forward_project

# The basis is computed on an image no larger than this (block-averaged metal fraction,
# result interpolated back), so it costs about 0.2 s per slice whatever the slice's size.
# On the simulated 512 px slices a 256 px basis corrected as well as a full-size one
# (polymer Dice 0.975-0.992 against 0.975-0.989 on seeds 0-8) in 0.15 s instead of 0.45 s.
BASIS_MAX_PX = 256

# The polynomial model's higher terms are computed on a grid no larger than this: they only
# bend the main term, and at 128 px the whole model costs 1.5x the square one (0.23 s against
# 0.15 s) where 256 px cost 4x for the same Dice on the fan-beam multi-insert plates.
EXTRA_MAX_PX = 128


def metal_streak_basis(metal, n_angles=None):
    """The shape of the beam-hardening artifact of a metal mask: FBP of squared path lengths.

    Parameters
    ----------
    metal : (rows, cols) array_like of bool or float
        Metal mask, or metal fraction per pixel in [0, 1].
    n_angles : int, optional
        Parallel-beam projections over 180 degrees; default the larger image side (capped
        with the resolution at :data:`BASIS_MAX_PX`).

    Returns
    -------
    basis : (rows, cols) float64 ndarray
        ``FBP(L^2)`` with L in pixels of ``metal``, scaled by ``1 / max(rows, cols)`` so its
        size does not grow with the image.

    References
    ----------
    Park, Choi and Seo 2016 (see the module docstring).
    """
    m = np.asarray(metal, float)
    if m.ndim != 2:
        raise ParameterError(f"metal: expected a 2D mask, got shape {m.shape}")
    shape = m.shape
    step = int(np.ceil(max(shape) / BASIS_MAX_PX))
    m = _coarse(m, step)  # block means, padding with no metal
    n = max(m.shape)
    if n_angles is None:
        n_angles = n
    n_angles = check_number(n_angles, "n_angles", low=1, integer=True)
    angles = np.linspace(0.0, np.pi, n_angles, endpoint=False)
    path = forward_project(m, angles)
    return _refine(filtered_backprojection(path ** 2, angles, m.shape) / n, shape, step)


STREAK_MODELS = CorrectionParams.spec("streak_model").choices
"""Terms of the artifact model: ``square`` is ``L^2`` alone; ``polynomial`` adds ``L^3``
and ``L * P`` (P the path through the other, non-air materials); ``halo`` adds a glow
around the metal (:func:`halo_basis`) to the polynomial terms."""


def _coarse(m, step):
    """Block means of ``m`` over ``step`` x ``step`` pixels, padding with zeros."""
    if step == 1:
        return m
    ry, rx = -(-m.shape[0] // step), -(-m.shape[1] // step)
    pad = np.zeros((ry * step, rx * step))
    pad[:m.shape[0], :m.shape[1]] = m
    return pad.reshape(ry, step, rx, step).mean(axis=(1, 3))


def _refine(basis, shape, step, at=None):
    """Linear interpolation of a coarse map back onto the full ``shape`` (or onto the
    pixels of flat indices ``at`` only)."""
    if at is not None:
        rows, cols = np.unravel_index(np.asarray(at, np.int64), shape)
    else:
        rows, cols = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
    if step == 1:
        return basis[rows, cols] if at is not None else basis
    # coarse pixel centres sit at (i + 0.5) * step - 0.5 in fine pixels
    grid = [(rows + 0.5) / step - 0.5, (cols + 0.5) / step - 0.5]
    return ndimage.map_coordinates(basis, grid, order=1, mode="nearest")


def streak_bases(metal, other=None, model=DEFAULTS.streak_model, n_angles=None):
    """The artifact's shapes: FBP of the model's terms in the metal path length L.

    Parameters
    ----------
    metal : (rows, cols) array_like of bool or float
        Metal mask, or metal fraction per pixel in [0, 1].
    other : (rows, cols) array_like of bool or float, optional
        The other non-air materials (mask or fraction); needed by ``polynomial``.
    model : str
        One of :data:`STREAK_MODELS`. ``square``: ``FBP(L^2)`` (as
        :func:`metal_streak_basis`). ``polynomial``: also ``FBP(L^3)`` (the hardening
        levels off on long metal paths) and ``FBP(L P)``, P the path through ``other``
        (a ray through metal *and* a long stretch of plate hardens more than either alone:
        the bands along a row of inserts in a plate). ``halo`` gives the polynomial
        bases (its glow is :func:`halo_basis`, fitted apart).
    n_angles : int, optional
        As in :func:`metal_streak_basis`.

    Returns
    -------
    bases : list of (rows, cols) float64 ndarray
        ``FBP(L^2) / n`` first (:func:`metal_streak_basis`), then ``FBP(L^3) / n^2`` and
        ``FBP(L P) / n`` on a grid of at most :data:`EXTRA_MAX_PX` px (n its larger side,
        L and P in its pixels), so that each is of order one whatever the image size.

    Example
    -------
    >>> m = np.zeros((32, 32), bool); m[10:14, 8:12] = m[18:22, 20:24] = True
    >>> plate = np.zeros((32, 32), bool); plate[6:26, 4:28] = True; plate &= ~m
    >>> [b.shape for b in streak_bases(m, plate, model="polynomial")]
    [(32, 32), (32, 32), (32, 32)]
    """
    if model not in STREAK_MODELS:
        raise ParameterError(f"model: expected one of {STREAK_MODELS}, got {model!r}")
    m = np.asarray(metal, float)
    if m.ndim != 2:
        raise ParameterError(f"metal: expected a 2D mask, got shape {m.shape}")
    bases = [metal_streak_basis(m, n_angles=n_angles)]
    if model == "square":
        return bases
    if other is None:
        raise ParameterError("other: the polynomial model needs the other materials' mask")
    o = np.asarray(other, float)
    if o.shape != m.shape:
        raise ParameterError(f"other: shape {o.shape} differs from metal's {m.shape}")
    # the higher terms on a coarser grid (they only bend the main one: 3x cheaper)
    step = int(np.ceil(max(m.shape) / EXTRA_MAX_PX))
    mc, oc = _coarse(m, step), _coarse(o, step)
    n = max(mc.shape)
    k = n if n_angles is None else max(1, int(np.ceil(n_angles * n / max(m.shape))))
    angles = np.linspace(0.0, np.pi, k, endpoint=False)
    path, plate = forward_project(mc, angles), forward_project(oc, angles)
    for term in (path ** 3 / n ** 2, path * plate / n):
        bases.append(_refine(filtered_backprojection(term, angles, mc.shape), m.shape, step))
    return bases


HALO_SIGMAS_PX = tuple(8.0 * 2.0 ** (k / 2.0) for k in range(6))
"""Widths (Gaussian sd, px: 8 to 45 in steps of sqrt 2) tried for the glow around the metal
(:func:`halo_basis`); the one that explains most is fitted. Narrower is edge blur, which
the blur correction takes off after the first labelling."""

HALO_MIN_GAIN = 1.0 / 3.0
"""The glow is kept only where it removes this share of the within-material variance the
model without it leaves: more than the polynomial terms' ``streak_min_gain``, since its
width is chosen too (at a fifth, it took 0.004 from a simulated slice without any glow)."""


def halo_basis(metal, sigma_px, at=None):
    """The glow around a metal part: its mask blurred by a wide Gaussian.

    Scatter and detector glare add a smooth bright (or dark) veil around dense parts that
    decays over tens of pixels; none of the path-length terms of :func:`streak_bases`
    makes it. Its shape is modelled as ``G_sigma * metal``, computed on a grid coarsened
    to about ``sigma_px / 2`` per pixel and interpolated back.

    Parameters
    ----------
    metal : (rows, cols) array_like of bool or float
    sigma_px : float
        Gaussian sd in pixels of ``metal``, > 0.
    at : (n,) int array_like, optional
        Flat pixel indices: the values there only (a fit on a sample of the pixels).

    Returns
    -------
    (rows, cols) float64 ndarray, or (n,) with ``at``
        The metal fraction within the Gaussian window, in [0, 1].

    Example
    -------
    >>> m = np.zeros((64, 64), bool); m[28:36, 28:36] = True
    >>> h = halo_basis(m, 8.0)
    >>> bool(h[32, 32] > h[32, 50] > h[32, 63] > 0)
    True
    """
    m = np.asarray(metal, float)
    if m.ndim != 2:
        raise ParameterError(f"metal: expected a 2D mask, got shape {m.shape}")
    sigma = check_number(sigma_px, "sigma_px", low=0.0, low_open=True)
    step = max(1, int(sigma // 2))  # linear interpolation is exact enough over sd / 2
    coarse = ndimage.gaussian_filter(_coarse(m, step), sigma / step, mode="constant")
    return _refine(coarse, m.shape, step, at)


def fit_streak_weights(image, bases, classes, mask):
    """Least-squares weights making ``image + sum_j w_j * bases[j]`` flattest per class.

    As :func:`fit_streak_weight` with several bases (closed form: the class means
    eliminated, then the normal equations of the centred columns).

    Parameters
    ----------
    image : (rows, cols) array_like
    bases : sequence of (rows, cols) array_like
    classes : (rows, cols) int array_like
    mask : (rows, cols) bool array_like

    Returns
    -------
    weights : (len(bases),) float64 ndarray
        Zeros when the bases do not vary over the fitted pixels.
    explained : float
        Share of the within-class variance of ``image`` the correction removes, in [0, 1].
    """
    cols = [np.asarray(b, float)[mask] for b in bases]
    return _fit_columns(np.asarray(image, float)[mask], cols, np.asarray(classes)[mask])[:2]


def _fit_columns(img, cols, k):
    """:func:`fit_streak_weights` on the fitted pixels' values (1D arrays), plus the
    weight of ``cols[0]`` alone closest to the whole fitted correction (the square
    model's weight of it, from the Gram matrix)."""
    nb = len(cols)
    if img.size == 0 or nb == 0:
        return np.zeros(nb), 0.0, 0.0
    k = k.astype(np.int64) - int(k.min())
    count = np.maximum(np.bincount(k), 1).astype(float)
    # unit scales first (gray values up to 1e300 must not overflow the sums of squares),
    # then the products of the class-centred columns from the raw ones: u.v minus the
    # class sums' products (no centred copies: 10x cheaper than building them)
    vecs, scales = [], np.ones(nb + 1)
    for j, v in enumerate([img] + list(cols)):
        s = np.abs(v).max()
        scales[j] = s if s > 0 else 1.0
        vecs.append(v / scales[j])
    sums = [np.bincount(k, v, minlength=count.size) for v in vecs]
    prod = np.array([[dot(u, v) - float((su * sv / count).sum()) for v, sv in zip(vecs, sums)]
                     for u, su in zip(vecs, sums)])
    ii, rhs, gram = prod[0, 0], prod[1:, 0], prod[1:, 1:]
    diag = np.diag(gram)
    if ii <= 0.0 or not np.any(diag > 1e-12 * np.abs(np.diag(prod)).max()):
        return np.zeros(nb), 0.0, 0.0
    coef = -np.linalg.lstsq(gram, rhs, rcond=None)[0]
    explained = float(np.clip(-float(rhs @ coef) / ii, 0.0, 1.0))
    weights = coef * scales[0] / scales[1:]
    # <sum_j w_j b_j, b_0> / <b_0, b_0> over the centred columns
    first = float(coef @ gram[:, 0]) / gram[0, 0] * scales[0] / scales[1] \
        if gram[0, 0] > 0 else 0.0
    return weights, explained, first


def fit_streak_weight(image, basis, classes, mask):
    """Least-squares weight w making ``image + w * basis`` flattest within each class.

    Minimises ``sum_k sum_{i in class k, mask} (image_i + w basis_i - mu_k)^2`` over w and
    the class means mu_k (closed form).

    Parameters
    ----------
    image, basis : (rows, cols) array_like
    classes : (rows, cols) int array_like
        Provisional material of each pixel.
    mask : (rows, cols) bool array_like
        Pixels that take part.

    Returns
    -------
    weight : float
        0.0 when the basis does not vary over the fitted pixels.
    explained : float
        Share of the within-class variance of ``image`` the correction removes, in [0, 1].
    """
    img = np.asarray(image, float)[mask]
    b = np.asarray(basis, float)[mask]
    k = np.asarray(classes)[mask]
    if img.size == 0:
        return 0.0, 0.0
    k = k.astype(np.int64) - int(k.min())
    count = np.maximum(np.bincount(k), 1).astype(float)
    b_c = b - (np.bincount(k, b) / count)[k]
    i_c = img - (np.bincount(k, img) / count)[k]
    # unit scales first: gray values up to 1e300 must not overflow the sums of squares
    s_b, s_i = np.abs(b_c).max(), np.abs(i_c).max()
    if s_b == 0.0 or s_i == 0.0:
        return 0.0, 0.0
    b_c, i_c = b_c / s_b, i_c / s_i
    bb, ib, ii = dot(b_c, b_c), dot(i_c, b_c), dot(i_c, i_c)
    return -ib / bb * (s_i / s_b), min(1.0, ib * ib / (bb * ii))
