"""Stage 7: recursive graph-cut segmentation of the triangles into materials (paper 6, 8; SPEC 7)."""
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.ndimage import gaussian_filter1d
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ._validate import check_number
from .errors import ParameterError
from .graphcut import graphcut_split


def weighted_percentile(values, weights, q):
    """Percentile(s) q (0-100) of values weighted by weights (step-function inverse CDF)."""
    v = np.asarray(values, float)
    w = np.asarray(weights, float)
    o = np.argsort(v, kind="stable")
    cw = np.cumsum(w[o])
    cw /= cw[-1]
    idx = np.searchsorted(cw, np.asarray(q, float) / 100.0, side="left")
    return v[o][np.clip(idx, 0, len(v) - 1)]




def weighted_spread(values, weights):
    """Standard deviation of the values between their weighted 1st and 99th percentiles.

    Trimmed rather than median-based: the spread of a whole material's triangle grays
    includes streaks and cupping, which a median absolute deviation would hide.
    """
    v = np.asarray(values, float)
    w = np.asarray(weights, float)
    lo, hi = weighted_percentile(v, w, [1.0, 99.0])
    keep = (v >= lo) & (v <= hi)
    if keep.sum() < 2:
        return 0.0
    return float(np.sqrt(np.cov(v[keep], aweights=w[keep])))


def interior_triangles(gray, adjacency, step_threshold, rel=0.0):
    """Triangles whose gray differs from every neighbour's by at most
    ``step_threshold + rel * gray``.

    Those lie inside a material; triangles straddling a boundary (partial volume) have a
    large step to a neighbour on at least one side. The term in ``rel`` lets the noise and
    beam-hardening artifacts of dense materials, which grow with attenuation, through.
    """
    f = np.asarray(gray, float)
    step = np.zeros(len(f))
    if len(adjacency):
        d = np.abs(f[adjacency[:, 0]] - f[adjacency[:, 1]])
        np.maximum.at(step, adjacency[:, 0], d)
        np.maximum.at(step, adjacency[:, 1], d)
    return step <= step_threshold + rel * f




def step_noise(gray, adjacency, area=None):
    """Robust scale of the gray step between adjacent triangles (1.4826 x MAD of the steps).

    Only pairs of triangles both larger than the median area are used when ``area`` is
    given: the CVT makes triangles small along boundaries and large inside materials, so
    these pairs measure noise alone, while pairs across boundaries would dominate a mesh
    that resolves many boundaries.
    """
    f = np.asarray(gray, float)
    adjacency = np.asarray(adjacency, np.int64).reshape(-1, 2)
    if len(adjacency) == 0:
        return 0.0
    if area is not None:
        area = np.asarray(area, float)
        big = area >= np.median(area)
        sel = big[adjacency[:, 0]] & big[adjacency[:, 1]]
        if sel.sum() >= 10:
            adjacency = adjacency[sel]
    d = f[adjacency[:, 0]] - f[adjacency[:, 1]]
    return float(1.4826 * np.median(np.abs(d - np.median(d))))

def material_modes(gray, area, bandwidth, min_area, separation, n_modes=None):
    """Material gray levels: the modes of the area-weighted histogram of triangle grays.

    The histogram (0.25 gray-level bins on 0-255) is smoothed with a Gaussian of
    ``bandwidth``. Neighbouring modes are merged, weakest first, while the valley between
    them is above half the lower peak (no real separation) or they are closer than
    ``separation(level)`` gray levels; a mode whose basin holds less than ``min_area`` is
    merged into the neighbour it is least separated from. With ``n_modes`` the weakest
    boundaries are merged until exactly that many modes remain, whatever the rules say.

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
        raise ParameterError(
            f"n_materials: asked for {n_modes} materials but the gray values show only "
            f"{len(peaks)} distinct levels")
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
    means = np.array([np.average(f[basin == k], weights=w[basin == k]) if np.any(basin == k)
                      else peaks[k] * bin_w for k in range(len(peaks))])
    return means, edges




@dataclass
class MaterialSegmentation:
    """Outcome of :func:`segment_triangles`.

    Attributes
    ----------
    material : (m,) int ndarray
        Material of each triangle, 0..K-1 by ascending mean gray.
    material_gray : (K,) ndarray
        Area-weighted mean gray of each material's triangles (0-255 scale).
    mode_gray : (K,) ndarray
        The gray levels found for the materials (modes of the interior triangles' grays).
    leaf : (m,) int ndarray
        Leaf component of the recursion each triangle ended in.
    graphcut_calls, max_depth_reached : int
    step_noise, step_threshold : float
        Noise of steps between adjacent triangles, and the step above which a triangle
        counts as straddling a boundary (0-255 scale).
    material_noise : float
        Spread of interior triangle grays in the dominant material (0-255 scale; 0 when
        the levels were given).
    """

    material: np.ndarray
    material_gray: np.ndarray
    mode_gray: np.ndarray
    leaf: np.ndarray
    graphcut_calls: int = 0
    max_depth_reached: int = 0
    step_noise: float = 0.0
    step_threshold: float = 0.0
    material_noise: float = 0.0


def _recursive_split(f, area, adjacency, centroids, interior, edges, means, min_pocket,
                     min_layer_area, min_triangles, max_depth, cut_params, edge_length=None):
    """Split components while they hold more than one material; label each leaf.

    Returns (material per triangle, leaf per triangle, graph-cut calls, depth reached).
    """
    m = len(f)
    k_modes = len(means)
    # core zone of each material: within a quarter of the gap to its neighbouring levels
    gaps = np.diff(means)
    half_lo = np.r_[np.inf, gaps] * 0.25
    half_hi = np.r_[gaps, np.inf] * 0.25
    nearest = np.argmin(np.abs(f[:, None] - means[None, :]), axis=1)
    dev = f - means[nearest]
    in_core = np.where(dev < 0, -dev <= half_lo[nearest], dev <= half_hi[nearest])
    leaf = np.zeros(m, np.int64)
    leaf_material = []
    stack = [(np.arange(m), 0)]
    calls = deepest = 0
    in_comp = np.full(m, -1, np.int64)
    while stack:
        comp, depth = stack.pop()
        deepest = max(deepest, depth)
        core = comp[in_core[comp]]
        mass = np.bincount(nearest[core], area[core], k_modes)
        present = np.flatnonzero(mass >= min_pocket)
        if len(present) < 2 or len(comp) < max(2, min_triangles) or depth >= max_depth:
            inner = comp[interior[comp]]
            imass = np.bincount(nearest[inner], area[inner], k_modes)
            leaf[comp] = len(leaf_material)
            if imass.max() >= min_pocket:
                leaf_material.append(int(np.argmax(imass)))
            elif len(present) == 1 and area[comp].sum() >= min_layer_area:
                # a thin layer of one material: its triangles sit in that material's core
                leaf_material.append(int(present[0]))
            else:  # -1: a partial-volume leaf, decided by its neighbours
                leaf_material.append(-1)
            continue
        lo_mode, hi_mode = present[0], present[-1]
        c0 = core[nearest[core] == lo_mode]
        c1 = core[nearest[core] == hi_mode]
        s0 = c0[np.argmin(np.abs(f[c0] - means[lo_mode]))]
        s1 = c1[np.argmin(np.abs(f[c1] - means[hi_mode]))]
        in_comp[:] = -1
        in_comp[comp] = np.arange(len(comp))
        a, b = in_comp[adjacency[:, 0]], in_comp[adjacency[:, 1]]
        keep = (a >= 0) & (b >= 0)
        el = None if edge_length is None else edge_length[keep]
        labels, _ = graphcut_split(f[comp], np.column_stack([a[keep], b[keep]]), centroids[comp],
                                   seeds=(in_comp[s0], in_comp[s1]), edge_length=el, **cut_params)
        calls += 1
        # each side goes on as its connected pieces: a piece cut off far from the rest of
        # its side (a partial-volume triangle whose gray matches that side) is judged alone
        local = np.column_stack([a[keep], b[keep]])
        same = labels[local[:, 0]] == labels[local[:, 1]]
        n_loc = len(comp)
        graph = coo_matrix((np.ones(same.sum()), (local[same, 0], local[same, 1])), shape=(n_loc, n_loc))
        n_pieces, piece = connected_components(graph, directed=False)
        order = np.argsort(piece, kind="stable")
        bounds = np.searchsorted(piece[order], np.arange(n_pieces + 1))
        for q in range(n_pieces - 1, -1, -1):
            stack.append((comp[order[bounds[q]:bounds[q + 1]]], depth + 1))
    leaf_material = np.array(leaf_material, np.int64)
    _label_fragmented_layers(area, leaf, leaf_material, adjacency, nearest, in_core,
                             min_layer_area, k_modes)
    _label_partial_volume_leaves(f, area, leaf, leaf_material, adjacency, means,
                                 min_layer_area / 4.0)
    return leaf_material[leaf], leaf, calls, deepest


def _label_fragmented_layers(area, leaf, leaf_material, adjacency, nearest, in_core,
                             min_layer_area, k_modes):
    """Give a material to runs of adjacent partial-volume leaves that form a thin layer, in place.

    A thin layer between two other materials (a polymer sleeve between a steel core and an
    air gap) has no interior triangles, and the cuts between its neighbours can chop it
    into pieces too small for the thin-layer rule. Taken together, adjacent unlabelled
    leaves covering at least ``min_layer_area``, more than half of it in one material's
    core, are a layer of that material; a band of partial-volume triangles along a
    boundary spreads over the gray range between its two sides instead.
    """
    n = len(leaf_material)
    pending = leaf_material < 0
    if pending.sum() < 2:
        return
    a, b = leaf[adjacency[:, 0]], leaf[adjacency[:, 1]]
    join = (a != b) & pending[a] & pending[b]
    graph = coo_matrix((np.ones(join.sum()), (a[join], b[join])), shape=(n, n))
    _, run = connected_components(graph, directed=False)
    tri = pending[leaf]
    run_of_tri = run[leaf[tri]]
    run_area = np.bincount(run_of_tri, area[tri], n)
    core = tri & in_core
    core_mass = np.zeros((n, k_modes))
    np.add.at(core_mass, (run[leaf[core]], nearest[core]), area[core])
    best = np.argmax(core_mass, axis=1)
    layer = (run_area >= min_layer_area) & (core_mass.max(axis=1) > 0.5 * run_area)
    fix = pending & layer[run]
    leaf_material[fix] = best[run[fix]]


def _label_partial_volume_leaves(f, area, leaf, leaf_material, adjacency, means, min_area=np.inf):
    """Give leaves without interior triangles a material, in place.

    A partial-volume mix lies between the grays of the materials around it and joins the
    closest of those, unless it covers ``min_area`` or more and its gray is in the core of
    a material in between (then it is that material: a mixed band is thin); anything else
    (a small pore, a speck) joins the closest level.
    """
    n = len(leaf_material)
    la = np.bincount(leaf, area, n)
    lg = np.bincount(leaf, area * f, n) / np.maximum(la, 1e-300)
    gaps = np.diff(means)
    half_lo = np.r_[np.inf, gaps] * 0.25
    half_hi = np.r_[gaps, np.inf] * 0.25

    def in_core_of(g, k):
        return -half_lo[k] <= g - means[k] <= half_hi[k]

    a, b = leaf[adjacency[:, 0]], leaf[adjacency[:, 1]]
    cross = a != b
    src = np.concatenate([a[cross], b[cross]])
    dst = np.concatenate([b[cross], a[cross]])
    order = np.argsort(src, kind="stable")
    src, dst = src[order], dst[order]
    start = np.searchsorted(src, np.arange(n + 1))
    solid = leaf_material >= 0  # labelled by interior triangles, not by this function
    pending = np.flatnonzero(~solid)
    while len(pending):
        progressed = False
        for k in pending[np.argsort(-la[pending], kind="stable")]:
            nb = dst[start[k]:start[k + 1]]
            # neighbours labelled by their own interior come first: a partial-volume leaf
            # next to another one must not copy the gray-alike label it got
            use = nb[solid[nb]] if solid[nb].any() else nb[leaf_material[nb] >= 0]
            ng = np.unique(leaf_material[use])
            if len(ng) == 0:
                continue
            lv = means[ng]
            if len(ng) >= 2 and lv.min() <= lg[k] <= lv.max():
                closest = int(np.argmin(np.abs(means - lg[k])))
                if la[k] >= min_area and in_core_of(lg[k], closest):
                    # too large to be a mixed band: a piece of the material in between
                    leaf_material[k] = closest
                else:
                    leaf_material[k] = ng[int(np.argmin(np.abs(lv - lg[k])))]
            else:
                leaf_material[k] = int(np.argmin(np.abs(means - lg[k])))
            progressed = True
        pending = np.flatnonzero(leaf_material < 0)
        if not progressed:
            leaf_material[pending] = [int(np.argmin(np.abs(means - lg[k]))) for k in pending]
            break


def dominant_spread(values, weights):
    """Noise of a whole material: the spread of the values in the heaviest coarse mode."""
    coarse, cedges = material_modes(values, weights, 2.0, 0.0, lambda g: 8.0)
    basin = np.searchsorted(cedges, values)
    dom = basin == np.argmax(np.bincount(basin, weights, len(coarse)))
    return weighted_spread(values[dom], weights[dom]) if dom.sum() > 1 else 0.0


def pixel_material_levels(image255, flat, merge_k=5.0, merge_rel=0.2, merge_floor=2.0,
                          min_fraction=1e-3, n_materials=None):
    """Material gray levels from the pixels away from edges (SPEC 7's data-driven defaults).

    Parameters
    ----------
    image255 : (rows, cols) or (n, rows, cols) array_like
        The image, or a stack of slices, on the 0-255 scale
        (:func:`ctseg.intensity.rescale_gray`).
    flat : bool array_like, the shape of ``image255``
        Pixels away from edges (e.g. where the density map is below half its range).
    merge_k, merge_rel, merge_floor : float
        Separation rule of :func:`material_modes`; sigma is the spread of the flat pixels
        of the dominant mode, smoothed over 3 x 3.
    min_fraction : float
        Share of the flat pixels a level must hold.
    n_materials : int, optional

    Returns
    -------
    levels : (K,) ndarray, ascending
    sigma : float
        The noise used (0-255 scale).
    """
    from scipy.ndimage import uniform_filter

    img = np.asarray(image255, float)
    # smooth within each slice only: neighbouring slices can be far apart
    img = uniform_filter(img, (1,) * (img.ndim - 2) + (3, 3), mode="nearest")
    flat = np.asarray(flat, bool)
    v = img[flat] if flat.sum() >= 16 else img.ravel()
    w = np.ones(len(v))
    sigma = dominant_spread(v, w)
    base = max(merge_floor, merge_k * sigma)
    levels, _ = material_modes(v, w, max(sigma, 0.5), 0.0 if n_materials else min_fraction * len(v),
                               lambda g: base + merge_rel * g, n_modes=n_materials)
    return levels, sigma


def _partial_volume_triangles(f, material, interior, adjacency, means):
    """A boundary triangle whose gray lies between the levels of two materials it touches
    takes the closer of the two (the material covering most of it)."""
    mat = material.copy()
    m = len(f)
    # neighbour lists in CSR form (each triangle has at most 3 neighbours)
    src = np.concatenate([adjacency[:, 0], adjacency[:, 1]])
    dst = np.concatenate([adjacency[:, 1], adjacency[:, 0]])
    order = np.argsort(src, kind="stable")
    src, dst = src[order], dst[order]
    start = np.searchsorted(src, np.arange(m + 1))
    boundary = np.flatnonzero(~interior)
    means = np.asarray(means, np.float64)
    for _ in range(2):
        if not _partial_volume_pass(np.asarray(f, np.float64), mat, boundary, start, dst, means):
            break
    return mat


# Compiled (numba): this loop over boundary triangles was 75% of the graph-cut stage.
@njit(cache=True)
def _partial_volume_pass(f, mat, boundary, start, dst, means):
    """One in-place sweep of the rule above, in triangle order; True if a label changed.
    Ties go to the lower material number."""
    changed = False
    for t in boundary:
        own = mat[t]
        lo = means[own]
        hi = means[own]
        for e in range(start[t], start[t + 1]):
            lo = min(lo, means[mat[dst[e]]])
            hi = max(hi, means[mat[dst[e]]])
        if lo == hi or not (lo <= f[t] <= hi):
            continue  # one material around, or the gray outside their levels
        best = own
        for e in range(start[t] - 1, start[t + 1]):
            k = own if e < start[t] else mat[dst[e]]
            d = abs(means[k] - f[t])
            db = abs(means[best] - f[t])
            if d < db or (d == db and k < best):
                best = k
        if best != own:
            mat[t] = best
            changed = True
    return changed


def order_by_gray(material, gray, area):
    """Renumber materials 0..K-1 by the area-weighted mean gray of what each holds.

    On a coarse mesh the partial-volume rules can make that order differ from the order of
    the gray levels, so numbering always follows what the triangles hold.

    Returns
    -------
    material : (m,) int64 ndarray
    mean_gray : (K,) ndarray, ascending
    old_ids : (K,) ndarray, the input label of each new material
    """
    used, inv = np.unique(np.asarray(material), return_inverse=True)
    k = len(used)
    inv = inv.reshape(-1)
    mean = np.bincount(inv, area * gray, k) / np.bincount(inv, area, k)
    order = np.argsort(mean, kind="stable")
    rank = np.empty(k, np.int64)
    rank[order] = np.arange(k)
    return rank[inv], mean[order], used[order]


def segment_triangles(gray, area, adjacency, centroids, step_threshold=None, merge_k=5.0,
                      merge_rel=0.2, merge_floor=2.0, merge_threshold=None, min_triangles=2,
                      max_depth=32, min_material_area=None, min_pocket_area=4.0,
                      n_materials=None, theta=None,
                      lam=70.0, beta=0.286, eps=1.0, edge_length=None, levels=None):
    """Recursive graph-cut segmentation of a triangle mesh into materials.

    Rules (SPEC 7, with the choices made where it leaves room):

    1. Material gray levels come first, from the data. Triangles whose gray differs from
       every neighbour's by at most ``step_threshold`` are *interior* (not straddling a
       boundary). The modes of the area-weighted histogram of interior grays (smoothed by
       the noise sigma of interior triangles in the largest material) are the candidate
       materials (:func:`material_modes`); neighbouring modes merge unless a valley below
       half the lower peak separates them by at least ``max(merge_floor, merge_k * sigma)
       + merge_rel * gray`` (or ``merge_threshold``) gray levels; the term proportional to
       the gray allows for beam hardening, whose errors grow with attenuation (cupping in
       steel and streaks next to it span up to 20% of the gray). A mode holding less than ``min_material_area`` is
       not a material. Merging compares modes, never chains of single triangles, so
       intermediate partial-volume grays cannot join two materials.
    2. Start from all triangles as one component. While a component holds, in two or more
       materials, >= ``min_pocket_area`` of triangles whose gray lies in the material's core
       (within a quarter of the gap to the neighbouring levels) -- the paper: "while the
       gray range is above a threshold"; a pore of a few pixels is enough -- cut it in two with :func:`ctseg.graphcut.graphcut_split` and
       recurse on both sides. The seeds are the interior triangles closest to the darkest
       and brightest materials present, not the paper's darkest and brightest triangles:
       in a real scan those are single noisy or partial-volume triangles, and cutting
       between them shaves off a few triangles per call (measured on the simulated part:
       48 of 49 leaves held 5 triangles or fewer, and polymer stayed inside the air leaf).
       Each side of a cut recurses as its connected pieces (the seed sets of eq. 8 can
       pull a far-away partial-volume triangle to a side by gray alone). Mixed boundary
       triangles go wherever the cut puts them; ``min_triangles`` and ``max_depth`` guard
       against endless splitting.
    3. Each leaf becomes the material that holds most of its interior area, or else, if
       it covers at least 4 x ``min_material_area``, the one material whose core holds its
       triangles (a thin wall has few interior triangles). Any other leaf is a
       partial-volume mix or a small pocket (a steel/polymer mix can have aluminium's
       gray, so gray alone cannot tell): if its
       gray lies between the materials of the leaves around it, it joins the closest of
       those, else the material closest in gray. Two exceptions for thin layers, which
       have no interior triangles: adjacent such leaves that together cover
       4 x ``min_material_area``, more than half of it in one material's core, are that
       material (:func:`_label_fragmented_layers`); and a leaf of at least
       ``min_material_area`` whose gray lies in the core of a material between its
       neighbours' is that material (too large to be a mixed band).
    4. Then triangle by triangle (twice): a triangle that is not interior and whose gray
       lies between the levels of two materials among its own and its neighbours' takes
       the closer of those, i.e. the material that covers most of it
       (:func:`_partial_volume_triangles`; mean boundary distance on the simulated 512 px
       slices 0.35-1.09 -> 0.23-0.87 px).
    5. Materials are numbered 0..K-1 by ascending gray; ``n_materials=K`` merges the least
       separated modes until K remain (ParameterError if the data show fewer than K).

    Parameters
    ----------
    gray : (m,) array_like
        Triangle gray values on the 0-255 scale.
    area : (m,) array_like
        Triangle areas in pixels.
    adjacency : (k, 2) int array_like
        Adjacent triangle pairs.
    centroids : (m, 2) array_like
        Triangle barycentres.
    step_threshold : float, optional
        Default ``max(4 * s, 2)`` gray levels, with s = :func:`step_noise`.
    merge_k, merge_rel, merge_floor, merge_threshold : float
        Mode separation rule (rule 1).
    min_triangles, max_depth : int
        Backstop guards against endless splitting.
    min_material_area : float, optional
        Interior area (px) a gray mode must hold to be a material; default
        ``max(16, 1e-3 * total area)``.
    min_pocket_area : float
        Interior area (px) of a material that makes a component worth splitting.
    n_materials : int, optional
        Exact number of materials wanted.
    theta, lam, beta, eps, edge_length
        Passed to the graph cut (SPEC 6).
    levels : (K,) array_like, optional
        Material gray levels found elsewhere (e.g. :func:`pixel_material_levels` on the
        image, which sees far more samples than the triangles); replaces rule 1.

    Returns
    -------
    MaterialSegmentation

    Raises
    ------
    ParameterError
        Out-of-range parameters, or ``n_materials`` more than the data can give.

    References
    ----------
    Yang et al. 2014, sections 6 and 8.
    """
    f = np.asarray(gray, float)
    area = np.asarray(area, float)
    adjacency = np.asarray(adjacency, np.int64).reshape(-1, 2)
    centroids = np.asarray(centroids, float)
    if f.ndim != 1 or len(f) == 0 or area.shape != f.shape or centroids.shape != (len(f), 2):
        raise ParameterError("segment_triangles: gray, area and centroids must describe the same triangles")
    s = step_noise(f, adjacency, area)
    if step_threshold is None:
        step_threshold = max(4.0 * s, 2.0)
    step_threshold = check_number(step_threshold, "step_threshold", low=0.0)
    merge_k = check_number(merge_k, "merge_k", low=0.0)
    merge_rel = check_number(merge_rel, "merge_rel", low=0.0)
    merge_floor = check_number(merge_floor, "merge_floor", low=0.0)
    if merge_threshold is not None:
        merge_threshold = check_number(merge_threshold, "merge_threshold", low=0.0, low_open=True)
    min_triangles = check_number(min_triangles, "min_triangles", low=1, integer=True)
    max_depth = check_number(max_depth, "max_depth", low=0, integer=True)
    if min_material_area is None:
        min_material_area = max(16.0, 1e-3 * area.sum())
    min_material_area = check_number(min_material_area, "min_material_area", low=0.0)
    min_pocket_area = check_number(min_pocket_area, "min_pocket_area", low=0.0)
    if n_materials is not None:
        n_materials = check_number(n_materials, "n_materials", low=1, integer=True)
    if edge_length is not None:
        edge_length = np.asarray(edge_length, float)
        if edge_length.shape != (len(adjacency),):
            raise ParameterError(f"edge_length: expected shape ({len(adjacency)},), got {edge_length.shape}")
    cut_params = dict(theta=theta, lam=check_number(lam, "lam", low=0.0),
                      beta=check_number(beta, "beta", low=0.0),
                      eps=check_number(eps, "eps", low=0.0, low_open=True))
    if theta is not None:
        check_number(theta, "theta", low=0.0)

    interior = interior_triangles(f, adjacency, step_threshold, 0.5 * merge_rel)
    if not interior.any():
        interior = np.ones(len(f), bool)
    sigma = 0.0
    if levels is not None:
        means = np.sort(np.asarray(levels, float).ravel())
        if n_materials is not None and len(means) != n_materials:
            raise ParameterError(f"levels: {len(means)} levels given for n_materials={n_materials}")
        edges = 0.5 * (means[1:] + means[:-1])
    else:
        sigma = dominant_spread(f[interior], area[interior])
        if merge_threshold is None:
            base = max(merge_floor, merge_k * sigma)
            separation = lambda level: base + merge_rel * level
        else:
            separation = lambda level: merge_threshold
        means, edges = material_modes(f[interior], area[interior], max(sigma, 0.5),
                                      min_material_area if n_materials is None else 0.0,
                                      separation, n_modes=n_materials)
    material, leaf, calls, deepest = _recursive_split(
        f, area, adjacency, centroids, interior, edges, means, min_pocket_area,
        4.0 * min_material_area, min_triangles, max_depth, cut_params, edge_length)
    material = _partial_volume_triangles(f, material, interior, adjacency, means)
    material, mat_gray, used = order_by_gray(material, f, area)
    return MaterialSegmentation(material=material, material_gray=mat_gray,
                                mode_gray=means[used], leaf=leaf, graphcut_calls=calls,
                                max_depth_reached=deepest, step_noise=s,
                                step_threshold=step_threshold, material_noise=sigma)
