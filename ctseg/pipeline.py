"""The whole 2D method in one call: image -> segmented triangle mesh (paper sections 5-6)."""
import inspect
import time
from dataclasses import dataclass, field

import numpy as np

from ._validate import as_image, check_number
from .beam_hardening import correct_metal_streaks
from .blur import blur_corrected_gray, region_levels
from .boundary import chain_polylines, material_boundary
from .cvt import lloyd_cvt
from .density import density_map
from .errors import ParameterError
from .intensity import estimate_noise, rescale_gray
from .materials import order_by_gray, pixel_material_levels, segment_triangles
from .resources import check_memory, slice_bytes
from .sites import initial_sites
from .triangle_gray import triangle_gray
from .triangulation import delaunay_mesh, triangle_areas

PIXELS_PER_SITE = 128


def default_n_sites(shape):
    """Default number of CVT sites: one per 128 pixels, at least 16 and at most one per pixel.

    512 x 512 gives 2048 sites. The paper used 1000 sites on 512 x 512; twice that keeps the
    mean boundary error under one pixel on parts with long boundaries and thin walls
    (see the README's accuracy table).
    """
    n_pix = int(shape[0]) * int(shape[1])
    return int(min(n_pix, max(16, round(n_pix / PIXELS_PER_SITE))))


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
        ``graphcut_calls`` and the parameters used.
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


def flat_pixels(image, sigma=1.0, density_floor=0.02, density_saturation="auto"):
    """Pixels away from material edges: the un-sharpened density below half its range.

    These pixels measure the material gray levels (:func:`material_levels`); the ridge
    sharpening of the density is left out because it thins the edge bands.

    Parameters
    ----------
    image : (rows, cols) array_like
    sigma, density_floor, density_saturation
        As in :func:`ctseg.density_map`.

    Returns
    -------
    flat : (rows, cols) bool ndarray
    """
    strength = density_map(image, sigma=sigma, floor=density_floor,
                           saturation=density_saturation)
    return (strength - density_floor) < 0.5


def material_levels(images, scale, *, sigma=1.0, density_floor=0.02,
                    density_saturation="auto", merge_k=5.0, merge_rel=0.2, merge_floor=2.0,
                    n_materials=None):
    """Material gray levels (0-255 scale) seen in one slice or in a stack of slices.

    The modes of the histogram of the pixels away from edges
    (:func:`ctseg.materials.pixel_material_levels`). Given a stack, the pixels of all its
    slices count together, so every slice of a volume is labelled against the same levels
    and material numbers agree across slices.

    Parameters
    ----------
    images : (rows, cols) or (n, rows, cols) array_like
    scale : (offset, factor)
        The map onto 0-255 (:func:`ctseg.intensity.gray_scale`).
    sigma, density_floor, density_saturation
        Define the flat pixels (:func:`flat_pixels`).
    merge_k, merge_rel, merge_floor, n_materials
        Mode separation rule and exact count (:func:`ctseg.materials.material_modes`).

    Returns
    -------
    levels : (K,) ndarray, ascending
    sigma_255 : float
        Noise of the dominant material's flat pixels (0-255 scale).
    """
    stack = np.asarray(images)
    stack = stack[None] if stack.ndim == 2 else stack
    g255 = np.stack([rescale_gray(sl, scale=scale)[0] for sl in stack])
    flat = np.stack([flat_pixels(sl, sigma, density_floor, density_saturation) for sl in stack])
    return pixel_material_levels(g255, flat, merge_k=merge_k, merge_rel=merge_rel,
                                 merge_floor=merge_floor, n_materials=n_materials)


def segment_image(image, n_sites=None, seed=0, *, init="ward", sigma=1.0, density_floor=0.02,
                  density_saturation="auto", density_ridge=2.0,
                  ward_block_px=None, tol_px=0.01, max_iter=200, step_threshold=None,
                  merge_k=5.0, merge_rel=0.2, merge_floor=2.0, merge_threshold=None,
                  n_materials=None, theta=None, lam=70.0, beta=0.286, min_triangles=2,
                  max_depth=32, min_material_area=None, min_pocket_area=4.0,
                  weight_by_edge_length=False, streak_correction=True, blur_correction=True,
                  gray_scale=None, levels_255=None, progress=None):
    """Segment a 2D gray image into a triangle mesh with one material per triangle.

    [metal streak correction (not in the paper)] -> density map (SPEC 1) -> initial sites
    (SPEC 2) -> Lloyd CVT (SPEC 3) -> Delaunay mesh (SPEC 4) -> triangle gray (SPEC 5) ->
    recursive graph cut (SPEC 6-7) [-> blur correction of the grays and the graph cut
    again (not in the paper)].

    Parameters
    ----------
    image : (rows, cols) array_like
        The CT slice, any numeric dtype and units.
    n_sites : int, optional
        Number of CVT sites (mesh vertices). Default :func:`default_n_sites`.
    seed : int
        Seed for the random initialisations (Ward's is deterministic anyway).
    init : {'ward', 'random', 'density_random'}
    sigma, density_floor, density_saturation, density_ridge
        Density map smoothing (px), floor, gradient normalisation and ridge sharpening
        (SPEC 1; see :func:`ctseg.density_map`).
    ward_block_px : int, optional
        Ward pre-merge block size (1 = exact Ward).
    tol_px, max_iter
        Lloyd stopping rule.
    step_threshold, merge_k, merge_rel, merge_floor, merge_threshold, n_materials, theta,
    lam, beta, min_triangles, max_depth, min_material_area, min_pocket_area
        Segmentation parameters on the 0-255 gray scale, see
        :func:`ctseg.materials.segment_triangles`.
    weight_by_edge_length : bool
        Multiply n-links by the shared edge length (an option, not the paper's).
    streak_correction : bool
        First remove the beam-hardening streaks of the densest material
        (:func:`ctseg.beam_hardening.correct_metal_streaks`; not in the paper). Every later
        stage, and the reported ``gray``, then use the corrected image; the fitted weight
        is in ``diagnostics["streak_correction"]``.
    blur_correction : bool
        After the first labelling, correct the triangle grays for the smear of the
        scanner's point-spread function that this labelling predicts, and label again
        (:func:`ctseg.blur.blur_corrected_gray`; not in the paper). The reported ``gray``
        is the measured one; the fitted blur is ``diagnostics["blur_px"]``.
    gray_scale : (offset, factor), optional
        Map of gray values onto 0-255 found elsewhere (a whole volume's,
        :func:`ctseg.intensity.gray_scale`); default: this image's percentiles.
    levels_255 : (K,) array_like, optional
        Material gray levels found elsewhere (:func:`material_levels` of a whole volume).
        Then material k is level k, whether or not this slice holds it, so numbers agree
        across slices, and ``material_gray`` holds the levels in the input's units.
    progress : callable, optional
        Called as ``progress(fraction_done, stage_name)`` when each stage starts, after
        every Lloyd iteration, and with ``(1.0, "done")`` at the end.

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
    """
    img = as_image(image)
    if n_sites is None:
        n_sites = default_n_sites(img.shape)
    n_sites = check_number(n_sites, "n_sites", low=1, integer=True)
    if n_sites < 4:
        raise ParameterError(f"n_sites: need at least 4 sites (the four image corners), got {n_sites}")
    if n_sites > img.size:
        raise ParameterError(
            f"n_sites: {n_sites} sites for an image of {img.shape[0]} x {img.shape[1]} = "
            f"{img.size} pixels; use at most {img.size}")
    seed = check_number(seed, "seed", low=0, integer=True)
    check_memory(slice_bytes(*img.shape), f"segmenting a {img.shape[0]} x {img.shape[1]} slice",
                 "crop or downsample it")
    if n_materials is not None:  # checked again where used; here to fail before the CVT
        check_number(n_materials, "n_materials", low=1, integer=True)
    times = {}
    report = progress or (lambda frac, stage: None)

    def timed(name, frac, fn, *a, **k):
        report(frac, name)  # the stage that starts now, and the share of the work done
        t0 = time.perf_counter()
        out = fn(*a, **k)
        times[name] = time.perf_counter() - t0
        return out

    streaks = None
    if streak_correction:
        streaks = timed("streak_correction", 0.0, correct_streaks, img, gray_scale, levels_255,
                        sigma=sigma, density_floor=density_floor,
                        density_saturation=density_saturation, merge_k=merge_k,
                        merge_rel=merge_rel, merge_floor=merge_floor, n_materials=n_materials)
        img = streaks.image
    g255, scale = timed("rescale", 0.01, rescale_gray, img, scale=gray_scale)
    noise = estimate_noise(g255)
    rho = timed("density", 0.01, density_map, img, sigma=sigma, floor=density_floor,
                saturation=density_saturation, ridge=density_ridge)
    sites0 = timed("initial_sites", 0.03, initial_sites, rho, n_sites, method=init, seed=seed,
                   block_px=ward_block_px)
    cvt = timed("cvt", 0.2, lloyd_cvt, rho, sites0, tol=tol_px, max_iter=max_iter,
                progress=lambda it, n: report(0.2 + 0.5 * it / max(n, 1), "cvt"))
    mesh = timed("triangulation", 0.7, delaunay_mesh, cvt.sites)
    gray = timed("triangle_gray", 0.71, triangle_gray, img, mesh.points, mesh.triangles)
    report(0.9, "graphcut")
    t0 = time.perf_counter()
    labels = label_mesh(img, mesh, gray, scale=scale, levels_255=levels_255, sigma=sigma,
                        density_floor=density_floor, density_saturation=density_saturation,
                        step_threshold=step_threshold, merge_k=merge_k, merge_rel=merge_rel,
                        merge_floor=merge_floor, merge_threshold=merge_threshold,
                        n_materials=n_materials, theta=theta, lam=lam, beta=beta,
                        min_triangles=min_triangles, max_depth=max_depth,
                        min_material_area=min_material_area, min_pocket_area=min_pocket_area,
                        weight_by_edge_length=weight_by_edge_length,
                        blur_correction=blur_correction)
    blur_s = labels.times_s.get("blur_correction", 0.0)
    times["graphcut"] = time.perf_counter() - t0 - blur_s  # both cuts and the levels
    if labels.blur_px is not None:
        times["blur_correction"] = blur_s
    material, mat_gray = labels.material, labels.material_gray
    bedges, bsides = timed("boundary", 0.99, material_boundary, mesh.shared_edges,
                           mesh.adjacency, material)
    report(1.0, "done")
    seg = labels.segmentation
    diagnostics = {
        "image_shape": list(img.shape),
        "n_sites": int(n_sites),
        "n_triangles": int(len(mesh.triangles)),
        "n_materials": int(len(mat_gray)),
        "init": init,
        "seed": int(seed),
        "pixel_noise_255": noise,
        "step_noise_255": seg.step_noise,
        "step_threshold_255": seg.step_threshold,
        "material_noise_255": labels.pixel_sigma,
        "material_levels_255": [float(v) for v in labels.levels_255],
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
    }
    return SegmentedMesh(points=mesh.points, triangles=mesh.triangles, material=material,
                         gray=gray, boundary_edges=bedges, boundary_sides=bsides,
                         material_gray=mat_gray, adjacency=mesh.adjacency, shape=img.shape,
                         diagnostics=diagnostics, density=rho, cvt_labels=cvt.labels,
                         corrected_image=img if streaks is not None and streaks.weight > 0 else None)


def correct_streaks(image, gray_scale=None, levels_255=None, *, sigma=1.0, density_floor=0.02,
                    density_saturation="auto", merge_k=5.0, merge_rel=0.2, merge_floor=2.0,
                    n_materials=None):
    """The metal streak correction as :func:`segment_image` runs it.

    :func:`ctseg.beam_hardening.correct_metal_streaks` with the material levels of the
    image itself (:func:`material_levels`) or the given ones, and its flat pixels.

    Parameters
    ----------
    image : (rows, cols) array_like
    gray_scale, levels_255
        As in :func:`segment_image` (a volume's map onto 0-255 and its levels).
    other parameters
        As in :func:`segment_image`.

    Returns
    -------
    ctseg.beam_hardening.StreakCorrection
    """
    img = as_image(image)
    flat = flat_pixels(img, sigma, density_floor, density_saturation)
    if levels_255 is not None and gray_scale is not None:
        levels255, (offset, factor) = np.asarray(levels_255, float), gray_scale
    else:
        # material_levels' own way, with the flat pixels computed once for both uses
        g255, (offset, factor) = rescale_gray(img, scale=gray_scale)
        levels255 = pixel_material_levels(g255, flat, merge_k=merge_k, merge_rel=merge_rel,
                                          merge_floor=merge_floor, n_materials=n_materials)[0]
    levels = levels255 / factor + offset if factor else np.array([offset])
    return correct_metal_streaks(img, levels, flat=flat, sigma=sigma)


@dataclass
class MeshLabels:
    """Outcome of :func:`label_mesh`: ``material`` per triangle, ``material_gray`` (input
    units), the ``levels_255`` used, the pixel noise ``pixel_sigma`` (0-255 scale; 0 when
    the levels were given), the raw :class:`ctseg.materials.MaterialSegmentation`, the
    fitted blur ``blur_px`` (None without blur correction) and ``times_s``, the seconds
    spent in the blur correction ('blur_correction'; the graph cuts are the rest)."""

    material: np.ndarray
    material_gray: np.ndarray
    levels_255: np.ndarray
    pixel_sigma: float
    segmentation: object
    blur_px: object = None
    times_s: dict = field(default_factory=dict)


def label_mesh(image, mesh, gray, *, scale=None, levels_255=None, sigma=1.0,
               density_floor=0.02, density_saturation="auto", step_threshold=None,
               merge_k=5.0, merge_rel=0.2, merge_floor=2.0, merge_threshold=None,
               n_materials=None, theta=None, lam=70.0, beta=0.286, min_triangles=2,
               max_depth=32, min_material_area=None, min_pocket_area=4.0,
               weight_by_edge_length=False, blur_correction=True):
    """One material per triangle of a mesh over an image (SPEC 6-7): the last stage.

    Material levels come from the image's flat pixels (:func:`material_levels`) unless
    ``levels_255`` gives them; then the recursive graph cut
    (:func:`ctseg.materials.segment_triangles`) labels the triangles. With
    ``blur_correction``, the grays are then corrected for the blur this labelling predicts
    (:func:`ctseg.blur.blur_corrected_gray`) and the graph cut labels them again.

    Parameters
    ----------
    image : (rows, cols) array_like
        The image the mesh was made on.
    mesh : TriangleMesh
        From :func:`ctseg.delaunay_mesh` (its adjacency and shared edges are used).
    gray : (m,) array_like
        Triangle mean gray in the image's units (:func:`ctseg.triangle_gray`).
    scale : (offset, factor), optional
        Map onto 0-255; default the image's own (:func:`ctseg.intensity.rescale_gray`).
    levels_255 : (K,) array_like, optional
        Fixed material levels: material k is level k (numbers agree across slices).
    other parameters
        As in :func:`segment_image`.

    Returns
    -------
    MeshLabels
        Materials 0..K-1 by ascending mean gray of what they hold (or by level, given
        ``levels_255``).

    Raises
    ------
    ParameterError
        Out-of-range parameters, or ``gray`` not one value per triangle.
    """
    img = as_image(image)
    if n_materials is not None:
        n_materials = check_number(n_materials, "n_materials", low=1, integer=True)
    gray = np.asarray(gray, float)
    if gray.shape != (len(mesh.triangles),):
        raise ParameterError(f"gray: expected one value per triangle ({len(mesh.triangles)}), "
                             f"got shape {gray.shape}")
    if scale is None:
        scale = rescale_gray(img)[1]
    offset, factor = scale
    f255 = np.clip((gray - offset) * factor, 0.0, 255.0)
    area = triangle_areas(mesh.points, mesh.triangles)
    cent = mesh.points[mesh.triangles].mean(axis=1)
    edge_len = None
    if weight_by_edge_length:
        d = mesh.points[mesh.shared_edges[:, 0]] - mesh.points[mesh.shared_edges[:, 1]]
        edge_len = np.hypot(d[:, 0], d[:, 1])
    pixel_sigma = 0.0
    fixed = levels_255 is not None
    if fixed:
        levels = np.sort(np.asarray(levels_255, float).ravel())
        if len(levels) == 0 or not np.all(np.isfinite(levels)):
            raise ParameterError(f"levels_255: need finite gray levels, got {levels_255!r}")
        if n_materials is not None and len(levels) != n_materials:
            raise ParameterError(f"levels_255: {len(levels)} levels given for n_materials={n_materials}")
    else:
        levels, pixel_sigma = material_levels(
            img, scale, sigma=sigma, density_floor=density_floor,
            density_saturation=density_saturation, merge_k=merge_k, merge_rel=merge_rel,
            merge_floor=merge_floor, n_materials=n_materials)
    params = dict(step_threshold=step_threshold, merge_k=merge_k, merge_rel=merge_rel,
                  merge_floor=merge_floor, merge_threshold=merge_threshold,
                  min_triangles=min_triangles, max_depth=max_depth,
                  min_material_area=min_material_area, min_pocket_area=min_pocket_area,
                  theta=theta, lam=lam, beta=beta, edge_length=edge_len)
    seg = segment_triangles(f255, area, mesh.adjacency, cent, levels=levels, **params)
    times = {}
    blur_px = None
    if blur_correction and len(seg.mode_gray) > 1:
        t0 = time.perf_counter()
        # in 0-255 units like f255; the image unclipped (f255's clip only bounds outliers)
        level = region_levels(seg.material, f255, area, mesh.adjacency)
        f_sharp, blur_px = blur_corrected_gray(f255, mesh.points, mesh.triangles, level,
                                               (img - offset) * factor)
        times["blur_correction"] = time.perf_counter() - t0
        seg = segment_triangles(np.clip(f_sharp, 0.0, 255.0), area, mesh.adjacency, cent,
                                levels=levels, **params)
    if fixed:
        # one numbering for every slice: the index of the level the material was cut at
        material = np.searchsorted(levels, seg.mode_gray)[seg.material]
        mat_gray = levels / factor + offset if factor else np.full(len(levels), offset)
    else:
        # numbered by mean gray in the input's units (the 0-255 copy is clipped)
        material, mat_gray, _ = order_by_gray(seg.material, gray, area)
    return MeshLabels(material=material.astype(np.int64), material_gray=np.asarray(mat_gray, float),
                      levels_255=seg.mode_gray if not fixed else levels,
                      pixel_sigma=float(pixel_sigma), segmentation=seg, blur_px=blur_px,
                      times_s=times)


SEGMENT_DEFAULTS = {name: p.default for name, p in inspect.signature(segment_image).parameters.items()
                    if p.kind is p.KEYWORD_ONLY
                    and name not in ("gray_scale", "levels_255", "progress")}
"""Every tuning keyword of :func:`segment_image` with its default (the volume driver and the
filters take the same names)."""
