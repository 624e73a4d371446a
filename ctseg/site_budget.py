"""How many CVT sites a 2D slice gets: from its boundary length, not only its size.

One site per ``pixels_per_site`` pixels gives a large flat part the same mesh as a slice of
sand grains of the same size; the grains have twenty times the boundary and their triangles
come out too large to follow it. :func:`site_budget` counts the sites a slice needs from
its boundary length, measured on the image (:func:`boundary_length`).
"""
import numpy as np
from scipy import ndimage
from scipy.special import ndtri

from ._validate import as_image
from .params import DEFAULTS, check

MEAN_RIDGE_DENSITY = 2.0 * np.sqrt(2.0) / np.pi
"""Edge pixels per pixel of boundary length after non-maximum suppression, averaged over
the boundary's direction (a line at angle t from the nearer axis leaves cos t pixels per
unit length; the mean of cos over [0, pi/4] is 2 sqrt 2 / pi = 0.90)."""

EDGE_NOISE_K = 4.0
"""An edge pixel's gradient is at least this many noise standard deviations of one
gradient component (noise alone passes with probability exp(-8) = 3e-4)."""

EDGE_CONTRAST_FRACTION = 0.02
"""...and at least this fraction of the image's gray span per pixel (an ideal step of the
full span smoothed by sigma = 1 px peaks at 0.4 span/px), so a noiseless image counts
only steps of at least 1/20 of its span (a scan with steel has aluminium and polymer
edges of a tenth of it and less)."""


DENSE_SPACING_FRACTION = 0.5
"""Where boundaries are everywhere, sites a uniform ``DENSE_SPACING_FRACTION`` of the
mean boundary spacing apart (see :func:`site_budget`)."""


def _noise_sigma(img):
    """Robust pixel noise: the MAD of adjacent-pixel differences (as
    :func:`ctseg.intensity.estimate_noise`). When most differences are exactly 0 the MAD
    is 0 whatever the noise, and the nonzero differences tell why. Most of them one step q
    (the smallest): a quantized scan whose noise is below q; a normal difference of sd s_d
    rounds to 0 with probability p0 = P(|d| < q / 2), so the share p0 of zero differences
    gives s_d = (q / 2) / z((1 + p0) / 2), z the normal quantile. Otherwise a scan whose
    background is clipped flat: the nonzero differences alone give the noise, if they are
    at least a tenth of all (fewer are the edges of a noiseless image: its noise is 0)."""
    d = np.concatenate([np.diff(img, axis=0).ravel(), np.diff(img, axis=1).ravel()])
    nonzero = np.abs(d[d != 0])
    if len(nonzero) < 0.5 * len(d):
        if len(nonzero) < 0.1 * len(d):
            return 0.0
        step = nonzero.min()
        if np.mean(nonzero <= 1.5 * step) >= 0.5:
            p0 = 1.0 - len(nonzero) / len(d)
            return float(0.5 * step / ndtri(0.5 * (1.0 + p0)) / np.sqrt(2.0))
        d = d[d != 0]
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0))


def _gradient_noise_gain(sigma):
    """Standard deviation of one gradient component (Gaussian smoothing ``sigma``, then
    central differences) per unit of white pixel noise: the filter's L2 norm."""
    half = int(np.ceil(4 * max(sigma, 0.5))) + 2
    delta = np.zeros((2 * half + 1, 2 * half + 1))
    delta[half, half] = 1.0
    smooth = ndimage.gaussian_filter(delta, sigma, mode="constant") if sigma > 0 else delta
    gx = np.gradient(smooth, axis=1)
    return float(np.sqrt(np.sum(gx * gx)))


def boundary_length(image, density_sigma_px=DEFAULTS.density_sigma_px):
    """Length in pixels of the gray edges of a slice, from its gradient, and the edge map.

    The image is smoothed by a Gaussian of ``density_sigma_px`` (the density map's, so both
    see the same edges); a pixel is an edge pixel when its gradient magnitude is a local
    maximum across the edge (non-maximum suppression along the gradient direction,
    interpolated bilinearly one pixel either way) and exceeds both :data:`EDGE_NOISE_K` times the noise of one
    gradient component (pixel noise from the MAD of adjacent-pixel differences times the
    filter's gain) and :data:`EDGE_CONTRAST_FRACTION` of the image's 0.5-99.5 percentile
    span per pixel. The length is the edge-pixel count divided by
    :data:`MEAN_RIDGE_DENSITY` (thin edges are one pixel wide; a diagonal leaves fewer
    pixels than its length).

    Parameters
    ----------
    image : (rows, cols) array_like
        The gray slice, any units.
    density_sigma_px : float, optional
        Gaussian smoothing in pixels (0: none).

    Returns
    -------
    length_px : float
        Estimated boundary length in pixels (0 for a flat or pure-noise image).
    edges : (rows, cols) bool ndarray
        The edge pixels.

    Raises
    ------
    InputError
        The image is not a finite 2D numeric array of at least 2 x 2.

    Example
    -------
    >>> import numpy as np
    >>> yy, xx = np.mgrid[:100, :100]
    >>> disc = ((yy - 50) ** 2 + (xx - 50) ** 2 < 20 ** 2) * 100.0
    >>> length, edges = boundary_length(disc)
    >>> round(length / (2 * np.pi * 20), 2)  # a staircase disc: edge pixels off the ridge
    1.13
    """
    img = as_image(image).astype(np.float64)
    sigma = check("density_sigma_px", density_sigma_px)
    lo, hi = np.percentile(img, [0.5, 99.5])
    span = float(hi - lo)
    if span <= 0:
        return 0.0, np.zeros(img.shape, bool)
    img = (img - lo) / span
    smooth = ndimage.gaussian_filter(img, sigma, mode="nearest") if sigma > 0 else img
    gy, gx = np.gradient(smooth)
    mag = np.hypot(gx, gy)
    t = max(EDGE_NOISE_K * _noise_sigma(img) * _gradient_noise_gain(sigma), EDGE_CONTRAST_FRACTION)
    # non-maximum suppression at the pixels above the threshold: a local maximum of mag
    # along the gradient direction, the neighbours one pixel either way interpolated
    # bilinearly
    rr, cc = np.nonzero(mag > t)
    m = mag[rr, cc]
    uy, ux = gy[rr, cc] / m, gx[rr, cc] / m
    ahead = ndimage.map_coordinates(mag, [rr + uy, cc + ux], order=1, mode="nearest")
    behind = ndimage.map_coordinates(mag, [rr - uy, cc - ux], order=1, mode="nearest")
    keep = (m >= ahead) & (m > behind)
    edges = np.zeros(mag.shape, bool)
    edges[rr[keep], cc[keep]] = True
    return float(edges.sum() / MEAN_RIDGE_DENSITY), edges


def _at_most_one_per_element(n, n_elements, which, reason, report, element):
    """The last step of both budgets: at most one site per pixel (``element`` 'pixel') or
    voxel; the report completed with ``n_sites``, ``rule``, ``reason`` and
    ``pixels_per_site`` (or ``voxels_per_site``)."""
    if n > n_elements:
        n, which = n_elements, element + "s"
        reason += f"; at most one per {element} ({n_elements})"
    report.update(n_sites=int(n), rule=which, reason=reason,
                  **{f"{element}s_per_site": round(n_elements / n, 2)})
    return int(n), report


def site_budget(image, pixels_per_site=DEFAULTS.pixels_per_site,
                boundary_px_per_site=DEFAULTS.boundary_px_per_site,
                min_pixels_per_site=DEFAULTS.min_pixels_per_site,
                site_rule=DEFAULTS.site_rule, density_sigma_px=DEFAULTS.density_sigma_px):
    """Number of CVT sites for a 2D slice, from its size and its boundary length.

    The rule (``site_rule='boundary'``, the default)::

        n_area     = max(16, round(N / pixels_per_site))       N = rows * cols
        n_boundary = round(L / boundary_px_per_site)            L = boundary_length(image)
        n_dense    = round(N / (f * N / L) ** 2)                f = DENSE_SPACING_FRACTION
        n_cap      = max(n_area, round(N / min_pixels_per_site))
        n_sites    = min(N, max(n_area, min(max(n_boundary, n_dense), n_cap)))

    Every slice gets at least the old size rule (one site per ``pixels_per_site`` pixels,
    at least 16); a slice whose edges are long for its area gets one site per
    ``boundary_px_per_site`` pixels of edge, and a slice that is edges everywhere gets
    sites half the mean edge spacing ``N / L`` apart; all up to one per
    ``min_pixels_per_site`` pixels. Why: the mesh can follow a boundary only with
    triangle edges shorter than the boundary's features, so a boundary of length L needs
    sites in proportion to L whatever the image size (n_boundary; the density map puts
    them on the edges). Where edges are everywhere, the density map is flat (its noise
    subtraction takes them for noise) and the sites spread evenly; then they must be
    closer than the edges are to each other: parallel edges ``N / L`` apart need sites
    about half that apart (n_dense, which grows as L squared). A machined part of
    512 x 512 has L of about 4000-5500 px, so n_boundary (about 1500-1800) and n_dense
    (about 300) stay under n_area (2048) and its mesh is what the size rule gave; sand
    grains 13 px across on the same image have L of about 50000 px and get the cap,
    32768 sites; a flat slice gets n_area, the minimum (its edges are short). A 94 x 103
    slice with a 15 px cavity gets one site per ``boundary_px_per_site`` px of its edges,
    the cavity's 47 px outline among them. ``site_rule='area'`` is the old rule, n_area
    alone.

    The boundary is measured on the image, not on the density map's mass: the map's
    automatic saturation subtracts twice the median gradient as noise, so on a slice that
    is all grain boundaries it puts almost every pixel at the floor (sum(rho - floor) of a
    sand slice is a tenth of a machined part's) and its mass says nothing of the edges.

    Parameters
    ----------
    image : (rows, cols) array_like
        The gray slice (any units), as the density map sees it.
    pixels_per_site : float, optional
        Pixels per site of the size rule (the least a slice gets).
    boundary_px_per_site : float, optional
        Pixels of boundary length per site.
    min_pixels_per_site : float, optional
        The boundary rule gives at most one site per this many pixels.
    site_rule : {'boundary', 'area'}, optional
        'boundary': the rule above; 'area': ``n_area`` only.
    density_sigma_px : float, optional
        Gaussian smoothing before the gradient (:func:`boundary_length`).

    Returns
    -------
    n_sites : int
    report : dict
        ``n_sites``, ``rule`` (which term decided: 'area', 'boundary', 'dense',
        'boundary_cap', 'pixels' when the image has fewer pixels than that), ``reason``
        (a sentence), ``boundary_px`` (L; None with the area rule), ``area_sites``,
        ``boundary_sites``, ``dense_sites``, ``cap_sites``, ``pixels_per_site``
        (N / n_sites).

    Raises
    ------
    InputError
        The image is not a finite 2D numeric array of at least 2 x 2.
    ParameterError
        A parameter outside its range in :mod:`ctseg.params`.

    Example
    -------
    >>> import numpy as np
    >>> flat = np.zeros((128, 128))
    >>> site_budget(flat)[0]
    128
    >>> rng = np.random.default_rng(1)
    >>> yy, xx = np.mgrid[:128, :128]
    >>> grains = (np.sin(xx / 2.0) * np.sin(yy / 2.0) > 0) * 100.0 + rng.normal(0, 3, (128, 128))
    >>> n, report = site_budget(grains)  # edges 6 px apart: the cap, one site per 8 px
    >>> n, report["rule"]
    (2048, 'boundary_cap')
    """
    img = as_image(image)
    pps = check("pixels_per_site", pixels_per_site)
    bpps = check("boundary_px_per_site", boundary_px_per_site)
    mpps = check("min_pixels_per_site", min_pixels_per_site)
    rule = check("site_rule", site_rule)
    n_pix = int(img.shape[0]) * int(img.shape[1])
    n_area = max(16, int(round(n_pix / pps)))
    report = {"area_sites": n_area, "boundary_px": None, "boundary_sites": None,
              "dense_sites": None, "cap_sites": None}
    if rule == "area":
        n, which = n_area, "area"
        reason = f"one site per {pps:g} pixels (site_rule='area')"
    else:
        length, _ = boundary_length(img, density_sigma_px)
        n_bound = int(round(length / bpps))
        spacing = n_pix / max(length, 1e-9)  # mean edge spacing, px
        n_dense = int(round(n_pix / (DENSE_SPACING_FRACTION * spacing) ** 2))
        n_cap = max(n_area, int(round(n_pix / mpps)))
        report.update(boundary_px=round(length, 1), boundary_sites=n_bound,
                      dense_sites=n_dense, cap_sites=n_cap)
        n_want, which = (n_bound, "boundary") if n_bound >= n_dense else (n_dense, "dense")
        if n_want <= n_area:
            n, which = n_area, "area"
            reason = (f"{length:.0f} px of boundary need {n_want} sites, fewer than the "
                      f"{n_area} of one per {pps:g} pixels")
        elif n_want <= n_cap:
            n = n_want
            reason = (f"{length:.0f} px of boundary at one site per {bpps:g} px"
                      if which == "boundary" else
                      f"edges {spacing:.1f} px apart on average: sites "
                      f"{DENSE_SPACING_FRACTION * spacing:.1f} px apart")
        else:
            n, which = n_cap, "boundary_cap"
            reason = (f"{length:.0f} px of boundary would take {n_want} sites; capped at one "
                      f"per {mpps:g} pixels")
    return _at_most_one_per_element(n, n_pix, which, reason, report, "pixel")


AREA_SAMPLE_SLICES = 24
""":func:`boundary_area` measures at most this many evenly spaced slices per axis."""


def boundary_area(volume, density_sigma_px=DEFAULTS.density_sigma_px,
                  max_slices=AREA_SAMPLE_SLICES):
    """Area of the gray interfaces of a volume, in voxel faces, by stereology.

    A surface of area S in a volume V cuts planes into boundary lines of L_A = (pi / 4) S / V
    per unit area, averaged over the planes' orientations (S_V = 4 L_A / pi, Saltykov). L_A is
    :func:`boundary_length` of evenly spaced slices (at most ``max_slices``) perpendicular
    to each axis over their area, averaged over the three axes (a surface parallel to one
    set of slices is seen by the other two).

    Parameters
    ----------
    volume : (nz, ny, nx) array_like
        The gray volume (any units), at least 2 voxels along every axis.
    density_sigma_px : float, optional
        Smoothing of each slice before its gradient (:func:`boundary_length`).
    max_slices : int, optional

    Returns
    -------
    area : float
        Voxel-face units (index space; the spacing is not applied).

    Example
    -------
    >>> zz, yy, xx = np.mgrid[:40, :40, :40]
    >>> ball = ((zz - 20) ** 2 + (yy - 20) ** 2 + (xx - 20) ** 2 < 12 ** 2) * 100.0
    >>> round(boundary_area(ball) / (4 * np.pi * 12 ** 2), 1)
    1.1
    """
    vol = np.asarray(volume, np.float64)
    n_vox = vol.size
    s_v = []
    for axis in range(3):
        n = vol.shape[axis]
        idx = np.unique(np.linspace(0, n - 1, min(n, max_slices)).round().astype(int))
        lengths = [boundary_length(np.take(vol, k, axis=axis), density_sigma_px)[0] for k in idx]
        s_v.append(4.0 / np.pi * float(np.mean(lengths)) / (n_vox / n))
    return float(np.mean(s_v)) * n_vox


def site_budget_3d(volume, voxels_per_site=DEFAULTS.voxels_per_site,
                   min_pixels_per_site=DEFAULTS.min_pixels_per_site,
                   site_rule=DEFAULTS.site_rule, density_sigma_px=DEFAULTS.density_sigma_px):
    """Number of CVT sites for a volume in 3D mode: the size rule, or closer sites where
    the surfaces are closer than its sites.

    With V voxels, A = :func:`boundary_area` and s = V / A, the mean distance between
    surfaces::

        n_area  = max(64, round(V / voxels_per_site))      sites about s_a = (V / n_area) ** (1/3) apart
        n_dense = round(V / s ** 3)                       sites s apart, where s < s_a
        n_cap   = max(n_area, round(V / min_pixels_per_site ** 1.5))
        n_sites = min(V, n_area if s >= s_a else min(n_dense, n_cap))

    The sites are as far apart as the size rule puts them or as the surfaces are, whichever
    is closer (continuous: n_dense = n_area at s = s_a), down to the closest spacing the 2D
    rule allows, sqrt(min_pixels_per_site). Unlike 2D, a long boundary alone does not add
    sites: smaller tetrahedra have noisier grays, which costs a low-contrast material more
    than the finer boundary gains (README, Method); only surfaces closer than the sites
    do. A machined part keeps n_area; a granular or porous volume gets its sites a surface
    spacing apart. ``site_rule='area'``: n_area alone.

    Parameters
    ----------
    volume : (nz, ny, nx) array_like
    voxels_per_site, min_pixels_per_site, site_rule, density_sigma_px
        As in :mod:`ctseg.params`.

    Returns
    -------
    n_sites : int
    report : dict
        ``n_sites``, ``rule`` ('area', 'dense', 'boundary_cap', 'voxels'), ``reason``,
        ``boundary_area_vox2`` (A; None with the area rule), ``surface_spacing_vox`` (s),
        ``area_sites``, ``dense_sites``, ``cap_sites``, ``voxels_per_site`` (V / n_sites).

    Example
    -------
    >>> site_budget_3d(np.zeros((20, 20, 20)))[0]
    64
    """
    vol = np.asarray(volume)
    vps = check("voxels_per_site", voxels_per_site)
    mpps = check("min_pixels_per_site", min_pixels_per_site)
    rule = check("site_rule", site_rule)
    n_vox = int(vol.size)
    n_area = max(64, int(round(n_vox / vps)))
    report = {"area_sites": n_area, "boundary_area_vox2": None, "surface_spacing_vox": None,
              "dense_sites": None, "cap_sites": None}
    n, which, reason = n_area, "area", f"one site per {vps:g} voxels (site_rule='area')"
    if rule != "area":
        area = boundary_area(vol, density_sigma_px)
        spacing = n_vox / max(area, 1e-9)
        s_area = (n_vox / n_area) ** (1.0 / 3.0)
        n_dense = int(round(min(n_vox / spacing ** 3, 1e15)))
        n_cap = max(n_area, int(round(n_vox / mpps ** 1.5)))
        report.update(boundary_area_vox2=round(area, 1), surface_spacing_vox=round(spacing, 2),
                      dense_sites=n_dense, cap_sites=n_cap)
        if spacing >= s_area:
            reason = (f"surfaces {spacing:.1f} voxels apart on average, farther than the "
                      f"{s_area:.1f} of one site per {vps:g} voxels")
        elif n_dense <= n_cap:
            n, which = n_dense, "dense"
            reason = f"surfaces {spacing:.1f} voxels apart on average: sites that far apart"
        else:
            n, which = n_cap, "boundary_cap"
            reason = (f"surfaces {spacing:.1f} voxels apart would take {n_dense} sites; "
                      f"capped at one per {mpps ** 1.5:.1f} voxels")
    return _at_most_one_per_element(n, n_vox, which, reason, report, "voxel")
