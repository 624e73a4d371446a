"""The whole 2D method in one call: image -> segmented triangle mesh (paper sections 5-6)."""
import time
from contextlib import nullcontext
from dataclasses import dataclass, field

import numpy as np

from ._allocation import release_free_heap
from ._validate import as_image, check_value_range
from .beam_hardening import correct_streaks
from .boundary import chain_polylines, material_boundary
from .cvt import lloyd_cvt
from .density import density_map
from .errors import ParameterError
from .intensity import estimate_noise, rescale_gray
from .labelling import label_mesh
from .levels_given import check_gray_levels
from .params import AUTO, DEFAULTS, resolve
from .resources import PeakRss, check_memory, slice_bytes
from .site_budget import site_budget
from .subpixel import subpixel_mesh

from .sites import initial_sites
from .triangle_gray import triangle_gray
from .triangulation import delaunay_mesh

DENSITY_KEYS = ("density_sigma_px", "density_floor", "density_saturation", "density_ridge")
"""The parameters of the 2D and 3D density maps (2D adds ``density_small_boost``)."""


def stage_runner(report, times, peaks_mib=None):
    """A function ``timed(name, fraction, fn, *args, **kwargs)`` that reports the stage
    starting (``report(fraction, name)``), runs ``fn`` and records its wall time in
    ``times[name]``, and, given ``peaks_mib``, the process's peak resident memory during
    the stage (MiB, :class:`ctseg.resources.PeakRss`) in ``peaks_mib[name]``. The memory
    is sampled, not traced: tracing every allocation would slow every stage."""
    def timed(name, frac, fn, *a, **k):
        report(frac, name)  # the stage that starts now, and the share of the work done
        release_free_heap()
        probe = PeakRss() if peaks_mib is not None else nullcontext()
        t0 = time.perf_counter()
        try:
            with probe:
                return fn(*a, **k)
        finally:
            times[name] = time.perf_counter() - t0
            if peaks_mib is not None:
                peaks_mib[name] = probe.peak_mib
    return timed


def monotone_progress(progress):
    """``progress(fraction, stage)`` (or nothing) wrapped so that the share reported never
    goes down: a stage that starts inside a range already reported by a nested loop (the
    voxel Lloyd after the coarse one) keeps the share reached."""
    if progress is None:
        return lambda frac, stage: None
    reached = 0.0

    def report(frac, stage):
        nonlocal reached
        reached = max(reached, float(frac))
        progress(reached, stage)
    return report


def default_n_sites(shape, pixels_per_site=DEFAULTS.pixels_per_site):
    """The size rule of the number of CVT sites: one per ``pixels_per_site`` pixels, at
    least 16 and at most one per pixel (``site_rule='area'``; the least that
    :func:`ctseg.site_budget.site_budget`, the default rule, gives a slice).

    Example
    -------
    >>> default_n_sites((512, 512))
    2048
    """
    n_pix = int(shape[0]) * int(shape[1])
    return int(min(n_pix, max(16, round(n_pix / pixels_per_site))))


@dataclass
class SegmentedMesh:
    """A segmented triangle mesh of one 2D image, in pixel-index coordinates (x=col, y=row).

    Attributes
    ----------
    points : (n, 2) float64 ndarray
    triangles : (m, 3) int64 ndarray, counter-clockwise
    material : (m,) int64 ndarray, 0..K-1 by ascending mean gray
    gray : (m,) float64 ndarray, triangle mean gray in the input's units
    boundary_edges : (b, 2) int64 ndarray, vertex pairs between different materials
    boundary_sides : (b, 2) int64 ndarray, the materials each side (smaller first)
    material_gray : (K,) float64 ndarray, mean gray of each material in the input's units
    adjacency : (k, 2) int64 ndarray, adjacent triangle pairs
    diagnostics : dict
        ``times_s`` (per-stage wall time), ``cvt_energy`` (history), ``lloyd_iterations``,
        ``graphcut_calls``, the parameters used, ``sites``: how many sites and why
        (:func:`ctseg.site_budget.site_budget`'s report: ``n_sites``, ``rule``, ``reason``,
        ``boundary_px``; ``rule`` 'given' when ``n_sites`` was), and ``levels``: how the
        material levels were found, with the evidence (:func:`ctseg.levels.material_levels`'s report:
        ``method``, ``reason``, ``k_candidates``, ``criterion``, ``clipped`` and the
        clipped fraction; ``{'method': 'given'}`` with ``levels_255``).
    density, cvt_labels : ndarray
        The density map and the final Voronoi regions (for figures).
    corrected_image : ndarray or None
        The streak-corrected image the mesh was made on (for figures); None when the
        correction was off or changed nothing.
    """

    points: np.ndarray
    triangles: np.ndarray
    material: np.ndarray
    gray: np.ndarray
    boundary_edges: np.ndarray
    boundary_sides: np.ndarray
    material_gray: np.ndarray
    adjacency: np.ndarray
    shape: tuple
    diagnostics: dict = field(default_factory=dict)
    density: np.ndarray = None
    cvt_labels: np.ndarray = None
    corrected_image: np.ndarray = None

    @property
    def n_materials(self):
        return len(self.material_gray)

    def boundary_polylines(self):
        """Boundary as chained polylines: (list of vertex-index arrays, (L, 2) side pairs)."""
        return chain_polylines(self.boundary_edges, self.boundary_sides)


def segment_image(image, params=None, *, progress=None, gray_scale=None, levels_255=None,
                  **overrides):
    """Segment a 2D gray image into a triangle mesh with one material per triangle.

    [metal streak correction (not in the paper)] -> density map (SPEC 1) -> initial sites
    (SPEC 2) -> Lloyd CVT (SPEC 3) -> Delaunay mesh (SPEC 4) -> triangle gray (SPEC 5) ->
    recursive graph cut (SPEC 6-7) [-> blur correction of the grays and the graph cut
    again (not in the paper)].

    Parameters
    ----------
    image : (rows, cols) array_like
        The CT slice, any numeric dtype and units.
    params : ctseg.params.SegmentParams or dict, optional
        All parameters (default :data:`ctseg.params.DEFAULTS`); ``ctseg params`` lists
        them with their ranges, units and meaning.
    progress : callable, optional
        Called as ``progress(fraction_done, stage_name)`` when each stage starts, after
        every Lloyd iteration, and with ``(1.0, "done")`` at the end.
    gray_scale : (offset, factor), optional
        Map of gray values onto 0-255 found elsewhere (a whole volume's,
        :func:`ctseg.intensity.gray_scale`); default: this image's percentiles.
    levels_255 : (K,) array_like, optional
        Material gray levels found elsewhere (:func:`ctseg.levels.material_levels` of a
        whole volume). Then material k is level k, whether or not this slice holds it, so
        numbers agree across slices, and ``material_gray`` holds the levels in the
        input's units.
    **overrides
        Single parameters by name (``n_sites=3000``, ``lam=50``, ``streak_correction=False``),
        applied over ``params``; an unknown name is a ParameterError naming the closest
        valid one.

    Notes
    -----
    The metal streak correction (``streak_correction``,
    :func:`ctseg.beam_hardening.correct_streaks`) runs first; every later stage, and the
    reported ``gray``, use the corrected image, and its fitted weight is in
    ``diagnostics["streak_correction"]``. The blur correction (``blur_correction``) is part
    of the labelling (:func:`ctseg.labelling.label_mesh`); the reported ``gray`` is the
    measured one and the fitted blur ``diagnostics["blur_px"]``. Neither is in the paper.

    Returns
    -------
    SegmentedMesh

    Raises
    ------
    InputError
        The image is not a finite 2D numeric array of at least 2 x 2.
    ParameterError
        A parameter is out of range (e.g. more sites than pixels).

    References
    ----------
    Yang et al. 2014, sections 5 and 6.

    Example
    -------
    >>> import numpy as np
    >>> img = np.zeros((40, 40)); img[10:30, 10:30] = 100.0
    >>> seg = segment_image(img, n_sites=60)
    >>> seg.n_materials, bool(seg.material.max() == 1)
    (2, True)
    """
    p = resolve(params, **overrides)
    img = as_image(image)
    if levels_255 is None:  # a volume's slice: checked against the whole volume
        check_value_range(img, "image")
        check_gray_levels(p.gray_levels, img)
    n_sites = p.n_sites
    if n_sites == AUTO:  # the size rule's count; the boundary rule may raise it below
        n_sites = default_n_sites(img.shape, p.pixels_per_site)
    if n_sites > img.size:
        raise ParameterError(
            f"n_sites: {n_sites} sites for an image of {img.shape[0]} x {img.shape[1]} = "
            f"{img.size} pixels; use at most {img.size}")
    check_memory(slice_bytes(*img.shape), f"segmenting a {img.shape[0]} x {img.shape[1]} slice",
                 "crop or downsample it")
    times = {}
    report = monotone_progress(progress)
    timed = stage_runner(report, times)

    streaks = None
    if p.streak_correction:
        streaks = timed("streak_correction", 0.0, correct_streaks, img, p,
                        gray_scale=gray_scale, levels_255=levels_255)
        img = streaks.image
    g255, scale = timed("rescale", 0.01, rescale_gray, img, p.rescale_low_pct,
                        p.rescale_high_pct, scale=gray_scale)
    noise = estimate_noise(g255)
    if p.n_sites == AUTO:
        n_sites, site_report = timed("site_budget", 0.01, site_budget, img, p.pixels_per_site,
                                     p.boundary_px_per_site, p.min_pixels_per_site,
                                     p.site_rule, p.density_sigma_px)
    else:
        site_report = {"n_sites": int(n_sites), "rule": "given", "reason": "n_sites given",
                       "boundary_px": None}
    rho = timed("density", 0.01, density_map, img, density_small_boost=p.density_small_boost,
                **{k: getattr(p, k) for k in DENSITY_KEYS})
    sites0 = timed("initial_sites", 0.03, initial_sites, rho, n_sites, init=p.init,
                   seed=p.seed, ward_block_px=p.ward_block_px)
    cvt = timed("cvt", 0.2, lloyd_cvt, rho, sites0, tol_px=p.tol_px, max_iter=p.max_iter,
                progress=lambda it, n: report(0.2 + 0.5 * it / max(n, 1), "cvt"))
    mesh = timed("triangulation", 0.7, delaunay_mesh, cvt.sites)
    gray = timed("triangle_gray", 0.71, triangle_gray, img, mesh.points, mesh.triangles)
    report(0.9, "graphcut")
    t0 = time.perf_counter()
    labels = label_mesh(img, mesh, gray, p, scale=scale, levels_255=levels_255)
    blur_s = labels.times_s.get("blur_correction", 0.0)
    times["graphcut"] = time.perf_counter() - t0 - blur_s  # both cuts and the levels
    if labels.blur_px is not None:
        times["blur_correction"] = blur_s
    material, mat_gray = labels.material, labels.material_gray
    points, n_moved = mesh.points, 0
    if p.subpixel_boundary:  # the labels stay; the mesh's vertices move
        fixed = levels_255 is not None or p.gray_levels != AUTO  # numbered by the levels
        moved = timed("subpixel_boundary", 0.98, subpixel_mesh, img, mesh.points,
                      mesh.triangles, gray, material, p.subpixel_max_shift, renumber=not fixed)
        points, gray, material, n_moved = moved.points, moved.gray, moved.material, moved.n_moved
        mat_gray = mat_gray if fixed else moved.material_gray
    bedges, bsides = timed("boundary", 0.99, material_boundary, mesh.shared_edges,
                           mesh.adjacency, material)
    report(1.0, "done")
    seg = labels.segmentation
    if levels_255 is None:  # how label_mesh found the levels
        level_report = labels.levels_report
    else:
        level_report = {"method": "given", "levels_255": [float(v) for v in levels_255]}
    diagnostics = {
        "image_shape": list(img.shape),
        "n_sites": int(n_sites),
        "sites": site_report,
        "n_triangles": int(len(mesh.triangles)),
        "n_materials": int(len(mat_gray)),
        "init": p.init,
        "seed": int(p.seed),
        "parameters": p.to_dict(),
        "pixel_noise_255": noise,
        "step_noise_255": seg.step_noise,
        "step_threshold_255": seg.step_threshold,
        "material_noise_255": labels.pixel_sigma,
        "material_levels_255": [float(v) for v in labels.levels_255],
        "levels": level_report,
        "gray_rescale": {"offset": scale[0], "factor": scale[1]},
        "times_s": times,
        "total_time_s": float(sum(times.values())),
        "cvt_energy": [float(e) for e in cvt.energy],
        "lloyd_iterations": int(cvt.n_iter),
        "lloyd_converged": bool(cvt.converged),
        "empty_regions": int(cvt.empty_regions),
        "graphcut_calls": int(seg.graphcut_calls),
        "recursion_depth": int(seg.max_depth_reached),
        "material_gray": [float(v) for v in mat_gray],
        "streak_correction": streaks.summary() if streaks else None,
        "blur_px": labels.blur_px,
        "subpixel_moved": int(n_moved),
    }
    return SegmentedMesh(points=points, triangles=mesh.triangles, material=material,
                         gray=gray, boundary_edges=bedges, boundary_sides=bsides,
                         material_gray=mat_gray, adjacency=mesh.adjacency, shape=img.shape,
                         diagnostics=diagnostics, density=rho, cvt_labels=cvt.labels,
                         corrected_image=img if streaks is not None and streaks.weight > 0 else None)
