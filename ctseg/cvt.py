"""Stage 3: centroidal Voronoi tessellation of the pixels by Lloyd iterations (paper 5.3, SPEC 3)."""
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ._validate import check_number
from .errors import InputError, ParameterError


@dataclass
class CVTResult:
    """Outcome of :func:`lloyd_cvt`.

    Attributes
    ----------
    sites : (n, 2) ndarray
        Final sites, (x, y) = (col, row) pixel units.
    labels : (rows, cols) int ndarray
        Index of each pixel's nearest final site (its Voronoi region).
    energy : list of float
        CVT energy F (eq. 4) of the starting sites and after every iteration; non-increasing.
    n_iter : int
        Lloyd iterations run.
    converged : bool
        True if the largest site move fell below ``tol``.
    empty_regions : int
        Number of (iteration, site) events where a region had no pixel and its site stayed.
    """

    sites: np.ndarray
    labels: np.ndarray
    energy: list = field(default_factory=list)
    n_iter: int = 0
    converged: bool = False
    empty_regions: int = 0


def nearest_site(points, sites):
    """Index of the nearest site for each point (Euclidean; ties go to the lower index)."""
    return cKDTree(sites).query(points, k=1, workers=-1)[1]


def pixel_centres(shape):
    """(rows * cols, 2) pixel centres (x, y) in row-major order."""
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    return np.column_stack([xx.ravel(), yy.ravel()]).astype(np.float64)


def _energy(px, w, sites, labels):
    d = px - sites[labels]
    return float(np.sum(w * (d[:, 0] ** 2 + d[:, 1] ** 2)))


def cvt_energy(rho, sites, labels):
    """CVT energy F = sum_j rho_j ||c_j - x_{label(j)}||^2 over pixels j (paper eq. 4)."""
    rho = np.asarray(rho, float)
    return _energy(pixel_centres(rho.shape), rho.ravel(), np.asarray(sites, float),
                   np.asarray(labels).ravel())


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


def lloyd_cvt(rho, sites, tol=0.01, max_iter=200, progress=None):
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
    site whose starting region holds border pixels is moved onto that border line (eq. 6),
    so the four corners are always sites, the border lines carry sites, and the Delaunay
    triangulation covers the image rectangle. These classes are then kept: a border site
    stays on its line, a free site stays free (its region may touch the border later; it
    then follows rule 3). A border site moves to eq. (6) when that does not raise its
    region's energy, else to the constrained minimiser (the centroid projected onto its
    line): eq. (6) is not that minimiser, and taking it blindly can raise F. With fixed
    classes and exact nearest-site regions, F never increases, which is what makes Lloyd's
    method converge. A region that lost all its pixels keeps its site (counted in
    ``empty_regions``).

    Parameters
    ----------
    rho : (rows, cols) array_like
        Density (> 0).
    sites : (n, 2) array_like
        Starting sites (x, y) inside the image, n >= 4, all distinct.
    tol : float, optional
        Stop when the largest site displacement is below this, in pixels.
    max_iter : int, optional
        Iteration cap.
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
        Bad tol or max_iter, fewer than 4 sites, or more sites than pixels.

    References
    ----------
    Yang et al. 2014, section 5.3, eqs. (4)-(6).
    """
    rho = np.asarray(rho, dtype=np.float64)
    if rho.ndim != 2 or min(rho.shape) < 2 or not np.all(np.isfinite(rho)) or rho.min() <= 0:
        raise InputError("density: expected a finite 2D array (at least 2 x 2) of values > 0")
    tol = check_number(tol, "tol", low=0.0, low_open=True)
    max_iter = check_number(max_iter, "max_iter", low=0, integer=True)
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

    px = pixel_centres(rho.shape)
    xr, yr = px[:, 0], px[:, 1]
    w = rho.ravel()
    wx, wy = w * px[:, 0], w * px[:, 1]
    sites, corner_sites = _pin_corners(sites, rho.shape)

    # Border lines (corners excluded: rule 1 owns them): (pixel indices, axis held fixed, value)
    inner_x = (xr > 0) & (xr < cols - 1)
    inner_y = (yr > 0) & (yr < rows - 1)
    lines = [(np.flatnonzero((yr == 0) & inner_x), 1, 0.0),
             (np.flatnonzero((yr == rows - 1) & inner_x), 1, rows - 1.0),
             (np.flatnonzero((xr == 0) & inner_y), 0, 0.0),
             (np.flatnonzero((xr == cols - 1) & inner_y), 0, cols - 1.0)]

    def border_barycentres(labels):
        """Per site: the line carrying most of its region's border weight, and eq. (6) there."""
        best_w = np.zeros(n)
        best_line = np.full(n, -1)
        bary = np.zeros((n, 2))
        for k, (idx, axis, value) in enumerate(lines):
            lab = labels[idx]
            bw = np.bincount(lab, w[idx], n)
            better = bw > best_w
            if better.any():
                bary[better, 0] = np.bincount(lab, wx[idx], n)[better] / bw[better]
                bary[better, 1] = np.bincount(lab, wy[idx], n)[better] / bw[better]
                bary[better, axis] = value  # exactly on the line, not value * w / w
                best_w[better] = bw[better]
                best_line[better] = k
        return best_line, bary

    # Constraint of each site, decided once from the starting regions: -2 corner (rule 1),
    # 0..3 on that border line (rule 2), -1 free (rule 3). Keeping the classes fixed is what
    # makes the energy provably non-increasing; re-deciding them every iteration moves
    # sites from the interior onto the border and raises F.
    labels = nearest_site(px, sites)
    constraint = np.full(n, -1)
    line0, bary0 = border_barycentres(labels)
    on = line0 >= 0
    sites[on] = bary0[on]
    constraint[on] = line0[on]
    sites[corner_sites] = [[0, 0], [cols - 1, 0], [0, rows - 1], [cols - 1, rows - 1]]
    constraint[corner_sites] = -2
    if len(np.unique(sites, axis=0)) != n:
        raise InputError("sites: two starting sites coincide after snapping to the border")

    # Hamerly's bounds: u >= distance to the own site, l <= distance to any other site.
    # A pixel can change region only where u > l, so only those are re-queried; the
    # assignment stays exactly the nearest site (the energy argument needs that).
    d, idx = cKDTree(sites).query(px, k=2, workers=-1)
    labels, u, l = idx[:, 0], d[:, 0], d[:, 1]
    # F from per-region sums: sum_j w|p_j - s|^2 = Q - 2 s.S + |s|^2 W over each region,
    # with coordinates taken about the image centre to keep the cancellation small;
    # the same sums give the centroids of the next iteration
    centre = np.array([(cols - 1) / 2.0, (rows - 1) / 2.0])
    q = w * ((xr - centre[0]) ** 2 + (yr - centre[1]) ** 2)

    def region_sums(labels):
        return (np.bincount(labels, w, n), np.bincount(labels, wx, n),
                np.bincount(labels, wy, n), np.bincount(labels, q, n))

    def region_energy(sums, sites):
        W, Sx, Sy, Q = sums
        c = sites - centre
        Sxc, Syc = Sx - centre[0] * W, Sy - centre[1] * W
        return float(np.sum(Q - 2.0 * (c[:, 0] * Sxc + c[:, 1] * Syc)
                            + (c[:, 0] ** 2 + c[:, 1] ** 2) * W))

    sums = region_sums(labels)
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
        for k, (_, axis, value) in enumerate(lines):
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
        sites = new
        u = u + drift[labels]
        # any other site came at most the largest drift among the others closer: the
        # second largest for the pixels whose own site moved most (Hamerly's refinement)
        top = np.argsort(drift)[-2:] if n > 1 else np.array([0, 0])
        l = l - np.where(labels == top[-1], drift[top[0]], move)
        check = np.flatnonzero(u > l)
        if len(check):
            own = sites[labels[check]]
            u[check] = np.hypot(px[check, 0] - own[:, 0], px[check, 1] - own[:, 1])
            check = check[u[check] > l[check]]
        if len(check):
            d, idx = cKDTree(sites).query(px[check], k=2, workers=-1)
            labels[check], u[check], l[check] = idx[:, 0], d[:, 0], d[:, 1]
        sums = region_sums(labels)
        energy.append(region_energy(sums, sites))
        if progress is not None:
            progress(it, max_iter)
        if move < tol:
            converged = True
            break
    return CVTResult(sites=sites, labels=labels.reshape(rows, cols), energy=energy,
                     n_iter=it, converged=converged, empty_regions=empty_total)
