"""Material gray levels (SPEC 7's data-driven defaults): the modes of the gray histogram
of the pixels away from edges, on the 0-255 scale, for one slice or a stack of slices."""
import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter, minimum_filter, uniform_filter

from ._reduce import weighted_variance
from ._validate import as_image
from .density import density_map, flat_pixels, flat_voxels  # noqa: F401  (flat_pixels: re-exported)
from .geometry import slice_axis, volume_slice
from .intensity import gray_scale, rescale_gray
from .levels_auto import (FLAT_TRUST_FRACTION, clipped_extremes, level_report, level_sample,
                          low_gradient_pixels, otsu_candidates, otsu_levels, otsu_thresholds,
                          tail_levels)
from .levels_given import check_gray_levels, given_levels_255
from .params import AUTO, DEFAULTS, check

LEVEL_KEYS = ("gray_levels", "flat_sigma_px", "density_floor", "density_saturation", "merge_k", "merge_rel",
              "merge_floor_255", "merge_threshold_255", "level_min_fraction", "n_materials")
"""The parameters of :func:`material_levels`."""


def weighted_percentile(values, weights, q):
    """Percentile(s) q (0-100) of values weighted by weights (step-function inverse CDF)."""
    v, w = np.asarray(values, float), np.asarray(weights, float)
    # equal weights (voxels): the same cumulative sums unsorted, and the k-th smallest by
    # selection instead of a sort of millions of values
    equal = len(w) > 0 and np.all(w == w[0])
    o = None if equal else np.argsort(v, kind="stable")
    cw = np.cumsum(w if equal else w[o])
    cw /= cw[-1]
    idx = np.clip(np.searchsorted(cw, np.asarray(q, float) / 100.0, side="left"), 0, len(v) - 1)
    return np.partition(v, np.unique(idx))[idx] if equal else v[o][idx]


def weighted_spread(values, weights):
    """Standard deviation of the values between their weighted 1st and 99th percentiles.

    Trimmed rather than median-based: the spread of a whole material's triangle grays
    includes streaks and cupping, which a median absolute deviation would hide.
    """
    v, w = np.asarray(values, float), np.asarray(weights, float)
    lo, hi = weighted_percentile(v, w, [1.0, 99.0])
    keep = (v >= lo) & (v <= hi)
    return float(np.sqrt(weighted_variance(v[keep], w[keep]))) if keep.sum() >= 2 else 0.0


def material_modes(gray, area, bandwidth, min_area, separation, n_modes=None):
    """Material gray levels: the modes of the area-weighted histogram of triangle grays.

    The histogram (0.25 gray-level bins on 0-255) is smoothed with a Gaussian of
    ``bandwidth``. Neighbouring modes are merged, weakest first, while the valley between
    them is above half the lower peak (no real separation) or they are closer than
    ``separation(level)`` gray levels; a mode whose basin holds less than ``min_area`` is
    merged into the neighbour it is least separated from. With ``n_modes`` the weakest
    boundaries are merged until exactly that many modes remain, whatever the rules say;
    where the histogram shows fewer modes than that (no flat region separates them, as in
    granular and porous media), the classes of multi-level Otsu (:func:`otsu_thresholds`)
    are the modes.

    Returns
    -------
    means : (K,) ndarray
        Area-weighted mean gray of each mode's basin, ascending.
    edges : (K - 1,) ndarray
        Gray levels of the valleys between consecutive modes.
    """
    f = np.asarray(gray, float)
    w = np.asarray(area, float)
    bin_w = 0.25
    nb = int(255.0 / bin_w) + 1
    idx = np.clip(np.round(f / bin_w).astype(int), 0, nb - 1)
    hist = gaussian_filter1d(np.bincount(idx, w, nb), max(bandwidth, bin_w) / bin_w, mode="constant")
    interior = (hist[1:-1] > hist[:-2]) & (hist[1:-1] >= hist[2:])
    peaks = list(np.flatnonzero(interior) + 1)
    if hist[0] > hist[1]:
        peaks.insert(0, 0)
    if hist[-1] > hist[-2]:
        peaks.append(nb - 1)
    if not peaks:
        peaks = [int(np.argmax(hist))]
    cum = np.concatenate([[0.0], np.cumsum(np.bincount(idx, w, nb))])

    def valley(i):  # position of the minimum between peaks i and i+1
        a, b = peaks[i], peaks[i + 1]
        return a + int(np.argmin(hist[a:b + 1]))

    if n_modes is not None and len(peaks) < n_modes:
        # fewer separated modes than asked for (granular or porous media, all partial
        # volume): the classes of multi-level Otsu, which need only distinct values
        edges = otsu_thresholds(f, w, n_modes)
        basin = np.searchsorted(edges, f)
        return _basin_means(f, w, basin, [0.0] * n_modes), edges
    while len(peaks) > 1:
        vals = [valley(i) for i in range(len(peaks) - 1)]
        bounds = [0] + [v + 1 for v in vals] + [nb]
        mass = np.array([cum[bounds[k + 1]] - cum[bounds[k]] for k in range(len(peaks))])
        ratio = np.array([hist[vals[i]] / max(min(hist[peaks[i]], hist[peaks[i + 1]]), 1e-300)
                          for i in range(len(vals))])
        gap = np.array([(peaks[i + 1] - peaks[i]) * bin_w / separation(peaks[i + 1] * bin_w)
                        for i in range(len(vals))])
        # weakness of each boundary: high valley or small gap means no real separation
        weak = np.maximum(ratio / 0.5, 1.0 / np.maximum(gap, 1e-300))
        small = np.flatnonzero(mass < min_area)
        if n_modes is not None:
            if len(peaks) == n_modes:
                break
            i = int(np.argmax(weak))
        elif weak.max() >= 1.0:
            i = int(np.argmax(weak))
        elif len(small):
            k = int(small[np.argmin(mass[small])])
            cand = [i for i in (k - 1, k) if 0 <= i < len(vals)]
            i = max(cand, key=lambda j: weak[j])
        else:
            break
        keep = peaks[i] if hist[peaks[i]] >= hist[peaks[i + 1]] else peaks[i + 1]
        peaks[i:i + 2] = [keep]
    vals = [valley(i) for i in range(len(peaks) - 1)]
    edges = np.array([(v + 0.5) * bin_w for v in vals])
    basin = np.searchsorted(edges, f)
    return _basin_means(f, w, basin, [p * bin_w for p in peaks]), edges


def _basin_means(f, w, basin, empty):
    """Weighted mean of ``f`` in each basin k (``empty[k]`` where it holds nothing); one
    mask per basin."""
    means = np.empty(len(empty))
    for k in range(len(empty)):
        inside = basin == k
        means[k] = np.average(f[inside], weights=w[inside]) if inside.any() else empty[k]
    return means


def dominant_spread(values, weights):
    """Noise of a whole material: the spread of the values in the heaviest coarse mode."""
    coarse, cedges = material_modes(values, weights, 2.0, 0.0, lambda g: 8.0)
    basin = np.searchsorted(cedges, values)
    dom = basin == np.argmax(np.bincount(basin, weights, len(coarse)))
    return weighted_spread(values[dom], weights[dom]) if dom.sum() > 1 else 0.0


def pixel_material_levels(image255, flat, merge_k=DEFAULTS.merge_k,
                          merge_rel=DEFAULTS.merge_rel, merge_floor_255=DEFAULTS.merge_floor_255,
                          merge_threshold_255=DEFAULTS.merge_threshold_255,
                          level_min_fraction=DEFAULTS.level_min_fraction,
                          n_materials=DEFAULTS.n_materials):
    """Material gray levels from the pixels away from edges (SPEC 7's data-driven defaults):
    the modes of their 3 x 3-smoothed grays (:func:`material_modes`); with ``n_materials``
    'auto', only modes holding a core, a flat pixel whose 3 x 3 neighbours all lie in its
    mode (:func:`_has_core`; not on slices under 5 pixels a side, nor where no mode has
    one).

    Parameters
    ----------
    image255 : (rows, cols) or (n, rows, cols) array_like
        The image, or a stack of slices, on the 0-255 scale
        (:func:`ctseg.intensity.rescale_gray`).
    flat : bool array_like, the shape of ``image255``
        Pixels away from edges (e.g. where the density map is below half its range).
    merge_k, merge_rel, merge_floor_255 : float
        Separation rule of :func:`material_modes`: ``max(merge_floor_255, merge_k * sigma)
        + merge_rel * gray``, sigma the spread of the flat pixels of the dominant mode,
        smoothed over 3 x 3.
    merge_threshold_255 : float or 'auto'
        A fixed separation instead of that rule.
    level_min_fraction : float
        Share of the flat pixels a level must hold.
    n_materials : int or 'auto'
        Exactly this many levels (the least separated modes merged).

    Returns
    -------
    levels : (K,) ndarray, ascending
    sigma : float
        The noise used (0-255 scale).

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> img = np.where(np.arange(64)[None, :] < 32, 40.0, 200.0) + rng.normal(0, 2, (64, 64))
    >>> levels, sigma = pixel_material_levels(img, flat_pixels(img))
    >>> np.round(levels).tolist()
    [40.0, 200.0]
    """
    merge_k, merge_rel = check("merge_k", merge_k), check("merge_rel", merge_rel)
    merge_floor_255 = check("merge_floor_255", merge_floor_255)
    merge_threshold_255 = check("merge_threshold_255", merge_threshold_255)
    level_min_fraction = check("level_min_fraction", level_min_fraction)
    n_materials = check("n_materials", n_materials)
    n_modes = None if n_materials == AUTO else n_materials
    img = np.asarray(image255, float)
    # smooth within each slice only: neighbouring slices can be far apart
    img = uniform_filter(img, (1,) * (img.ndim - 2) + (3, 3), mode="nearest")
    flat = np.asarray(flat, bool)
    v = img[flat] if flat.sum() >= 16 else img.ravel()
    w = np.ones(len(v))
    sigma = dominant_spread(v, w)
    base = max(merge_floor_255, merge_k * sigma)
    if merge_threshold_255 == AUTO:
        separation = lambda g: base + merge_rel * g  # noqa: E731
    else:
        separation = lambda g: merge_threshold_255  # noqa: E731
    levels, edges = material_modes(v, w, max(sigma, 0.5),
                                   0.0 if n_modes else level_min_fraction * len(v), separation,
                                   n_modes=n_modes)
    if n_modes is None and len(levels) > 1 and min(img.shape[-2:]) >= 5:
        core = _has_core(img, flat, edges)
        levels = levels[core] if core.any() else levels  # none: too small to tell
    return levels, sigma


def _has_core(img, flat, edges):
    """Which modes hold a core: a flat pixel whose 3 x 3 neighbours (in its slice) all lie in
    its mode. The 3 x 3 mean of pixels along a sharp edge between two materials falls a third
    and two thirds of the way between them, and on a low-noise image those bands make modes
    of their own; they are one or two pixels wide, a material is not."""
    basin = np.searchsorted(edges, img)
    size = (1,) * (img.ndim - 2) + (3, 3)
    core = flat & (minimum_filter(basin, size, mode="nearest") == maximum_filter(basin, size, mode="nearest"))
    return np.bincount(basin[core], minlength=len(edges) + 1) > 0


def material_levels(images, scale, *, gray_levels=DEFAULTS.gray_levels,
                    flat_sigma_px=DEFAULTS.flat_sigma_px, density_floor=DEFAULTS.density_floor,
                    density_saturation=DEFAULTS.density_saturation, merge_k=DEFAULTS.merge_k,
                    merge_rel=DEFAULTS.merge_rel, merge_floor_255=DEFAULTS.merge_floor_255,
                    merge_threshold_255=DEFAULTS.merge_threshold_255,
                    level_min_fraction=DEFAULTS.level_min_fraction, n_materials=DEFAULTS.n_materials,
                    report=None, volume=False):
    """Material gray levels (0-255 scale) seen in one slice or in a stack of slices
    (``volume``: consecutive slices, whose low-gradient pixels see the 3D gradient).

    The modes of the histogram of the pixels away from edges
    (:func:`pixel_material_levels` on :func:`flat_pixels`). Given a stack, the pixels of
    all its slices count together, so every slice of a volume is labelled against the
    same levels and material numbers agree across slices; with ``volume`` the voxels on a
    ramp across the slices (a face parallel to them) are not flat either
    (:func:`ctseg.density.flat_voxels`).

    Three rules beyond that (only the last can change a scan whose flat pixels can be
    trusted and whose data are not clipped):

    * Clipped data (:func:`clipped_extremes`): the voxels at a clipped extreme are a
      material of their own, at their gray: that gray replaces every level found within
      ``max(merge_floor_255, merge_k * sigma)`` of it (the clipped material's unclipped
      tail), or is added; with ``n_materials`` it counts as one of them.
    * Untrusted flat pixels: when they are fewer than 16, or at least
      :data:`FLAT_TRUST_FRACTION` of all pixels (the density map found no edges, as on
      granular and porous scans where nearly every pixel is partial volume), or when they
      give a single level (n_materials 'auto' only), the levels are instead the modes, by
      the same rule (separation ``max(merge_floor_255, merge_k * sigma) + merge_rel *
      gray``, valley below half the lower peak, ``level_min_fraction``), of the
      low-gradient pixels (:func:`low_gradient_pixels`), whose noise sigma is then not
      inflated by partial volume; clipped voxels are left out of them. With a single
      level the new levels are used only if they are more than one. Where fewer than 16
      pixels are low-gradient (quantized or windowed data), multi-level Otsu of all the
      pixels gives the levels instead: k the largest, up to 6, for which
      every k' <= k keeps adjacent class means at least that separation apart (sigma
      from the flat pixels), used if it is more levels than the flat pixels gave.
    * A material beyond the outermost levels (n_materials 'auto';
      :func:`ctseg.levels_auto.tail_levels`): regions further than the separation above
      the highest level (a dense insert too small for flat pixels: one 3 x 3 square beyond
      suffices), or, where the flat pixels are untrusted, below the lowest (a phase too
      fine to leave a low-gradient pixel), get a level there. Below the lowest level only
      then: with trusted flat pixels, the dark bands that beam hardening and scatter leave
      between metal parts lie there.

    Given ``gray_levels`` (input units), those are the levels (:func:`given_levels_255`).

    Parameters
    ----------
    images : (rows, cols) or (n, rows, cols) array_like
    scale : (offset, factor)
        The map onto 0-255 (:func:`ctseg.intensity.gray_scale`).
    gray_levels : sequence of float or 'auto'
        The levels in the input's units, ascending; 'auto' finds them as above.
    flat_sigma_px, density_floor, density_saturation
        Define the flat pixels (:func:`flat_pixels`).
    merge_k, merge_rel, merge_floor_255, merge_threshold_255, level_min_fraction, n_materials
        As in :func:`pixel_material_levels`.
    report : dict, optional
        Filled with the evidence: ``method`` ('given', 'flat_pixels', 'low_gradient',
        'otsu_all_pixels'), ``reason`` (why the flat pixels were not trusted),
        ``criterion``, ``flat_fraction``, ``flat_levels_255``, ``low_gradient_fraction``,
        ``k_candidates`` (multi-level Otsu of the pixels used, for k = 1..6, with the
        smallest gap between adjacent class means over the separation the rule asks for),
        ``levels_255``, ``sigma_255``, ``clipped``, ``clipped_fraction``,
        ``clipped_low_fraction``, ``clipped_high_fraction``.

    Returns
    -------
    levels : (K,) ndarray, ascending
    sigma_255 : float
        Noise of the dominant material's flat pixels (0-255 scale).

    Example
    -------
    >>> img = np.zeros((40, 40)); img[10:30, 10:30] = 1.0
    >>> levels, _ = material_levels(img, (0.0, 255.0))
    >>> np.round(levels).tolist()
    [0.0, 255.0]
    """
    stack = np.asarray(images)
    stack = stack[None] if stack.ndim == 2 else stack
    g255 = np.stack([rescale_gray(sl, scale=scale)[0] for sl in stack])
    flat = flat_voxels(stack, flat_sigma_px, density_floor, density_saturation, across=volume)
    kw = dict(merge_k=merge_k, merge_rel=merge_rel, merge_floor_255=merge_floor_255,
              merge_threshold_255=merge_threshold_255, level_min_fraction=level_min_fraction)
    if check("gray_levels", gray_levels) != AUTO:
        levels = given_levels_255(gray_levels, scale)
        sigma = pixel_material_levels(g255, flat, **kw)[1]
        if report is not None:
            report.update(method="given", levels_255=levels.tolist(), sigma_255=float(sigma))
        return levels, sigma
    n_mat = check("n_materials", n_materials)
    clip_lo, clip_hi = clipped_extremes(stack)
    clipped = [m for m in (clip_lo, clip_hi) if m.any()]
    keep = ~(clip_lo | clip_hi)
    n_rest = n_mat if n_mat == AUTO else n_mat - len(clipped)
    if n_rest != AUTO and n_rest < 1:  # asked for fewer materials than the clipped ends
        clipped, keep, n_rest = [], np.ones(stack.shape, bool), n_mat
    # the levels of the flat pixels, exactly as ever
    if n_mat == AUTO or not clipped:
        levels, sigma = pixel_material_levels(g255, flat, n_materials=n_mat, **kw)
    else:  # exactly n_materials: the clipped ends count among them
        levels, sigma = pixel_material_levels(g255, flat & keep, n_materials=n_rest, **kw)
    flat_levels = levels
    n_flat = int(flat.sum())
    frac = n_flat / flat.size
    reason = None
    if n_flat < 16:
        reason = f"only {n_flat} flat pixels"
    elif frac >= FLAT_TRUST_FRACTION:
        reason = (f"{frac:.1%} of the pixels are flat: the density map found no edges, so "
                  f"partial-volume pixels counted as flat")
    elif n_mat == AUTO and len(levels) < 2:
        reason = "the flat pixels give a single level"
    method, low, k_cand, tail = "flat_pixels", None, None, []
    base = max(merge_floor_255, merge_k * sigma)
    if reason is not None:
        # the clipped voxels are left out: they would make the noise look like zero
        low = low_gradient_pixels(g255, flat_sigma_px, mask=keep, volume=volume) & keep
        if low.sum() >= 16:
            lv2, sig2 = pixel_material_levels(g255, low, n_materials=n_rest, **kw)
            if reason != "the flat pixels give a single level" or len(lv2) + len(clipped) > 1:
                levels, sigma, method = lv2, sig2, "low_gradient"
                base = max(merge_floor_255, merge_k * sigma)
        elif n_mat == AUTO and merge_threshold_255 == AUTO:  # quantized or windowed data
            lv2, k_cand = otsu_levels(g255, lambda g: base + merge_rel * g)
            if len(lv2) > len(levels):
                levels, method = lv2, "otsu_all_pixels"
    clip_levels = [float(np.mean(g255[m])) for m in clipped]
    if n_mat == AUTO and merge_threshold_255 == AUTO:
        tail = tail_levels(g255, np.sort(np.append(levels, clip_levels)),
                           lambda g: base + merge_rel * g, keep, below=reason is not None)
        levels = np.sort(np.append(levels, tail))
    if report is not None:
        if k_cand is None:
            sel = {"low_gradient": low, "flat_pixels": flat if n_flat >= 16 else None}[method]
            sm = level_sample(g255, sel)
            sep = (lambda g: base + merge_rel * g) if merge_threshold_255 == AUTO \
                else (lambda g: merge_threshold_255)
            k_cand = otsu_candidates(sm, sep)
    for c in clip_levels:  # a material of its own (with n_materials, the rest found without it)
        near = np.abs(levels - c) < base if n_mat == AUTO else np.zeros(len(levels), bool)
        levels = np.sort(np.append(levels[~near], c))
    if report is not None:
        report.update(level_report(method, reason, flat, flat_levels, low, k_cand, levels,
                                   sigma, clip_lo, clip_hi, clip_levels, tail))
    return levels, sigma


LEVEL_SAMPLE_VOXELS = 1 << 25
"""At most this many voxels (evenly spaced whole slices) measure the gray map and levels."""


def volume_levels(volume, params, axis=0):
    """The gray map onto 0-255 and the material levels of a whole volume, measured on
    evenly spaced whole slices along ``axis`` (at most :data:`LEVEL_SAMPLE_VOXELS`
    voxels) with :func:`ctseg.intensity.gray_scale` and :func:`material_levels`.

    Returns
    -------
    scale : (offset, factor)
    levels_255 : (K,) ndarray
    sigma_255 : float
        The noise of the flat pixels of the dominant material.
    sample : (s,) int ndarray
        The slices measured.
    """
    ax = slice_axis(axis)
    n_slices = volume.shape[ax]
    n_keep = max(1, min(n_slices, LEVEL_SAMPLE_VOXELS // max(volume.size // n_slices, 1)))
    sample = np.unique(np.linspace(0, n_slices - 1, n_keep).round().astype(int))
    stack = np.stack([as_image(volume_slice(volume, ax, k), name=f"slice {k}") for k in sample])
    check_gray_levels(params.gray_levels, stack)
    scale = gray_scale(stack, params.rescale_low_pct, params.rescale_high_pct)
    levels, sigma = material_levels(stack, scale, **{k: getattr(params, k) for k in LEVEL_KEYS},
                                    volume=len(sample) == n_slices)
    return scale, levels, sigma, sample
