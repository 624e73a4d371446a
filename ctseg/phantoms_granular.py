"""Synthetic granular and porous media slices with known sub-pixel truth (benchmarks, tests).

Three kinds of microstructure, each a label map painted at ``supersample`` times the pixel
resolution (the conventions of :func:`ctseg.phantoms.make_phantom`: pixel (r, c) has its
centre at x = c, y = r; labels ascend with gray; ``truth`` is the per-pixel majority of
the supersampled ``truth_hr``):

- ``'sand'``: packed sand. Pores (label 0, dark) between irregular grains (label 1) that
  touch and overlap a little, a tenth of them a denser mineral (label 2, bright).
- ``'casting'``: a porous casting or metal foam. Metal (label 1) with round gas pores of
  2-15 px diameter and irregular shrinkage pores (thresholded smooth noise), both label 0,
  and small dense inclusions (label 2).
- ``'sintered'``: sintered powder. Round particles (label 1) overlapping at their necks,
  the pore space (label 0) between them.

The image is the materials' gray levels mixed by area fraction per pixel (partial volume),
each grain's gray varied a little (real grains differ), blurred by a Gaussian, plus
Gaussian noise; optionally mapped to 8 bits and clipped at 0 and 255. Grains are a few
pixels to a few tens of pixels across, so boundaries are everywhere: the gray histogram is
broad with a partial-volume plateau between the peaks and hardly any pixel lies in a flat
region. Everything is deterministic for a given ``seed``.
"""
import numpy as np
from scipy import ndimage

from .phantoms import Phantom, _downsample_fractions

KINDS = ("sand", "casting", "sintered")
"""The microstructures :func:`make_granular` paints."""

NAMES = {
    "sand": ("pore", "quartz", "heavy mineral"),
    "casting": ("pore", "metal", "inclusion"),
    "sintered": ("pore", "particle"),
}
"""Material names per kind, label k = NAMES[kind][k] (ascending gray)."""

LEVELS = {
    "sand": (0.15, 0.60, 0.95),
    "casting": (0.10, 0.60, 0.90),
    "sintered": (0.15, 0.75),
}
"""Gray level of each material (before blur and noise) on a 0-1 scale."""


def _hr_grid(shape, supersample):
    """Sub-pixel centre coordinates along rows and columns, in pixels of the final image."""
    ys = (np.arange(shape[0] * supersample) + 0.5) / supersample - 0.5
    xs = (np.arange(shape[1] * supersample) + 0.5) / supersample - 0.5
    return ys, xs


def _paint_blob(lab, ys, xs, cx, cy, r, value, harmonics=(), mask_out=None):
    """Paint a star-shaped blob ``r(theta) = r (1 + sum a_k cos(k theta + phi_k))`` into
    ``lab`` (in place, within its bounding box); ``harmonics`` is a list of (k, a_k, phi_k).
    Returns the (row slice, col slice, mask) painted."""
    amp = 1.0 + sum(abs(a) for _, a, _ in harmonics)
    r_max = r * amp + 1.0
    i0 = max(0, int(np.searchsorted(ys, cy - r_max)))
    i1 = min(len(ys), int(np.searchsorted(ys, cy + r_max)) + 1)
    j0 = max(0, int(np.searchsorted(xs, cx - r_max)))
    j1 = min(len(xs), int(np.searchsorted(xs, cx + r_max)) + 1)
    if i0 >= i1 or j0 >= j1:
        return None
    dy = ys[i0:i1, None] - cy
    dx = xs[None, j0:j1] - cx
    rho = np.hypot(dx, dy)
    radius = np.full(rho.shape, float(r))
    if harmonics:
        theta = np.arctan2(dy, dx)
        radius = radius * (1.0 + sum(a * np.cos(k * theta + ph) for k, a, ph in harmonics))
    mask = rho <= radius
    lab[i0:i1, j0:j1][mask] = value
    return (slice(i0, i1), slice(j0, j1), mask)


def _place_grains(rng, shape, r_mean, r_sd, target_fraction, min_gap_factor, r_min):
    """Random sequential placement of grain centres and radii: a candidate is kept when no
    kept grain's centre is nearer than ``min_gap_factor`` times the two radii summed (so
    grains overlap by at most ``1 - min_gap_factor``), until the discs' summed area
    reaches ``target_fraction`` of the image or the candidates run out (a jammed packing).
    Neighbours are looked up in a grid of cells of the largest diameter."""
    rows, cols = shape
    area = rows * cols
    n_try = int(40 * area / (np.pi * r_mean ** 2)) + 200
    radii_c = np.maximum(r_min, rng.normal(r_mean, r_sd, n_try))
    r_top = float(radii_c.max())
    xs_c = rng.uniform(-r_top / 2, cols - 1 + r_top / 2, n_try)
    ys_c = rng.uniform(-r_top / 2, rows - 1 + r_top / 2, n_try)
    cell = 2.0 * r_top
    grid = {}
    centres, radii = [], []
    covered = 0.0
    for cx, cy, r in zip(xs_c, ys_c, radii_c):
        if covered >= target_fraction * area:
            break
        gi, gj = int(np.floor(cy / cell)), int(np.floor(cx / cell))
        ok = True
        for a in (gi - 1, gi, gi + 1):
            for b in (gj - 1, gj, gj + 1):
                for k in grid.get((a, b), ()):
                    (qx, qy), q = centres[k], radii[k]
                    if (qx - cx) ** 2 + (qy - cy) ** 2 < (min_gap_factor * (q + r)) ** 2:
                        ok = False
                        break
                if not ok:
                    break
            if not ok:
                break
        if not ok:
            continue
        grid.setdefault((gi, gj), []).append(len(centres))
        centres.append((float(cx), float(cy)))
        radii.append(float(r))
        covered += np.pi * r * r
    return np.asarray(centres).reshape(-1, 2), np.asarray(radii)


def _harmonics(rng, strength):
    """Random shape harmonics (k = 2, 3, 4) of a grain outline."""
    return [(k, rng.uniform(0.0, strength) / (k - 1), rng.uniform(0, 2 * np.pi)) for k in (2, 3, 4)]


def _smooth_noise_hr(rng, shape, supersample, corr_px):
    """Smooth Gaussian noise (correlation ``corr_px`` pixels) sampled at sub-pixel
    resolution: made on the pixel grid, smoothed, then interpolated (cubic) so its level
    sets are smooth curves at the sub-pixel scale. Normalised to unit standard deviation."""
    field = ndimage.gaussian_filter(rng.standard_normal(shape), corr_px, mode="wrap")
    field = (field - field.mean()) / max(field.std(), 1e-12)
    ys, xs = _hr_grid(shape, supersample)
    yy, xx = np.meshgrid(ys, xs, indexing="ij")
    return ndimage.map_coordinates(field, [yy, xx], order=3, mode="nearest")


def granular_labels(kind, shape, seed, supersample=4, grain_scale=1.0):
    """Paint the supersampled label map of one microstructure (see the module docstring).

    Parameters
    ----------
    kind : {'sand', 'casting', 'sintered'}
    shape : (rows, cols)
        Size of the final image in pixels; grain sizes are in pixels and do not scale
        with it.
    seed : int
        Seed of the random placement.
    supersample : int, optional
        Sub-pixels per pixel side of the label map.
    grain_scale : float, optional
        Multiplies every grain and pore size (1: sand grains about 13 px across,
        sintered particles 14 px, gas pores 2-15 px).

    Returns
    -------
    labels_hr : (rows * s, cols * s) uint8 ndarray
    grain_id : (rows * s, cols * s) int32 ndarray
        Which grain (1..) or pore object painted each sub-pixel last; 0 for the background.
    """
    if kind not in KINDS:
        raise ValueError(f"kind: {kind!r} is not one of {KINDS}")
    rng = np.random.default_rng([seed, KINDS.index(kind)])
    rows, cols = int(shape[0]), int(shape[1])
    ys, xs = _hr_grid((rows, cols), supersample)
    n_r, n_c = len(ys), len(xs)
    gid = np.zeros((n_r, n_c), np.int32)
    g = float(grain_scale)
    if kind == "sand":
        lab = np.zeros((n_r, n_c), np.uint8)  # pore background
        centres, radii = _place_grains(rng, (rows, cols), r_mean=6.5 * g, r_sd=2.0 * g,
                                       target_fraction=0.95, min_gap_factor=0.80, r_min=2.0 * g)
        for k, ((cx, cy), r) in enumerate(zip(centres, radii), start=1):
            value = 2 if rng.random() < 0.1 else 1
            hit = _paint_blob(lab, ys, xs, cx, cy, r, value, _harmonics(rng, 0.25))
            if hit is not None:
                gid[hit[0], hit[1]][hit[2]] = k
    elif kind == "sintered":
        lab = np.zeros((n_r, n_c), np.uint8)
        centres, radii = _place_grains(rng, (rows, cols), r_mean=7.0 * g, r_sd=1.4 * g,
                                       target_fraction=1.1, min_gap_factor=0.70, r_min=3.0 * g)
        for k, ((cx, cy), r) in enumerate(zip(centres, radii), start=1):
            hit = _paint_blob(lab, ys, xs, cx, cy, r, 1, _harmonics(rng, 0.06))
            if hit is not None:
                gid[hit[0], hit[1]][hit[2]] = k
    else:  # casting
        lab = np.ones((n_r, n_c), np.uint8)  # metal
        # irregular shrinkage pores: the low tail of smooth noise
        noise = _smooth_noise_hr(rng, (rows, cols), supersample, corr_px=4.0 * g)
        lab[noise < -1.2] = 0
        # round gas pores, 2-15 px in diameter, more small ones than large ones
        area = rows * cols
        n_pores = int(area / (110 * g * g))
        for _ in range(n_pores):
            r = g * float(np.clip(rng.lognormal(np.log(2.6), 0.55), 1.0, 7.5))
            cx, cy = rng.uniform(0, cols - 1), rng.uniform(0, rows - 1)
            _paint_blob(lab, ys, xs, cx, cy, r, 0, _harmonics(rng, 0.08))
        # dense inclusions (oxides, intermetallics): small blobs inside the metal
        for k in range(1, int(area / (900 * g * g)) + 1):
            r = g * rng.uniform(1.5, 4.0)
            cx, cy = rng.uniform(0, cols - 1), rng.uniform(0, rows - 1)
            i = min(n_r - 1, max(0, int(round((cy + 0.5) * supersample - 0.5))))
            j = min(n_c - 1, max(0, int(round((cx + 0.5) * supersample - 0.5))))
            if lab[i, j] == 1:
                hit = _paint_blob(lab, ys, xs, cx, cy, r, 2, _harmonics(rng, 0.3))
                if hit is not None:
                    gid[hit[0], hit[1]][hit[2]] = k
    return lab, gid


def make_granular(kind, size, seed, supersample=4, noise=0.03, blur_px=0.8,
                  grain_spread=0.02, grain_scale=1.0, clip8=False):
    """A granular or porous slice with its sub-pixel truth (see the module docstring).

    Parameters
    ----------
    kind : {'sand', 'casting', 'sintered'}
        The microstructure.
    size : int or (rows, cols)
        Image size in pixels (200 to 512 a side are the intended sizes; any >= 16 works).
    seed : int
        The phantom is a function of (kind, size, seed, the other arguments).
    supersample : int, optional
        Sub-pixels per pixel side of the truth.
    noise : float, optional
        Standard deviation of the Gaussian noise on the 0-1 gray scale of :data:`LEVELS`.
    blur_px : float, optional
        Standard deviation of the Gaussian blur (the scanner's point spread), pixels.
    grain_spread : float, optional
        Standard deviation of the gray of each grain (sand, sintered) or inclusion about
        its material's level, on the same scale.
    grain_scale : float, optional
        Multiplies every grain and pore size (see :func:`granular_labels`).
    clip8 : bool, optional
        Map the gray to 8 bits, the pores' level to 5 and the densest material's to 230,
        so the noise of the pores clips at 0; round and return uint8 (as an 8-bit export
        of a scan would).

    Returns
    -------
    ctseg.phantoms.Phantom
        ``image`` (float32, or uint8 with ``clip8``), ``truth`` (per-pixel majority
        labels), ``truth_hr`` (supersampled labels), ``supersample``, ``names``
        (:data:`NAMES`), ``pixel_mm`` (nominal 0.02 mm).

    Raises
    ------
    ValueError
        An unknown ``kind`` or a size under 16 pixels.

    Example
    -------
    >>> p = make_granular("sand", 64, seed=3)
    >>> p.image.shape, p.truth_hr.shape, p.names
    ((64, 64), (256, 256), ('pore', 'quartz', 'heavy mineral'))
    """
    shape = (int(size), int(size)) if np.ndim(size) == 0 else (int(size[0]), int(size[1]))
    if min(shape) < 16:
        raise ValueError(f"size: {shape} is too small; use at least 16 pixels a side")
    lab, gid = granular_labels(kind, shape, seed, supersample, grain_scale)
    levels = np.asarray(LEVELS[kind], float)
    rng = np.random.default_rng([seed, KINDS.index(kind), 1])
    hr_gray = levels[lab]
    if grain_spread > 0 and gid.max() > 0:
        offsets = np.concatenate([[0.0], rng.normal(0.0, grain_spread, int(gid.max()))])
        inside = (gid > 0) & (lab > 0)
        hr_gray[inside] += offsets[gid[inside]]
    s = supersample
    gray = hr_gray.reshape(shape[0], s, shape[1], s).mean(axis=(1, 3))  # partial volume
    if blur_px > 0:
        gray = ndimage.gaussian_filter(gray, blur_px, mode="nearest")
    gray = gray + noise * rng.standard_normal(shape)
    if clip8:
        image = np.clip(np.round(_to8(gray, kind)), 0, 255).astype(np.uint8)
    else:
        image = gray.astype(np.float32)
    frac = _downsample_fractions_rect(lab, s, len(levels))
    truth = np.argmax(frac, axis=0).astype(np.uint8)
    return Phantom(image=image, truth=truth, truth_hr=lab, supersample=s,
                   names=NAMES[kind], pixel_mm=0.02)


def _to8(gray, kind):
    """The 8-bit map of ``clip8``: the pores' level to 5, the densest material's to 230."""
    lv = LEVELS[kind]
    return 5.0 + 225.0 * (np.asarray(gray, float) - lv[0]) / (lv[-1] - lv[0])


def image_levels(kind, clip8=False):
    """The materials' gray levels in the units of :func:`make_granular`'s image (for
    ``gray_levels=`` when the mesh is to be judged apart from the level finding).

    Example
    -------
    >>> image_levels("sintered", clip8=True)
    (5.0, 230.0)
    """
    lv = LEVELS[kind]
    return tuple(round(float(v), 6) for v in (_to8(lv, kind) if clip8 else lv))


def _downsample_fractions_rect(lab_hr, s, n_labels):
    """Area fraction of each label per pixel, for any (not only square) shape."""
    if lab_hr.shape[0] == lab_hr.shape[1]:
        return _downsample_fractions(lab_hr, s, n_labels)
    r, c = lab_hr.shape[0] // s, lab_hr.shape[1] // s
    return np.stack([(lab_hr == k).reshape(r, s, c, s).mean(axis=(1, 3)) for k in range(n_labels)])


def flat_fraction(image, window_px=5):
    """Share of the pixels that lie in a flat region: over the ``window_px`` square round
    the pixel, the gray range of the 3 x 3 median-filtered image is under a quarter of the
    image's contrast (its 1st-99th percentile span).

    A measure of how hard a slice is for level finding from flat regions: a simulated
    machined part (:func:`ctseg.phantoms.make_phantom`) is about 0.9 flat, the granular
    slices of this module much less.

    Example
    -------
    >>> import numpy as np
    >>> img = np.zeros((40, 40)); img[:, 20:] = 1.0
    >>> round(flat_fraction(img), 2)
    0.9
    """
    img = np.asarray(image, float)
    lo, hi = np.percentile(img, [1, 99])
    if hi <= lo:
        return 1.0
    med = ndimage.median_filter(img, size=3, mode="nearest")
    span = (ndimage.maximum_filter(med, size=window_px, mode="nearest")
            - ndimage.minimum_filter(med, size=window_px, mode="nearest"))
    return float(np.mean(span < 0.25 * (hi - lo)))
