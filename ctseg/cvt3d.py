"""3D stage 3 (SPEC 9.3): centroidal Voronoi tessellation of the voxels by Lloyd iterations,
in physical units, with corner, edge and face sites that keep the box covered."""
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ._box3d import (CORNER, EDGE, FACE, FREE, SITE_CLASSES, border_voxels, box_features,  # noqa: F401
                     feature_tables, start_sites)
from ._assign3d import _assign_3d
from ._cvt3d import _nearest_many_3d, _own_feature_sums_3d, _reassign_3d, _region_sums_3d
from ._validate import check_spacing
from .errors import InputError, ParameterError
from .params import DEFAULTS, check

_COINCIDENT_VOXELS = 1e-6
"""Sites closer than this (times the smallest spacing) to another site are dropped after
the iterations."""
_MARGIN_VOXELS = 1e-6
"""Face and edge sites stay this far (times the smallest spacing) inside their face or
edge, off the lines and corners of lower dimension."""


@dataclass
class CVT3DResult:
    """Outcome of :func:`lloyd_cvt_3d`.

    Attributes
    ----------
    sites : (n', 3) ndarray
        Final sites (x, y, z), physical; usually n' > n (face and edge sites added).
    labels : (nz, ny, nx) int ndarray
        Index of each voxel's nearest final site (its Voronoi region).
    energy : list of float
        CVT energy F = sum rho |c - site|^2 x voxel volume of the starting sites (after
        the corners were pinned and the border sites added) and after every iteration;
        non-increasing.
    n_iter : int
        Lloyd iterations run.
    converged : bool
        True if the largest site move fell below ``tol_px`` voxels.
    empty_regions : int
        Number of (iteration, site) events where a region had no voxel and its site stayed.
    site_class : (n',) int8 ndarray
        0 free, 1 face, 2 edge, 3 corner (:data:`SITE_CLASSES`).
    site_feature : (n',) int ndarray
        Which face (``2 axis + side``, axis 0..2 = x, y, z, side 0 at 0, 1 at the far end),
        edge (``4 axis + 2 side_b + side_c`` with ``axis`` the edge's direction and b < c
        the other two axes) or corner (``side_x + 2 side_y + 4 side_z``); -1 for free sites.
    coarse_iter : int
        Lloyd iterations on 2 x 2 x 2 voxel blocks before these (:func:`coarse_sites_3d`).
    """

    sites: np.ndarray
    labels: np.ndarray
    energy: list = field(default_factory=list)
    n_iter: int = 0
    converged: bool = False
    empty_regions: int = 0
    site_class: np.ndarray = None
    site_feature: np.ndarray = None
    coarse_iter: int = 0


def _check(rho, sites, spacing, tol_px, max_iter):
    rho = np.asarray(rho, dtype=np.float64)
    if (rho.ndim != 3 or min(rho.shape) < 2 or not np.all(np.isfinite(rho))
            or rho.min() <= 0):
        raise InputError("density: expected a finite 3D array (nz, ny, nx), every side >= 2, "
                         "of values > 0")
    sp = check_spacing(spacing)
    tol_px = check("tol_px", tol_px)
    max_iter = check("max_iter", max_iter)
    sites = np.asarray(sites, dtype=np.float64)
    if sites.ndim != 2 or sites.shape[1] != 3:
        raise InputError(f"sites: expected shape (n, 3), got {sites.shape}")
    n = len(sites)
    if n < 8:
        raise ParameterError(f"n_sites: need at least 8 sites (the box corners), got {n}")
    if n > rho.size:
        raise ParameterError(f"n_sites: {n} sites exceed the {rho.size} voxels of the volume")
    hi = (np.array(rho.shape[::-1]) - 1) * sp
    if not np.all(np.isfinite(sites)) or np.any(sites < 0) or np.any(sites > hi):
        raise InputError(f"sites: every site must lie inside the box [0, {hi[0]:g}] x "
                         f"[0, {hi[1]:g}] x [0, {hi[2]:g}] (physical units)")
    if len(np.unique(sites, axis=0)) != n:
        raise InputError("sites: two sites coincide")
    return rho, sites, sp, hi, tol_px, max_iter


def lloyd_cvt_3d(rho, sites, spacing=(1.0, 1.0, 1.0), tol_px=DEFAULTS.tol_px,
                 max_iter=DEFAULTS.max_iter, progress=None,
                 energy_rtol_3d=DEFAULTS.energy_rtol_3d,
                 overrelaxation_3d=DEFAULTS.overrelaxation_3d):
    """Lloyd iterations of the voxel CVT, in physical units, with box-keeping site classes.

    Each voxel belongs to the region of its nearest site (physical Euclidean distance from
    the voxel centre (i sx, j sy, k sz); ties to the lower site index). Site classes are
    fixed at the start, by the box ``[0, (nx-1) sx] x [0, (ny-1) sy] x [0, (nz-1) sz]``:

    - corner: the site nearest each of the 8 corner voxel centres is moved onto it, and
      stays there;
    - edge: moves along its edge line (one of 12); face: moves within its face plane (one
      of 6), at least 1e-6 voxels off the edges. The site goes to the rho-weighted
      barycentre of its region's voxels on that edge or face (the 3D eq. 6) when that does
      not raise its region's energy ``W |x - m|^2`` above the current site's, else to the
      constrained minimiser, the region's centroid m projected onto the line or plane and
      clipped into it;
    - free: from ``s`` to ``s + w (m - s)``, m the rho-weighted centroid of its region
      (eq. 5 when ``w = overrelaxation_3d`` is 1), or to m where that point would leave
      the box. With the regions fixed a region's energy is ``W |x - m|^2`` plus a
      constant, which this step multiplies by ``(1 - w)^2 <= 1`` for ``1 <= w < 2``; the
      new regions only lower it further.

    Before the first iteration, after the corners are pinned, a starting site that lies
    on an edge line (else a face plane) whose interior voxels its region holds becomes
    that edge's (face's) site, at its barycentre there. Then, as in 2D, border sites are
    added: every starting region holding interior voxels of an edge or face (corner voxels
    excluded from edges, edge voxels from faces) whose site is not on that closed edge or
    face gets a new site of that class at the barycentre of those voxels, and keeps its
    own site, so a site on a material edge near the box stays on the edge. An edge or face
    whose interior voxels all belong to sites on it or on its border (corners, say) and
    that has no site of its own gets one from the region holding the largest weight
    there. So every face and edge with interior voxels holds sites of its own, and with
    the 8 corners the Delaunay tetrahedra of the sites cover the box. With fixed classes
    and exact nearest-site regions the energy ``F = sum rho |c - site|^2 x (sx sy sz)``
    never increases. A region that lost all its voxels keeps its site (counted in
    ``empty_regions``). After the iterations a site within 1e-6 voxels of another is
    removed (a free one first, else the lower class: coincident sites break the Delaunay
    tetrahedra), and the regions are found again.

    Parameters
    ----------
    rho : (nz, ny, nx) array_like
        Density (> 0), e.g. from :func:`ctseg.density.density_volume`.
    sites : (n, 3) array_like
        Starting sites (x, y, z), physical, inside the box, distinct, n >= 8.
    spacing : (3,) array_like, optional
        Voxel spacing (sx, sy, sz), each > 0.
    tol_px : float, optional
        Stop when the largest site move is below ``tol_px`` times the smallest spacing.
    energy_rtol_3d : float, optional
        Also stop when an iteration lowers the energy by less than this share of it (the
        energy of a voxel CVT flattens long before the sites stop moving by ``tol_px``);
        0 turns this off.
    overrelaxation_3d : float, optional
        The free sites' step factor ``w``, in [1, 2).
    max_iter : int, optional
        Iteration cap.
    progress : callable, optional
        Called as ``progress(iteration, max_iter)`` after every iteration.

    Returns
    -------
    CVT3DResult

    Raises
    ------
    InputError
        A bad density, or sites outside the box or coincident.
    ParameterError
        A bad spacing, tol_px or max_iter, fewer than 8 sites, or more sites than voxels.

    Example
    -------
    >>> import numpy as np
    >>> from ctseg.sites import ward_sites_3d
    >>> rho = np.ones((8, 10, 12))
    >>> r = lloyd_cvt_3d(rho, ward_sites_3d(rho, 20, (1, 1, 2)), spacing=(1, 1, 2))
    >>> r.labels.shape, r.energy[-1] < r.energy[0], int((r.site_class == CORNER).sum())
    ((8, 10, 12), True, 8)
    """
    rho, sites, sp, hi, tol_px, max_iter = _check(rho, sites, spacing, tol_px, max_iter)
    energy_rtol = check("energy_rtol_3d", energy_rtol_3d)
    omega = check("overrelaxation_3d", overrelaxation_3d)
    nz, ny, nx = rho.shape
    sx, sy, sz = (float(v) for v in sp)
    w = np.ascontiguousarray(rho.ravel())
    feats = box_features((nx, ny, nz), sp)
    # the kernels' per-voxel state, in half-size types (see ctseg._cvt3d)
    labels, second = np.empty(rho.size, np.int32), np.empty(rho.size, np.int32)
    u, l2, l3 = (np.empty(rho.size, np.float32) for _ in range(3))
    state = (labels, second, u, l2, l3)

    def assign(s):
        _assign_3d(nz, ny, nx, sx, sy, sz, np.ascontiguousarray(s), *state)
        return labels

    border_idx, border_xyz = border_voxels(feats)

    def border_labels(s):  # start_sites reads the labels of the face and edge voxels only
        labels[border_idx] = _nearest_many_3d(border_xyz, np.ascontiguousarray(s))
        return labels

    sites, cls, feat = start_sites(sites, border_labels, hi, feats, w)
    n = len(sites)
    voxel_feature, site_feature, fixed_mask, fixed_value = feature_tables(feats, cls, feat)
    border_sites = np.flatnonzero(site_feature >= 0)
    assign(sites)
    centre = hi / 2.0
    vox = sx * sy * sz

    def energy_of(sums, s):
        c = s - centre
        return vox * float(np.sum(sums[4] - 2.0 * np.sum(c * sums[1:4].T, axis=1)
                                  + np.sum(c * c, axis=1) * sums[0]))

    sums = _region_sums_3d(labels, w, n, nz, ny, nx, sx, sy, sz, centre)
    energy = [energy_of(sums, sites)]
    margin = _MARGIN_VOXELS * sp.min()
    empty_total, converged, it = 0, False, 0
    for it in range(1, max_iter + 1):
        empty = sums[0] == 0
        empty_total += int(empty.sum())
        m = centre + sums[1:4].T / np.where(empty, 1.0, sums[0])[:, None]
        new = np.where(empty[:, None], sites, m)  # free: eq. 5; an empty region stays
        if omega != 1.0:  # over-relaxed; a step that would leave the box stays Lloyd's
            over = sites + omega * (new - sites)
            new = np.where(np.all((over >= 0) & (over <= hi), axis=1)[:, None], over, new)
        sel = border_sites[~empty[border_sites]]
        if len(sel):
            sums_b = _own_feature_sums_3d(border_idx, border_xyz, voxel_feature, labels, w, site_feature,
                                          n)[:, sel]
            bw = sums_b[0]
            b = np.where(fixed_mask[sel], fixed_value[sel],
                         (sums_b[1:4] / np.where(bw > 0, bw, 1.0)).T)  # eq. 6 on the feature
            # the constrained minimiser: never raises F
            proj = np.where(fixed_mask[sel], fixed_value[sel], np.clip(m[sel], margin, hi - margin))
            cur = np.sum((sites[sel] - m[sel]) ** 2, axis=1)
            e6 = np.sum((b - m[sel]) ** 2, axis=1)
            use6 = (bw > 0) & (e6 <= cur)
            new[sel] = np.where(use6[:, None], b, proj)
        new[cls == CORNER] = sites[cls == CORNER]
        drift = np.sqrt(np.sum((new - sites) ** 2, axis=1))
        move = float(drift.max())
        old, sites = sites, np.ascontiguousarray(new)
        _reassign_3d(nz, ny, nx, sx, sy, sz, old, sites, drift, *state)
        sums = _region_sums_3d(labels, w, n, nz, ny, nx, sx, sy, sz, centre)
        energy.append(energy_of(sums, sites))
        if progress is not None:
            progress(it, max_iter)
        if move < tol_px * sp.min():
            converged = True
            break
        if energy[-2] - energy[-1] < energy_rtol * energy[-2]:
            break
    keep = _not_coincident(sites, cls, _COINCIDENT_VOXELS * sp.min())
    if not keep.all():
        sites, cls, feat = np.ascontiguousarray(sites[keep]), cls[keep], feat[keep]
        assign(sites)
    return CVT3DResult(sites=sites, labels=labels.astype(np.int64).reshape(rho.shape), energy=energy,
                       n_iter=it, converged=converged, empty_regions=empty_total,
                       site_class=cls, site_feature=feat)


def coarse_sites_3d(rho, sites, spacing=(1.0, 1.0, 1.0), **lloyd_kw):
    """Starting sites moved by Lloyd on the density averaged over 2 x 2 x 2 voxel blocks.

    The block means form a volume of ``n // 2`` voxels per axis at twice the spacing; the
    sites are scaled from the voxel box ``[0, (n - 1) s]`` onto the coarse box
    ``[0, (n // 2 - 1) 2 s]`` (per axis), moved by :func:`lloyd_cvt_3d` there, and scaled
    back, so corner, edge and face sites land on the voxel box's corners, edges and faces.
    Lloyd's slow, long-range moves then cost an eighth of the voxels; the iterations on the
    voxels that follow only settle the sites locally. Where a side would have fewer than
    2 blocks, or the blocks are fewer than the sites, the sites come back unchanged.

    Parameters
    ----------
    rho : (nz, ny, nx) array_like
        Density (> 0).
    sites : (n, 3) array_like
        Starting sites (x, y, z), physical, inside the voxel box, distinct, n >= 8.
    spacing : (3,) array_like, optional
        Voxel spacing (sx, sy, sz).
    **lloyd_kw
        ``tol_px``, ``max_iter``, ``energy_rtol_3d``, ``overrelaxation_3d``, ``progress``
        of the coarse :func:`lloyd_cvt_3d`.

    Returns
    -------
    sites : (n', 3) ndarray
        Inside the voxel box, distinct (n' >= n: the coarse run adds face and edge sites).
    n_iter : int
        Coarse Lloyd iterations (0 where the sites came back unchanged).

    Raises
    ------
    InputError, ParameterError
        As :func:`lloyd_cvt_3d`.

    Example
    -------
    >>> from ctseg.sites import ward_sites_3d
    >>> rho = np.ones((16, 16, 16))
    >>> s, it = coarse_sites_3d(rho, ward_sites_3d(rho, 40, (1, 1, 1)), max_iter=20)
    >>> bool(s.min() >= 0 and s.max() <= 15), 0 < it <= 20
    (True, True)
    """
    rho, sites, sp, hi, _, _ = _check(rho, sites, spacing, DEFAULTS.tol_px, DEFAULTS.max_iter)
    half = np.array(rho.shape) // 2  # (cz, cy, cx)
    if half.min() < 2 or int(np.prod(half)) < len(sites):
        return sites, 0
    cz, cy, cx = (int(v) for v in half)
    blocks = rho[:2 * cz, :2 * cy, :2 * cx].reshape(cz, 2, cy, 2, cx, 2).mean(axis=(1, 3, 5))
    hi_coarse = (np.array([cx, cy, cz], float) - 1.0) * 2.0 * sp
    coarse = lloyd_cvt_3d(blocks, np.clip(sites * (hi_coarse / hi), 0.0, hi_coarse), 2.0 * sp,
                          **lloyd_kw)
    fine = np.clip(coarse.sites * (hi / hi_coarse), 0.0, hi)
    fine = np.where(coarse.sites == hi_coarse, hi, fine)  # exactly on the far faces
    keep = _not_coincident(fine, coarse.site_class, _COINCIDENT_VOXELS * sp.min())
    return np.ascontiguousarray(fine[keep]), coarse.n_iter


def _not_coincident(sites, cls, radius):
    """Mask of the sites to keep: of two within ``radius``, the higher class (corner >
    edge > face > free) stays, of equal classes the lower index. A free site whose region
    holds only face voxels has its centroid on the face, where rounding can leave it a
    hair from a face site; removing it leaves the energy as it was (its voxels are as near
    the other site)."""
    keep = np.ones(len(sites), bool)
    for a, b in cKDTree(sites).query_pairs(radius, output_type="ndarray"):
        if keep[a] and keep[b]:
            keep[a if cls[a] < cls[b] else b] = False
    return keep
