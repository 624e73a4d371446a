"""Stage 3: centroidal Voronoi tessellation of the pixels by Lloyd iterations (paper 5.3, SPEC 3)."""
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from . import _cvt, _threads
from ._cvt import _region_sums
from .errors import InputError, ParameterError
from .params import DEFAULTS, check

_COINCIDENT_PX = 1e-6
"""Free sites closer than this to a border line are put on it, and then those closer than
this to another site dropped, after the iterations."""


@dataclass
class CVTResult:
    """Outcome of :func:`lloyd_cvt`.

    Attributes
    ----------
    sites : (n', 2) ndarray
        Final sites, (x, y) = (col, row) pixel units; usually n' > n (border sites added; a
        free site that ends on another site removed; see
        :func:`lloyd_cvt`).
    labels : (rows, cols) int ndarray
        Index of each pixel's nearest final site (its Voronoi region).
    energy : list of float
        CVT energy F (eq. 4) of the starting sites and after every iteration; non-increasing.
    n_iter : int
        Lloyd iterations run.
    converged : bool
        True if the largest site move fell below ``tol_px``.
    empty_regions : int
        Number of (iteration, site) events where a region had no pixel and its site stayed.
    """

    sites: np.ndarray
    labels: np.ndarray
    energy: list = field(default_factory=list)
    n_iter: int = 0
    converged: bool = False
    empty_regions: int = 0


def _pin_corners(sites, shape):
    """Move the nearest distinct site onto each image corner (rule 1 needs them there)."""
    rows, cols = shape
    corners = np.array([[0, 0], [cols - 1, 0], [0, rows - 1], [cols - 1, rows - 1]], float)
    sites = sites.copy()
    taken = []
    for corner in corners:
        d = np.sum((sites - corner) ** 2, axis=1)
        d[taken] = np.inf
        k = int(np.argmin(d))
        sites[k] = corner
        taken.append(k)
    return sites, np.array(taken)


def lloyd_cvt(rho, sites, tol_px=DEFAULTS.tol_px, max_iter=DEFAULTS.max_iter, progress=None):
    """Lloyd iterations of the pixel CVT with the paper's corner and border rules.

    Each pixel belongs to the region of its nearest site (pixel centres, Euclidean). Then
    each site moves, in this order of rules:

    1. a region holding an image-corner pixel: the site is fixed at that corner's centre;
    2. else a region holding image-border pixels: the site goes to the rho-weighted
       barycentre of its border pixels (eq. 6); a region that touches two border lines
       without their corner uses the line that carries the larger rho weight, so the site
       stays on a border line;
    3. else the rho-weighted centroid of the region (eq. 5).

    Before the first iteration the site nearest each corner is moved onto it, and each
    starting region that holds border pixels gets a border site at its eq. (6) point, so
    the four corners are always sites, the border lines carry sites, and the Delaunay
    triangulation covers the image rectangle. Unlike the paper, these border sites are
    added: the region's own site stays free (unless it already lies on that line). The
    paper's rule moves the site onto the border, and a site that stood on a material edge
    a few pixels inside the image leaves the edge with no site, so the triangles there span
    air and material. The result therefore holds more sites than were given. These
    classes are then kept: a border site stays on its line, a free site stays free (its
    region may touch the border later; it then follows rule 3). A border site moves to
    eq. (6) when that does not raise its region's energy, else to the constrained
    minimiser (the centroid projected onto its line): eq. (6) is not that minimiser, and
    taking it blindly can raise F. With fixed classes and exact nearest-site regions, F
    never increases, which is what makes Lloyd's method converge. A region that lost all
    its pixels keeps its site (counted in ``empty_regions``). After the iterations, a free
    site within a rounding error of a border line is put on it, and one on another site
    removed, so that no Delaunay triangle is flat.

    Parameters
    ----------
    rho : (rows, cols) array_like
        Density (> 0).
    sites : (n, 2) array_like
        Starting sites (x, y) inside the image, n >= 4, all distinct.
    tol_px : float, optional
        Stop when the largest site displacement is below this, in pixels (default in
        :mod:`ctseg.params`).
    max_iter : int, optional
        Iteration cap (default in :mod:`ctseg.params`).
    progress : callable, optional
        Called as ``progress(iteration, max_iter)`` after every iteration.

    Returns
    -------
    CVTResult

    Raises
    ------
    InputError
        Bad density or sites outside the image.
    ParameterError
        Bad tol_px or max_iter, fewer than 4 sites, or more sites than pixels.

    References
    ----------
    Yang et al. 2014, section 5.3, eqs. (4)-(6).

    Example
    -------
    >>> import numpy as np
    >>> from ctseg import lloyd_cvt, ward_sites
    >>> rho = np.ones((32, 32))
    >>> r = lloyd_cvt(rho, ward_sites(rho, 16))
    >>> r.converged, r.labels.shape, r.energy[-1] < r.energy[0]
    (True, (32, 32), True)
    >>> len(r.sites) >= 16  # border sites added, the corners pinned
    True
    """
    rho = np.asarray(rho, dtype=np.float64)
    if rho.ndim != 2 or min(rho.shape) < 2 or not np.all(np.isfinite(rho)) or rho.min() <= 0:
        raise InputError("density: expected a finite 2D array (at least 2 x 2) of values > 0")
    tol_px = check("tol_px", tol_px)
    max_iter = check("max_iter", max_iter)
    sites = np.asarray(sites, dtype=np.float64)
    rows, cols = rho.shape
    if sites.ndim != 2 or sites.shape[1] != 2:
        raise InputError(f"sites: expected shape (n, 2), got {sites.shape}")
    n = len(sites)
    if n < 4:
        raise ParameterError(f"n_sites: need at least 4 sites (the image corners), got {n}")
    if n > rho.size:
        raise ParameterError(f"n_sites: {n} sites exceed the {rho.size} pixels of the image")
    if (not np.all(np.isfinite(sites)) or sites[:, 0].min() < 0 or sites[:, 0].max() > cols - 1
            or sites[:, 1].min() < 0 or sites[:, 1].max() > rows - 1):
        raise InputError("sites: every site must lie inside the image (0..cols-1, 0..rows-1)")

    w = np.ascontiguousarray(rho.ravel())
    sites, corner_sites = _pin_corners(sites, rho.shape)
    sites = np.ascontiguousarray(sites)
    _assign, _reassign = _kernels()

    # Border lines (corners excluded: rule 1 owns them): pixel indices, their weights and
    # weighted coordinates, the axis held fixed and its value
    inner_c = np.arange(1, cols - 1)
    inner_r = np.arange(1, rows - 1)
    lines = []
    for idx, axis, value in ((inner_c, 1, 0.0), ((rows - 1) * cols + inner_c, 1, rows - 1.0),
                             (inner_r * cols, 0, 0.0), (inner_r * cols + cols - 1, 0, cols - 1.0)):
        y, x = np.divmod(idx, cols)
        lines.append((idx, w[idx], w[idx] * x, w[idx] * y, axis, value))

    def border_barycentres(labels):
        """Per site: the line carrying most of its region's border weight, and eq. (6) there."""
        best_w = np.zeros(n)
        best_line = np.full(n, -1)
        bary = np.zeros((n, 2))
        for k, (idx, wl, wxl, wyl, axis, value) in enumerate(lines):
            lab = labels[idx]
            bw = np.bincount(lab, wl, n)
            better = bw > best_w
            if better.any():
                bary[better, 0] = np.bincount(lab, wxl, n)[better] / bw[better]
                bary[better, 1] = np.bincount(lab, wyl, n)[better] / bw[better]
                bary[better, axis] = value  # exactly on the line, not value * w / w
                best_w[better] = bw[better]
                best_line[better] = k
        return best_line, bary

    # Constraint of each site, decided once from the starting regions: -2 corner (rule 1),
    # 0..3 on that border line (rule 2), -1 free (rule 3). Keeping the classes fixed is what
    # makes the energy provably non-increasing; re-deciding them every iteration moves
    # sites from the interior onto the border and raises F.
    labels = np.empty(rows * cols, np.int64)
    u = np.empty(rows * cols)
    l = np.empty(rows * cols)
    # border_barycentres reads the labels of the border lines' pixels only
    border = np.concatenate([line[0] for line in lines])
    border_yx = np.column_stack(np.divmod(border, cols)).astype(np.float64)
    labels[border] = _cvt._nearest_many(np.ascontiguousarray(border_yx[:, ::-1]), sites)
    constraint = np.full(n, -1)
    line0, bary0 = border_barycentres(labels)
    on = line0 >= 0
    # A site already on its region's border line is that line's border site; any other
    # region touching the border keeps its (free) site and adds a border site at eq. (6):
    # a site standing on a material edge a few pixels inside the image stays on the edge.
    gap = np.abs(np.where(line0 < 2, sites[:, 1] - bary0[:, 1], sites[:, 0] - bary0[:, 0]))
    extra = np.flatnonzero(on & (gap > 0))
    on &= gap == 0
    if len(extra):
        # one new site per distinct position not already taken by a border site
        taken = {tuple(p) for p in bary0[on]}
        keep, seen = [], set()
        for k in extra:
            p = tuple(bary0[k])
            if p not in taken and p not in seen:
                seen.add(p)
                keep.append(k)
        keep = np.array(keep, np.int64)
        sites = np.vstack([sites, bary0[keep]])
        on = np.concatenate([on, np.ones(len(keep), bool)])
        line0 = np.concatenate([line0, line0[keep]])
        bary0 = np.vstack([bary0, bary0[keep]])
        n = len(sites)
        constraint = np.full(n, -1)
    sites[on] = bary0[on]
    constraint[on] = line0[on]
    sites[corner_sites] = [[0, 0], [cols - 1, 0], [0, rows - 1], [cols - 1, rows - 1]]
    constraint[corner_sites] = -2
    if len(np.unique(sites, axis=0)) != n:
        raise InputError("sites: two starting sites coincide after snapping to the border")

    # Hamerly's bounds (see _reassign): only pixels whose nearest site may have changed are
    # searched again, and the assignment stays exactly the nearest site (the energy
    # argument needs that).
    _assign(rows, cols, sites, labels, u, l)
    # F from per-region sums: sum_j w|p_j - s|^2 = Q - 2 s.S + |s|^2 W over each region,
    # with coordinates taken about the image centre to keep the cancellation small;
    # the same sums give the centroids of the next iteration
    centre = np.array([(cols - 1) / 2.0, (rows - 1) / 2.0])

    def region_energy(sums, sites):
        W, Sx, Sy, Q = sums
        c = sites - centre
        Sxc, Syc = Sx - centre[0] * W, Sy - centre[1] * W
        return float(np.sum(Q - 2.0 * (c[:, 0] * Sxc + c[:, 1] * Syc)
                            + (c[:, 0] ** 2 + c[:, 1] ** 2) * W))

    sums = _region_sums(labels, w, n, rows, cols, centre[0], centre[1])
    energy = [region_energy(sums, sites)]
    empty_total = 0
    converged = False
    it = 0
    lo = np.array([0.0, 0.0])
    hi = np.array([cols - 1.0, rows - 1.0])
    for it in range(1, max_iter + 1):
        W, Sx, Sy, _ = sums
        empty = W == 0
        empty_total += int(empty.sum())
        Wsafe = np.where(empty, 1.0, W)
        m = np.column_stack([Sx, Sy]) / Wsafe[:, None]
        new = np.where(empty[:, None], sites, m)  # rule 3 (an empty region keeps its site)
        line_now, bary = border_barycentres(labels)
        for k, (_, _, _, _, axis, value) in enumerate(lines):
            sel = np.flatnonzero((constraint == k) & ~empty)
            if len(sel) == 0:
                continue
            # constrained minimiser: the centroid projected onto the line (never raises F)
            proj = m[sel].copy()
            proj[:, axis] = value
            proj[:, 1 - axis] = np.clip(proj[:, 1 - axis], lo[1 - axis] + 1e-6, hi[1 - axis] - 1e-6)
            # eq. (6), the barycentre of the region's border pixels on this line, when it
            # does not raise the region's energy W |x - m|^2 above the current site's
            use6 = line_now[sel] == k
            cur = np.sum((sites[sel] - m[sel]) ** 2, axis=1)
            e6 = np.sum((bary[sel] - m[sel]) ** 2, axis=1)
            use6 &= e6 <= cur
            new[sel] = np.where(use6[:, None], bary[sel], proj)
        new[constraint == -2] = sites[constraint == -2]  # rule 1: corners never move
        drift = np.hypot(*(new - sites).T)
        move = float(drift.max())
        old, sites = sites, np.ascontiguousarray(new)
        _reassign(rows, cols, old, sites, drift, labels, u, l)
        sums = _region_sums(labels, w, n, rows, cols, centre[0], centre[1])
        energy.append(region_energy(sums, sites))
        if progress is not None:
            progress(it, max_iter)
        if move < tol_px:
            converged = True
            break
    sites, snapped = _snap_to_border(sites, constraint, rho.shape)
    sites, dropped = _drop_coincident(sites, constraint)
    if snapped or dropped:  # the regions of the sites returned
        _assign(rows, cols, sites, labels, u, l)
    return CVTResult(sites=sites, labels=labels.reshape(rows, cols), energy=energy,
                     n_iter=it, converged=converged, empty_regions=empty_total)


def _kernels():
    """The pixel assignment and the bound update: threaded unless :data:`ctseg._threads.enabled`
    is off (a slice worker); both give the same result."""
    return _threads.pick((_cvt._assign, _cvt._reassign),
                         (_cvt._assign_parallel, _cvt._reassign_parallel))


def _snap_to_border(sites, constraint, shape):
    """Put free sites within :data:`_COINCIDENT_PX` of a border line exactly on it; returns
    the sites and whether any moved.

    A free site whose region holds only pixels of one border line has its centroid on that
    line, but rounding can leave it a hair off: one pixel at x = cols - 1 has
    ``w * x / w`` = 12.999999999999998 for x = 13. Between two border sites of that line
    it then makes a flat triangle with them (Delaunay's, but of zero area, which
    :func:`ctseg.delaunay_mesh` rejects); on the line, the three are points of one hull
    edge and no triangle is flat. Moving a site by a rounding error leaves the energy as
    it is.
    """
    rows, cols = shape
    sites = sites.copy()
    free = constraint == -1
    moved = False
    for axis, value in ((0, 0.0), (0, cols - 1.0), (1, 0.0), (1, rows - 1.0)):
        near = free & (np.abs(sites[:, axis] - value) < _COINCIDENT_PX) & (sites[:, axis] != value)
        sites[near, axis] = value
        moved |= bool(near.any())
    return np.ascontiguousarray(sites), moved


def _drop_coincident(sites, constraint):
    """Remove free sites within :data:`_COINCIDENT_PX` of another site; returns the sites
    and whether any was removed (the caller re-finds the regions).

    A free site whose region holds only border pixels has its centroid on the border line,
    where rounding can leave it a hair from a border site; Qhull would then leave one of
    the two out of the triangulation. The free site adds nothing there. Removing it does
    not change the energy (its pixels are as near the other site).
    """
    pairs = cKDTree(sites).query_pairs(_COINCIDENT_PX, output_type="ndarray")
    if len(pairs) == 0:
        return sites, False
    drop = set()
    for a, b in pairs:
        if a in drop or b in drop:
            continue
        # keep the corner or border site; of two free sites, the lower index
        drop.add(int(b) if constraint[b] == -1 or constraint[a] != -1 else int(a))
    return np.ascontiguousarray(np.delete(sites, sorted(drop), axis=0)), True
