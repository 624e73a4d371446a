"""Stage 2: initial CVT sites: Ward's method, random and density-weighted random (paper 5.2,
SPEC 2; on voxels SPEC 9.2)."""
import numpy as np

from ._validate import check_number, check_spacing
from ._ward import ROUNDS_PER_SITE, _block_sums_3d, _ward_merges, reciprocal_premerge
from .errors import InputError, ParameterError
from .params import AUTO, DEFAULTS, SPECS, check

INIT_METHODS = SPECS["init"].choices
"""The initialisations :func:`initial_sites` knows ('ward' is the paper's)."""


def _check_density(rho):
    rho = np.asarray(rho, dtype=np.float64)
    if rho.ndim != 2 or min(rho.shape) < 2:
        raise InputError(f"density: expected a 2D array of at least 2 x 2, got shape {rho.shape}")
    if not np.all(np.isfinite(rho)) or rho.min() <= 0:
        raise InputError("density: values must be finite and > 0")
    return rho


def _check_n_sites(n_sites, n_pixels):
    n_sites = check_number(n_sites, "n_sites", low=4, integer=True)
    if n_sites > n_pixels:
        raise ParameterError(
            f"n_sites: {n_sites} sites for an image of only {n_pixels} pixels; "
            f"use at most {n_pixels} (each site sits in its own pixel)"
        )
    return n_sites


def ward_agglomerate(weights, centroids, edges, n_clusters):
    """Connectivity-constrained weighted Ward clustering of a graph's nodes.

    Merges, at each step, the adjacent pair of clusters whose merge raises the weighted
    energy least, ``Delta(A, B) = W_A W_B / (W_A + W_B) * ||m_A - m_B||^2`` (weight sums W,
    weighted centroids m; Ward 1963), until ``n_clusters`` remain. A heap with lazy invalidation makes it O(E log E).
    Ties are broken by the smaller node index so the result is deterministic.

    Parameters
    ----------
    weights : (m,) array_like
        Positive node weights (sum of rho over the node's pixels).
    centroids : (m, d) array_like
        Weighted centroid of each node (d = 2 for pixels, 3 for voxels).
    edges : (e, 2) int array_like
        Node pairs allowed to merge (the graph must be connected).
    n_clusters : int
        Number of clusters to stop at, 1 <= n_clusters <= m.

    Returns
    -------
    labels : (m,) int ndarray
        Cluster of each node, numbered 0..n_clusters-1 in order of first appearance.
    cluster_weights : (n_clusters,) ndarray
    cluster_centroids : (n_clusters, d) ndarray

    References
    ----------
    Ward 1963; Yang et al. 2014, section 5.2.
    """
    w = np.ascontiguousarray(weights, dtype=np.float64).copy()
    c = np.asarray(centroids, dtype=np.float64)
    s = np.ascontiguousarray(c * w[:, None])
    m = len(w)
    if m >= 2**31:  # the merge heap packs a pair in one int64: i * m + j
        raise InputError(f"Ward clustering: {m} nodes, at most 2^31 - 1; use larger blocks")
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    edges = edges[edges[:, 0] != edges[:, 1]]
    parent, n_alive = _ward_merges(w, s, np.ascontiguousarray(edges[:, 0]),
                                   np.ascontiguousarray(edges[:, 1]), m, int(n_clusters))
    if n_alive > n_clusters:
        raise InputError(f"Ward clustering: the adjacency graph is disconnected; stopped at "
                         f"{n_alive} clusters")
    root = np.array(parent)
    while not np.array_equal(root[root], root):  # each node to its cluster's root
        root = root[root]
    roots, labels = np.unique(root, return_inverse=True)
    return labels.reshape(-1), w[roots], s[roots] / w[roots, None]


def _block_graph(rho, block_px):
    """Pre-merge pixels into block_px x block_px blocks; return weights, centroids, edges."""
    rows, cols = rho.shape
    br = np.arange(rows) // block_px
    bc = np.arange(cols) // block_px
    nbr, nbc = br[-1] + 1, bc[-1] + 1
    block = (br[:, None] * nbc + bc[None, :]).ravel()
    yy, xx = np.mgrid[0:rows, 0:cols]
    r = rho.ravel()
    nb = nbr * nbc
    w = np.bincount(block, r, nb)
    cx = np.bincount(block, r * xx.ravel(), nb) / w
    cy = np.bincount(block, r * yy.ravel(), nb) / w
    ids = np.arange(nb).reshape(nbr, nbc)
    e = np.concatenate([
        np.column_stack([ids[:, :-1].ravel(), ids[:, 1:].ravel()]),
        np.column_stack([ids[:-1, :].ravel(), ids[1:, :].ravel()]),
    ])
    return w, np.column_stack([cx, cy]), e


def default_ward_block_px(shape, n_sites):
    """Block size for Ward's pre-merge: about 16 blocks per final site, at least 1 pixel.

    The value of ``ward_block_px='auto'``. The pre-merge may not raise the final CVT energy
    over exact Ward's (``ward_block_px=1``) by 1% or more on average;
    ``tests/test_sites.py::test_block_premerge_energy`` checks it.
    """
    return max(1, int(np.sqrt(shape[0] * shape[1] / (16.0 * n_sites))))


def ward_sites(rho, n_sites, ward_block_px=DEFAULTS.ward_block_px):
    """Initial sites by connectivity-constrained, rho-weighted Ward clustering of the pixels.

    Parameters
    ----------
    rho : (rows, cols) array_like
        Density map (> 0), e.g. from :func:`ctseg.density_map`.
    n_sites : int
        Number of sites, 4 <= n_sites <= number of pixels.
    ward_block_px : int or 'auto', optional
        Pre-merge pixels into square blocks of this side before Ward (1 = exact Ward on
        the pixels); 'auto' (or None): :func:`default_ward_block_px`.

    Returns
    -------
    sites : (n_sites, 2) float64 ndarray
        Weighted cluster centroids as (x, y) = (col, row) in pixel units.

    Raises
    ------
    InputError, ParameterError

    References
    ----------
    Yang et al. 2014, section 5.2; Ward 1963.

    Example
    -------
    >>> import numpy as np
    >>> from ctseg import ward_sites
    >>> sites = ward_sites(np.ones((20, 30)), 12)
    >>> sites.shape
    (12, 2)
    >>> bool(sites[:, 0].max() <= 29 and sites[:, 1].max() <= 19)
    True
    """
    rho = _check_density(rho)
    n_sites = _check_n_sites(n_sites, rho.size)
    block_px = check("ward_block_px", ward_block_px)
    if block_px == AUTO:
        block_px = default_ward_block_px(rho.shape, n_sites)
    w, c, e = _block_graph(rho, block_px)
    if len(w) < n_sites:  # blocks too coarse for this many sites: fall back to pixels
        w, c, e = _block_graph(rho, 1)
    _, _, centroids = ward_agglomerate(w, c, e, n_sites)
    # a weighted mean of pixel centres can land one rounding error outside the image
    centroids[:, 0] = np.clip(centroids[:, 0], 0, rho.shape[1] - 1)
    centroids[:, 1] = np.clip(centroids[:, 1], 0, rho.shape[0] - 1)
    return centroids


def random_sites(shape, n_sites, seed=DEFAULTS.seed):
    """n_sites distinct pixel centres drawn uniformly (the baseline of SPEC 2)."""
    n_pix = int(shape[0]) * int(shape[1])
    n_sites = _check_n_sites(n_sites, n_pix)
    rng = np.random.default_rng(seed)
    idx = rng.choice(n_pix, size=n_sites, replace=False)
    r, c = np.divmod(idx, int(shape[1]))
    return np.column_stack([c, r]).astype(np.float64)


def density_random_sites(rho, n_sites, seed=DEFAULTS.seed):
    """n_sites distinct pixel centres drawn with probability proportional to rho."""
    rho = _check_density(rho)
    n_sites = _check_n_sites(n_sites, rho.size)
    rng = np.random.default_rng(seed)
    p = rho.ravel() / rho.sum()
    idx = rng.choice(rho.size, size=n_sites, replace=False, p=p)
    r, c = np.divmod(idx, rho.shape[1])
    return np.column_stack([c, r]).astype(np.float64)


def initial_sites(rho, n_sites, init=DEFAULTS.init, seed=DEFAULTS.seed,
                  ward_block_px=DEFAULTS.ward_block_px):
    """Initial CVT sites by one of :data:`INIT_METHODS`.

    Parameters
    ----------
    rho : (rows, cols) array_like
        Density map (> 0), e.g. from :func:`ctseg.density_map`.
    n_sites : int
        Number of sites, 4 <= n_sites <= number of pixels.
    init : {'ward', 'random', 'density_random'}, optional
        :func:`ward_sites` (the paper's), :func:`random_sites` or
        :func:`density_random_sites`.
    seed : int, optional
        Seed of the random initialisations (Ward's is deterministic).
    ward_block_px : int or 'auto', optional
        Ward's pre-merge block side (see :func:`ward_sites`); only used by 'ward'.

    Returns
    -------
    sites : (n_sites, 2) float64 ndarray
        (x, y) = (col, row) in pixel units.

    Raises
    ------
    InputError, ParameterError

    Example
    -------
    >>> import numpy as np
    >>> from ctseg import initial_sites
    >>> rho = np.ones((20, 30))
    >>> initial_sites(rho, 10).shape
    (10, 2)
    >>> a = initial_sites(rho, 10, init="random", seed=3)
    >>> bool(np.array_equal(a, initial_sites(rho, 10, init="random", seed=3)))
    True
    """
    init = check("init", init)
    if init == "ward":
        return ward_sites(rho, n_sites, ward_block_px=ward_block_px)
    if init == "random":
        return random_sites(np.shape(rho), n_sites, seed=seed)
    return density_random_sites(rho, n_sites, seed=seed)


# ---- 3D (SPEC 9.2): sites (x, y, z) in physical units, voxel (k, j, i) at (i sx, j sy, k sz)

def _checked_3d(rho, n_sites, spacing):
    """rho (3D, every side >= 2, finite, > 0: else InputError), n_sites (8..voxels) and the
    spacing, checked."""
    rho = np.asarray(rho, dtype=np.float64)
    if rho.ndim != 3 or min(rho.shape) < 2:
        raise InputError(f"density: expected a 3D array (nz, ny, nx) with every side >= 2, "
                         f"got shape {rho.shape}")
    if not np.all(np.isfinite(rho)) or rho.min() <= 0:
        raise InputError("density: values must be finite and > 0")
    n_sites = check_number(n_sites, "n_sites", low=8, integer=True)
    if n_sites > rho.size:
        raise ParameterError(f"n_sites: {n_sites} sites for a volume of only {rho.size} voxels; "
                             f"use at most {rho.size} (each site sits in its own voxel)")
    return rho, n_sites, check_spacing(spacing)


def ward_block_sides_3d(shape, spacing, n_sites, ward_block_px=DEFAULTS.ward_block_px):
    """Voxels per Ward pre-merge block along (z, y, x).

    ``ward_block_px`` is the side in voxels along the finest axis; along an axis of spacing
    s it is ``max(1, round(ward_block_px * min(spacing) / s))``: about cubes in physical
    units. 'auto' (or None): ``int(L / min(spacing))`` with ``L**3 = volume / (16
    n_sites)``, about 16 blocks per final site (as :func:`default_ward_block_px` in 2D).
    """
    sp = check_spacing(spacing)
    block_px = check("ward_block_px", ward_block_px)
    if block_px == AUTO:
        vol = float(np.prod(shape)) * float(np.prod(sp))
        block_px = max(1, int(np.cbrt(vol / (16.0 * n_sites)) / sp.min()))
    return tuple(max(1, int(round(block_px * sp.min() / s))) for s in sp[::-1])


def _block_graph_3d(rho, sp, sides):
    """Pre-merge voxels into blocks of ``sides`` (z, y, x) voxels: weights, physical
    weighted centroids (x, y, z) and the 6-connected block adjacency."""
    nb = tuple(-(-n // b) for n, b in zip(rho.shape, sides))
    sums = _block_sums_3d(np.ascontiguousarray(rho, np.float64), np.array(sides, np.int64),
                          np.asarray(sp, np.float64))
    w = sums[0]
    cols = sums[1:] / w
    ids = np.arange(w.size).reshape(nb)
    e = np.concatenate([np.column_stack([a.ravel(), b.ravel()]) for a, b in (
        (ids[:, :, :-1], ids[:, :, 1:]), (ids[:, :-1], ids[:, 1:]), (ids[:-1], ids[1:]))])
    return w, np.ascontiguousarray(cols.T), e


def _voxel_sites(flat, shape, sp):
    k, j, i = np.unravel_index(flat, shape)
    return np.column_stack([i * sp[0], j * sp[1], k * sp[2]]).astype(np.float64)


def ward_sites_3d(rho, n_sites, spacing=(1.0, 1.0, 1.0), ward_block_px=DEFAULTS.ward_block_px):
    """Initial 3D sites by connectivity-constrained, rho-weighted Ward clustering of voxels.

    Voxels are pre-merged into blocks (:func:`ward_block_sides_3d`; 1 = exact Ward), blocks
    by rounds of reciprocal Ward pairs to 4 clusters per site
    (:func:`ctseg._ward.reciprocal_premerge`), then :func:`ward_agglomerate` merges to
    ``n_sites`` (weights: sums of rho); the sites are the clusters' rho-weighted centroids,
    physical. Blocks coarser than ``n_sites`` fall back to voxels.

    Parameters
    ----------
    rho : (nz, ny, nx) array_like
        Density (> 0), e.g. from :func:`ctseg.density.density_volume`.
    n_sites : int
        Number of sites, 8 <= n_sites <= number of voxels.
    spacing : (3,) array_like, optional
        Voxel spacing (sx, sy, sz), each > 0.
    ward_block_px : int or 'auto', optional
        Block side in voxels along the finest axis (see :func:`ward_block_sides_3d`).

    Returns
    -------
    sites : (n_sites, 3) float64 ndarray
        (x, y, z) physical, inside the box ``[0, (nx-1) sx] x [0, (ny-1) sy] x [0, (nz-1) sz]``.

    Raises
    ------
    InputError
        A density that is not 3D, finite and > 0 (ParameterError: a bad count, spacing, side).

    Example
    -------
    >>> import numpy as np
    >>> s = ward_sites_3d(np.ones((6, 8, 10)), 20, spacing=(0.5, 0.5, 1.5))
    >>> s.shape, bool(s[:, 2].max() <= 7.5)
    ((20, 3), True)
    """
    rho, n_sites, sp = _checked_3d(rho, n_sites, spacing)
    sides = ward_block_sides_3d(rho.shape, sp, n_sites, ward_block_px)
    w, c, e = _block_graph_3d(rho, sp, sides)
    if len(w) < n_sites:  # blocks too coarse for this many sites: fall back to voxels
        w, c, e = _block_graph_3d(rho, sp, (1, 1, 1))
    elif max(sides) > 1 and len(w) > ROUNDS_PER_SITE * n_sites:
        w, c, e = reciprocal_premerge(w, c, e, ROUNDS_PER_SITE * n_sites)
    _, _, centroids = ward_agglomerate(w, c, e, n_sites)
    hi = (np.array(rho.shape[::-1]) - 1) * sp  # a weighted mean can round past the box
    return np.clip(centroids, 0.0, hi)


def random_sites_3d(shape, n_sites, spacing=(1.0, 1.0, 1.0), seed=DEFAULTS.seed):
    """n_sites distinct voxel centres drawn uniformly, (x, y, z) physical."""
    rho, n_sites, sp = _checked_3d(np.ones(tuple(int(v) for v in shape)), n_sites, spacing)
    idx = np.random.default_rng(seed).choice(rho.size, size=n_sites, replace=False)
    return _voxel_sites(idx, rho.shape, sp)


def density_random_sites_3d(rho, n_sites, spacing=(1.0, 1.0, 1.0), seed=DEFAULTS.seed):
    """n_sites distinct voxel centres drawn with probability proportional to rho, (x, y, z)
    physical.

    Example
    -------
    >>> import numpy as np
    >>> s = density_random_sites_3d(np.ones((4, 5, 6)), 10, spacing=(1, 1, 2), seed=1)
    >>> s.shape, bool(np.all(s[:, 2] % 2 == 0))
    ((10, 3), True)
    """
    rho, n_sites, sp = _checked_3d(rho, n_sites, spacing)
    p = rho.ravel() / rho.sum()
    idx = np.random.default_rng(seed).choice(rho.size, size=n_sites, replace=False, p=p)
    return _voxel_sites(idx, rho.shape, sp)


def initial_sites_3d(rho, n_sites, spacing=(1.0, 1.0, 1.0), init=DEFAULTS.init,
                     seed=DEFAULTS.seed, ward_block_px=DEFAULTS.ward_block_px):
    """Initial 3D CVT sites by one of :data:`INIT_METHODS`.

    Parameters
    ----------
    rho, n_sites, spacing, ward_block_px
        As :func:`ward_sites_3d` (the block side only used by 'ward').
    init : {'ward', 'random', 'density_random'}, optional
        :func:`ward_sites_3d`, :func:`random_sites_3d` or :func:`density_random_sites_3d`.
    seed : int, optional
        Seed of the random initialisations (Ward's is deterministic).

    Returns
    -------
    sites : (n_sites, 3) float64 ndarray
        (x, y, z) physical.

    Raises
    ------
    InputError, ParameterError

    Example
    -------
    >>> import numpy as np
    >>> rho = np.ones((6, 7, 8))
    >>> [initial_sites_3d(rho, 12, init=m).shape for m in INIT_METHODS]
    [(12, 3), (12, 3), (12, 3)]
    """
    init = check("init", init)
    if init == "ward":
        return ward_sites_3d(rho, n_sites, spacing, ward_block_px=ward_block_px)
    if init == "random":
        return random_sites_3d(np.shape(rho), n_sites, spacing, seed=seed)
    return density_random_sites_3d(rho, n_sites, spacing, seed=seed)
