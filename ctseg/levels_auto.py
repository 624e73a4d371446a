"""The rules of :func:`ctseg.levels.material_levels` for scans its flat pixels cannot
measure (granular and porous media, all partial volume; quantized or windowed data) and for
clipped data, with the multi-level Otsu they share and the report of how the levels were
found."""
import numpy as np
from scipy.ndimage import binary_erosion, gaussian_filter, label, minimum_filter, uniform_filter

from .errors import ParameterError
from .params import DEFAULTS


def otsu_thresholds(values, weights, k):
    """Multi-level Otsu: the ``k - 1`` thresholds that maximise the between-class variance
    of the weighted values (exact, by dynamic programming over a 1024-bin histogram); a
    value belongs to class ``searchsorted(thresholds, value)``.

    Raises
    ------
    ParameterError
        Fewer than ``k`` distinct values.

    Example
    -------
    >>> t = otsu_thresholds([10, 11, 12, 50, 51, 90, 91], np.ones(7), 3)
    >>> np.searchsorted(t, [10, 11, 12, 50, 51, 90, 91]).tolist()
    [0, 0, 0, 1, 1, 2, 2]
    """
    v = np.asarray(values, float)
    w = np.asarray(weights, float)
    distinct = np.unique(v)
    if len(distinct) < k:
        raise ParameterError(f"n_materials: asked for {k} materials but the gray values hold "
                             f"only {len(distinct)} distinct value(s)")
    n_bins = 1024
    lo, hi = float(distinct[0]), float(distinct[-1])
    idx = np.minimum(((v - lo) / (hi - lo) * n_bins).astype(int), n_bins - 1)
    hist = np.bincount(idx, w, n_bins)
    centre = lo + (np.arange(n_bins) + 0.5) * (hi - lo) / n_bins
    c0 = np.concatenate([[0.0], np.cumsum(hist)])
    c1 = np.concatenate([[0.0], np.cumsum(hist * centre)])

    def score(a, b):  # W * mean^2 of bins a..b-1 (the between-class term to maximise)
        m = np.broadcast_to(c0[b] - c0[a], np.broadcast(a, b).shape)
        s = np.broadcast_to((c1[b] - c1[a]) ** 2, m.shape)
        return np.divide(s, m, out=np.full(m.shape, -np.inf), where=m > 0)

    occupied = np.flatnonzero(hist > 0)
    if len(occupied) < k:
        raise ParameterError(f"n_materials: asked for {k} materials but the gray values fall "
                             f"in only {len(occupied)} distinct level(s)")
    cuts = np.unique(np.concatenate([occupied, occupied + 1]))  # class bounds worth trying
    best = score(0, cuts)  # one class from bin 0 to each cut
    back = []
    for _ in range(k - 1):
        table = best[:, None] + score(cuts[:, None], cuts[None, :])
        table[cuts[:, None] >= cuts[None, :]] = -np.inf
        back.append(np.argmax(table, axis=0))
        best = table.max(axis=0)
    j = int(np.flatnonzero(cuts == n_bins)[0])
    bounds = []
    for b in reversed(back):
        j = int(b[j])
        bounds.append(cuts[j])
    return np.sort(lo + np.array(bounds, float) * (hi - lo) / n_bins)


FLAT_TRUST_FRACTION = 0.995
"""Flat pixels are not trusted when they are at least this share of all pixels: the density
map then found no edges (its 'auto' noise reference is the median gradient, which on a
granular or porous scan is itself an edge gradient), so partial-volume pixels count as
flat."""

LOW_GRADIENT_NOISE_MULT = 2.0
"""Low-gradient pixels: smoothed gradient below this many times the gradient noise scale."""

LOW_GRADIENT_MIN_PCT = 10.0
"""... or below this percentile of the smoothed gradient, whichever is larger."""

CLIP_MIN_FRACTION = 5e-4
"""Share of the voxels an extreme value must hold to be clipped data (also at least
:data:`CLIP_MIN_VOXELS` of them with a neighbour at the same value, and at least twice as
many as hold the next value inwards)."""

CLIP_MIN_VOXELS = 8
"""Voxels at an extreme value that must touch another one (a region, not noise hits)."""

CLIP_REGION_SHARE = 0.25
"""Share of the in-slice neighbours of the voxels at an extreme value that must be at it too
for them to be a region (a material of its own). Noise clips a material's voxels
independently, so this share is about the share of its voxels clipped: below it the
material's level lies more than about 0.7 noise sd inside the range and is measured from
its unclipped voxels (a uint16 scan whose air noise is cut at 0, say)."""


TAIL_MIN_FRACTION = 0.005
"""A material beyond the outermost level: at least this share of the pixels lies further
than the level separation below the lowest level (or above the highest), in regions of
at least :data:`TAIL_MIN_REGION_PX`. Noise keeps a material's pixels within that
separation and partial volume keeps them between the levels of the materials that mix,
so such pixels need a material beyond; on a porous or granular scan it is the phase too
fine to leave a flat pixel. The share that the default rescale maps onto gray 0 (or
255): a tail that thin is the rescale's own."""

TAIL_MIN_REGION_PX = 10
"""Pixels beyond the separation count towards :data:`TAIL_MIN_FRACTION` only in regions of
at least this many (8-connected within a slice): the 3 x 3 smoothing that the levels are
measured after spreads one outlying pixel (a hot pixel, a noise spike) over exactly its 9
pixels, so a larger region is a material's."""

TAIL_LEVEL_PCT = 5.0
"""The level of such a material: this percentile of the tail's pixels counted from the far
end (its pure pixels sit at the far end, partial-volume ones towards the known level)."""


def tail_levels(g255, levels, separation, mask=None, below=True):
    """Levels of materials beyond the outermost ones found (:data:`TAIL_MIN_FRACTION`,
    :data:`TAIL_MIN_REGION_PX`), on the grays smoothed over 3 x 3 within each slice, as the
    levels are measured. Above the highest level fewer pixels than the fraction suffice
    when their regions hold a whole 3 x 3 square of pixels beyond the separation (a small
    dense insert; hot pixels hold none): the level is then those regions'.

    Parameters
    ----------
    g255 : (rows, cols) or (n, rows, cols) array_like
        Grays on the 0-255 scale.
    levels : (K,) array_like, ascending, K >= 1
    separation : callable
        The level separation at a gray (as :func:`ctseg.levels.pixel_material_levels`).
    mask : bool array_like, the shape of ``g255``, optional
        The pixels that count (e.g. all but clipped ones).
    below : bool
        Whether to look below ``levels[0]`` too (above ``levels[-1]`` always).

    Returns
    -------
    added : list of float
        At most one level below ``levels[0]`` (first) and one above ``levels[-1]``.

    Example
    -------
    >>> g = np.full((40, 40), 200.0); g[:, :8] = np.linspace(0.0, 150.0, 40)[:, None]
    >>> [round(x, 1) for x in tail_levels(g, [200.0], lambda x: 20.0)]
    [7.7]
    """
    g = np.asarray(g255, float)
    sm = smoothed_grays(g[None] if g.ndim == 2 else g.reshape((-1,) + g.shape[-2:]))
    keep = np.ones(sm.shape, bool) if mask is None else np.asarray(mask, bool).reshape(sm.shape)
    n = int(keep.sum())
    lo, hi = float(levels[0]), float(levels[-1])
    in_slice = np.zeros((3, 3, 3), bool)
    in_slice[1] = True
    added = []
    sides = [(keep & (sm > hi + separation(hi)), 100.0 - TAIL_LEVEL_PCT, True)]
    if below:
        sides.insert(0, (keep & (sm < lo - separation(lo)), TAIL_LEVEL_PCT, False))
    for beyond, pct, above in sides:
        regions, n_regions = label(beyond, in_slice)
        size = np.bincount(regions.ravel(), minlength=n_regions + 1)
        size[0] = 0
        tail = size[regions] >= TAIL_MIN_REGION_PX
        if above and 0 < tail.sum() < TAIL_MIN_FRACTION * n:
            # fewer: a dense insert if a whole 3 x 3 square of its pixels lies beyond
            core = minimum_filter(g.reshape(sm.shape), size=(1, 3, 3)) > hi + separation(hi)
            dense = np.zeros(n_regions + 1, bool)
            dense[regions[core & tail]] = True
            tail = dense[regions]
        elif tail.sum() < TAIL_MIN_FRACTION * n:
            continue
        if tail.any():
            added.append(float(np.percentile(sm[tail], pct)))
    return added


def _gradient_gain(sigma_px, ndim=2):
    """The sd of one component of ``np.gradient`` of an image (``ndim`` 2) or a volume (3)
    smoothed by a Gaussian of ``sigma_px``, per unit sd of white noise."""
    delta = np.zeros((41,) * ndim)
    delta[(20,) * ndim] = 1.0
    kernel = gaussian_filter(delta, sigma_px) if sigma_px > 0 else delta
    return float(np.sqrt(np.sum(np.gradient(kernel, axis=0) ** 2)))


def low_gradient_pixels(image255, flat_sigma_px=DEFAULTS.flat_sigma_px, mask=None, volume=False):
    """Pixels inside flat regions told by the noise, not by the density map.

    Per slice: the gradient magnitude of the image smoothed by ``flat_sigma_px`` is below
    ``max(LOW_GRADIENT_NOISE_MULT * tau, LOW_GRADIENT_MIN_PCT-th percentile)``, ``tau``
    the gradient that white noise of the pixel-difference noise scale (as in
    :func:`ctseg.intensity.estimate_noise`, over ``mask``) gives (the Rayleigh scale: 86% of pure-noise
    pixels pass); then eroded by 3 x 3, so that single low-gradient pixels on a
    partial-volume slope (saddles, ridge tops) drop out.

    Parameters
    ----------
    image255 : (rows, cols) or (n, rows, cols) array_like
    flat_sigma_px : float
    mask : bool array_like, the shape of ``image255``, optional
        The pixels that measure the noise and the percentile (e.g. all but clipped ones).
    volume : bool, optional
        The stack is consecutive slices of a volume: smooth and take the gradient in 3D
        (a partial-volume voxel on a surface nearly parallel to the slices has no in-plane
        gradient), with the gain of the 3D filter; noise and percentile as before. Where
        that leaves fewer than 16 pixels (surfaces everywhere), the slices' own gradients.

    Returns
    -------
    low : bool ndarray, the shape of ``image255``

    Example
    -------
    >>> img = np.zeros((20, 20)); img[:, 10:] = 100.0
    >>> low = low_gradient_pixels(img)
    >>> bool(low[:, 2].all()), bool(low[:, 8:12].any())
    (True, False)
    """
    stack = np.asarray(image255, float)
    stack = stack[None] if stack.ndim == 2 else stack
    sel = np.ones(stack.shape, bool) if mask is None else np.asarray(mask, bool).reshape(stack.shape)
    volume = bool(volume) and stack.shape[0] >= 3
    gain = _gradient_gain(flat_sigma_px, 3 if volume else 2)
    if volume:
        sm3 = gaussian_filter(stack, flat_sigma_px, mode="nearest") if flat_sigma_px > 0 else stack
        mag3 = np.sqrt(sum(g * g for g in np.gradient(sm3)))
    out = np.zeros(stack.shape, bool)
    for k, sl in enumerate(stack):
        if not sel[k].any():
            continue
        if volume:
            mag = mag3[k]
        else:
            sm = gaussian_filter(sl, flat_sigma_px, mode="nearest") if flat_sigma_px > 0 else sl
            gy, gx = np.gradient(sm)
            mag = np.hypot(gx, gy)
        m = sel[k]
        d = np.concatenate([(sl[1:] - sl[:-1])[m[1:] & m[:-1]], (sl[:, 1:] - sl[:, :-1])[m[:, 1:] & m[:, :-1]]])
        noise = 1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0) if len(d) else 0.0
        thr = max(LOW_GRADIENT_NOISE_MULT * gain * noise,
                  float(np.percentile(mag[m], LOW_GRADIENT_MIN_PCT)))
        out[k] = binary_erosion(mag <= thr, np.ones((3, 3), bool), border_value=1)
    if volume and out.sum() < 16:  # edges everywhere in 3D: the slices' own gradients
        return low_gradient_pixels(image255, flat_sigma_px, mask)
    return out.reshape(np.shape(image255))


def clipped_extremes(images):
    """Voxels clipped at the top or bottom of the data's range (a saturated detector, the
    dtype's limit, a reconstruction window).

    An extreme value (the minimum or the maximum) is clipped when it holds at least
    :data:`CLIP_MIN_FRACTION` of the voxels, at least twice as many as the next value
    inwards does (a spike, not the tail of a distribution), at least
    :data:`CLIP_MIN_VOXELS` of its voxels touch another one within their slice, and at
    least :data:`CLIP_REGION_SHARE` of its voxels' in-slice neighbours are at it too (a
    region, not noise hits scattered through a material whose level lies inside the range).

    Returns
    -------
    low, high : bool ndarray, the shape of ``images``
        The clipped voxels at each end (all False where that end is not clipped).

    Example
    -------
    >>> img = np.tile(np.arange(40.0), (40, 1)); img[5:15, 5:15] = 39.0
    >>> low, high = clipped_extremes(img)
    >>> bool(low.any()), int(high.sum())
    (False, 140)
    """
    v = np.asarray(images)
    stack = v[None] if v.ndim == 2 else v
    masks = []
    vmin, vmax = stack.min(), stack.max()
    for value in (vmin, vmax):
        at = stack == value
        n = int(at.sum())
        inner = stack[~at]
        ok = vmin < vmax and n >= CLIP_MIN_FRACTION * stack.size
        if ok:
            nxt = inner.max() if value == vmax else inner.min()
            ok = n >= 2 * int(np.sum(stack == nxt))
        if ok:
            ok = _region_share(at) >= CLIP_REGION_SHARE
        masks.append(at.reshape(v.shape) if ok else np.zeros(v.shape, bool))
    return masks[0], masks[1]


def _region_share(at):
    """Share of the in-slice neighbours of ``at``'s voxels (n, rows, cols) that are in
    ``at`` too; 0 where fewer than :data:`CLIP_MIN_VOXELS` of them touch another one."""
    touching = np.zeros(at.shape, np.int8)
    neighbours = np.zeros(at.shape, np.int8)
    for dst, src in (((slice(None), slice(1, None)), (slice(None), slice(None, -1))),
                     ((slice(None), slice(None, -1)), (slice(None), slice(1, None))),
                     ((Ellipsis, slice(1, None)), (Ellipsis, slice(None, -1))),
                     ((Ellipsis, slice(None, -1)), (Ellipsis, slice(1, None)))):
        touching[dst] += at[src]
        neighbours[dst] += 1
    if int(np.sum(at & (touching > 0))) < CLIP_MIN_VOXELS:
        return 0.0
    return float(touching[at].sum()) / float(neighbours[at].sum())


def smoothed_grays(g255):
    """The grays smoothed over 3 x 3 within each slice, as the levels are measured."""
    return uniform_filter(g255, (1,) * (g255.ndim - 2) + (3, 3), mode="nearest")


def level_sample(g255, sel=None, n_max=20000):
    """The 3 x 3-smoothed grays (as :func:`pixel_material_levels` sees them) of the
    selected pixels, at most ``n_max`` of them, evenly spaced."""
    sm = smoothed_grays(g255)
    sm = sm.ravel() if sel is None else sm[sel]
    return sm[np.linspace(0, len(sm) - 1, n_max).astype(int)] if len(sm) > n_max else sm


def otsu_candidates(v, separation, k_max=6):
    """Candidates for the number of levels: multi-level Otsu of ``v`` for k = 1..k_max, the
    class means and the smallest gap between adjacent means in units of the separation
    the merge rule asks for there (>= 1: the rule keeps them apart)."""
    out = []
    for k in range(1, k_max + 1):
        try:
            t = otsu_thresholds(v, np.ones(len(v)), k) if k > 1 else np.zeros(0)
        except ParameterError:
            break
        cls = np.searchsorted(t, v)
        means = [float(np.mean(v[cls == j])) for j in range(k) if np.any(cls == j)]
        ratio = min((b - a) / separation(b) for a, b in zip(means[:-1], means[1:])) \
            if len(means) > 1 else None
        out.append({"k": k, "levels_255": [round(m, 2) for m in means],
                    "min_gap_over_separation": None if ratio is None else round(ratio, 3)})
    return out


def otsu_levels(g255, separation):
    """Levels by multi-level Otsu of all the pixels (:func:`level_sample`): k the largest
    (<= 6) for which every k' <= k keeps adjacent class means at least ``separation``
    apart. Returns the levels and the candidates of :func:`otsu_candidates`."""
    k_cand = otsu_candidates(level_sample(g255), separation)
    k_ok = 1
    for c in k_cand[1:]:
        if c["min_gap_over_separation"] < 1.0:
            break
        k_ok = c["k"]
    return np.array(k_cand[k_ok - 1]["levels_255"]), k_cand


def level_report(method, reason, flat, flat_levels, low, k_cand, levels, sigma, clip_lo, clip_hi,
                 clip_levels, tail=()):
    """The evidence of :func:`ctseg.levels.material_levels` as a JSON-ready dict."""
    n_vox = flat.size
    clipped = bool(clip_lo.any() or clip_hi.any())
    rule = ("adjacent modes apart by at least max(merge_floor_255, merge_k * sigma) + "
            "merge_rel * gray with a valley below half the lower peak, each holding "
            "level_min_fraction of the pixels")
    criterion = {
        "flat_pixels": "modes of the 3x3-smoothed gray of the flat pixels (density map "
                       "below half its range); " + rule,
        "low_gradient": "modes of the 3x3-smoothed gray of the low-gradient pixels "
                        "(smoothed gradient below twice the noise's); " + rule,
        "otsu_all_pixels": "multi-level Otsu of all pixels, k the largest (<= 6) whose "
                           "adjacent class means keep max(merge_floor_255, merge_k * sigma) "
                           "+ merge_rel * gray apart (min_gap_over_separation >= 1)",
    }[method]
    return {
        "method": method,
        "reason": reason or "flat pixels trusted",
        "criterion": criterion + ("; clipped ends are levels of their own" if clipped else "")
        + (f"; a material beyond the outermost levels where >= {TAIL_MIN_FRACTION:.1%} of the "
           f"pixels lie a separation beyond them in regions of >= {TAIL_MIN_REGION_PX} px" if tail else ""),
        "flat_fraction": round(float(flat.mean()), 4),
        "flat_levels_255": [round(float(x), 2) for x in flat_levels],
        "low_gradient_fraction": None if low is None else round(float(low.mean()), 4),
        "k_candidates": k_cand,
        "k_chosen": int(len(levels)),
        "levels_255": [round(float(x), 2) for x in levels],
        "sigma_255": round(float(sigma), 3),
        "clipped": clipped,
        "clipped_fraction": round(float((clip_lo | clip_hi).sum() / n_vox), 6),
        "clipped_low_fraction": round(float(clip_lo.sum() / n_vox), 6),
        "clipped_high_fraction": round(float(clip_hi.sum() / n_vox), 6),
        "clipped_levels_255": [round(c, 2) for c in clip_levels],
        "tail_levels_255": [round(c, 2) for c in tail],
    }
