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
    return cKDTree(sites).query(points, k=1)[1]


def cvt_energy(rho, sites, labels):
    """CVT energy F = sum_j rho_j ||c_j - x_{label(j)}||^2 over pixels j (paper eq. 4)."""
    rows, cols = rho.shape
    yy, xx = np.mgrid[0:rows, 0:cols]
    s = sites[labels.ravel()]
    d2 = (xx.ravel() - s[:, 0]) ** 2 + (yy.ravel() - s[:, 1]) ** 2
    return float(np.sum(rho.ravel() * d2))


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


def lloyd_cvt(rho, sites, tol=0.01, max_iter=200):
    """Lloyd iterations of the pixel CVT with the paper's corner and border rules.

    Each pixel belongs to the region of its nearest site (pixel centres, Euclidean). Then
    each site moves, in this order of rules:

    1. a region holding an image-corner pixel: the site is fixed at that corner's centre;
    2. else a region holding image-border pixels: the site goes to the rho-weighted
       barycentre of its border pixels (eq. 6); a region that touches two border lines
       without their corner uses the line that carries the larger rho weight, so the site
       stays on a border line;
    3. else the rho-weighted centroid of the region (eq. 5).

    Before the first iteration the site nearest each corner is moved onto it, so the four
    corners are always sites and the Delaunay triangulation covers the image rectangle.
    A region that lost all its pixels keeps its site (counted in ``empty_regions``).
    A rule-2 move that would raise the region's energy (possible: eq. 6 is not the
    constrained minimiser) is not taken for that iteration; this keeps F non-increasing,
    which is what makes Lloyd's method converge.

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

    yy, xx = np.mgrid[0:rows, 0:cols]
    px = np.column_stack([xx.ravel(), yy.ravel()]).astype(np.float64)
    w = rho.ravel()
    wx, wy = w * px[:, 0], w * px[:, 1]
    sites, corner_sites = _pin_corners(sites, rho.shape)
    is_corner_site = np.zeros(n, bool)
    is_corner_site[corner_sites] = True

    # Border pixels, one line at a time (corners excluded: rule 1 owns them).
    border_lines = [
        np.flatnonzero((yy.ravel() == 0) & (xx.ravel() > 0) & (xx.ravel() < cols - 1)),
        np.flatnonzero((yy.ravel() == rows - 1) & (xx.ravel() > 0) & (xx.ravel() < cols - 1)),
        np.flatnonzero((xx.ravel() == 0) & (yy.ravel() > 0) & (yy.ravel() < rows - 1)),
        np.flatnonzero((xx.ravel() == cols - 1) & (yy.ravel() > 0) & (yy.ravel() < rows - 1)),
    ]

    def energy_of(s, lab):
        d = px - s[lab]
        return float(np.sum(w * (d[:, 0] ** 2 + d[:, 1] ** 2)))

    # Hamerly's bounds: u >= distance to the own site, l <= distance to any other site.
    # A pixel can change region only where u > l, so only those are re-queried; the
    # assignment stays exactly the nearest site (the energy argument needs that).
    d, idx = cKDTree(sites).query(px, k=2)
    labels, u, l = idx[:, 0], d[:, 0], d[:, 1]
    energy = [energy_of(sites, labels)]
    empty_total = 0
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        W = np.bincount(labels, w, n)
        empty = W == 0
        empty_total += int(empty.sum())
        Wsafe = np.where(empty, 1.0, W)
        m = np.column_stack([np.bincount(labels, wx, n), np.bincount(labels, wy, n)]) / Wsafe[:, None]
        new = np.where(empty[:, None], sites, m)
        # rule 2: border barycentre on the heaviest border line of the region
        best_w = np.zeros(n)
        bary = np.zeros((n, 2))
        for line in border_lines:
            lab = labels[line]
            bw = np.bincount(lab, w[line], n)
            better = bw > best_w
            if better.any():
                bx = np.bincount(lab, wx[line], n)
                by = np.bincount(lab, wy[line], n)
                bary[better, 0] = bx[better] / bw[better]
                bary[better, 1] = by[better] / bw[better]
                best_w[better] = bw[better]
        on_border = (best_w > 0) & ~is_corner_site
        if on_border.any():
            cand = bary[on_border]
            cur = sites[on_border]
            mm = m[on_border]
            worse = np.sum((cand - mm) ** 2, axis=1) > np.sum((cur - mm) ** 2, axis=1)
            cand[worse] = cur[worse]
            new[on_border] = cand
        new[is_corner_site] = sites[is_corner_site]  # rule 1: corners never move
        drift = np.hypot(*(new - sites).T)
        move = float(drift.max())
        sites = new
        u = u + drift[labels]
        l = l - move
        check = np.flatnonzero(u > l)
        if len(check):
            own = sites[labels[check]]
            u[check] = np.hypot(px[check, 0] - own[:, 0], px[check, 1] - own[:, 1])
            check = check[u[check] > l[check]]
        if len(check):
            d, idx = cKDTree(sites).query(px[check], k=2)
            labels[check], u[check], l[check] = idx[:, 0], d[:, 0], d[:, 1]
        energy.append(energy_of(sites, labels))
        if move < tol:
            converged = True
            break
    return CVTResult(sites=sites, labels=labels.reshape(rows, cols), energy=energy,
                     n_iter=it, converged=converged, empty_regions=empty_total)
