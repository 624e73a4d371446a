"""The labelling stage (SPEC 6-7): one material per triangle of a mesh over an image, from
the material levels, the recursive graph cut and the blur correction."""
import time
from dataclasses import dataclass, field

import numpy as np

from ._validate import as_image
from .blur import blur_corrected_gray, region_levels
from .errors import ParameterError
from .intensity import rescale_gray
from .levels import LEVEL_KEYS, material_levels
from .params import AUTO, resolve
from .partial_volume import claim_missing_levels
from .recursive_cut import order_by_gray, segment_triangles
from .triangulation import triangle_areas

CUT_KEYS = ("step_threshold_255", "merge_k", "merge_rel", "merge_floor_255",
            "merge_threshold_255", "min_triangles", "max_depth", "min_material_area",
            "min_pocket_area", "theta_255", "lam", "beta", "eps_255")
"""The parameters of :func:`ctseg.recursive_cut.segment_triangles` besides the levels."""


@dataclass
class MeshLabels:
    """Outcome of :func:`label_mesh`: ``material`` per triangle, ``material_gray`` (input
    units), the ``levels_255`` used, the pixel noise ``pixel_sigma`` (0-255 scale; 0 when
    the levels were given), the raw :class:`ctseg.recursive_cut.MaterialSegmentation`, the
    fitted blur ``blur_px`` (None without blur correction), ``times_s``, the seconds
    spent in the blur correction ('blur_correction'; the graph cuts are the rest), and
    ``levels_report``, :func:`ctseg.levels.material_levels`'s evidence for the levels it
    found (empty when ``levels_255`` was given)."""

    material: np.ndarray
    material_gray: np.ndarray
    levels_255: np.ndarray
    pixel_sigma: float
    segmentation: object
    blur_px: object = None
    times_s: dict = field(default_factory=dict)
    levels_report: dict = field(default_factory=dict)


def label_mesh(image, mesh, gray, params=None, *, scale=None, levels_255=None, **overrides):
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
    params : ctseg.params.SegmentParams or dict, optional
        The parameters (levels, graph cut, recursion, blur correction); ``overrides``
        change single ones by name.
    levels_255 : (K,) array_like, optional
        Fixed material levels: material k is level k (numbers agree across slices); so
        are the parameters' ``gray_levels`` when given.

    Returns
    -------
    MeshLabels
        Materials 0..K-1 by ascending mean gray of what they hold (or by level, given
        ``levels_255`` or ``gray_levels``).

    Raises
    ------
    ParameterError
        Out-of-range parameters, or ``gray`` not one value per triangle.

    Example
    -------
    >>> import numpy as np
    >>> from ctseg import delaunay_mesh, triangle_gray
    >>> img = np.zeros((24, 24)); img[:, 12:] = 100.0
    >>> ys, xs = np.mgrid[0:24:4, 0:24:4]
    >>> mesh = delaunay_mesh(np.column_stack([xs.ravel(), ys.ravel()]).astype(float))
    >>> labels = label_mesh(img, mesh, triangle_gray(img, mesh.points, mesh.triangles))
    >>> len(labels.material_gray)
    2
    """
    p = resolve(params, **overrides)
    img = as_image(image)
    n_materials = p.n_materials
    # the number of materials asked for this image (not a volume's, which a slice may not all
    # hold; not given levels, which this image may not all hold): each of them gets elements
    claim = levels_255 is None and n_materials != AUTO and p.gray_levels == AUTO
    gray = np.asarray(gray, float)
    if gray.shape != (len(mesh.triangles),):
        raise ParameterError(f"gray: expected one value per triangle ({len(mesh.triangles)}), "
                             f"got shape {gray.shape}")
    if scale is None:
        scale = rescale_gray(img, p.rescale_low_pct, p.rescale_high_pct)[1]
    offset, factor = scale
    f255 = np.clip((gray - offset) * factor, 0.0, 255.0)
    area = triangle_areas(mesh.points, mesh.triangles)
    cent = mesh.points[mesh.triangles].mean(axis=1)
    edge_len = None
    if p.weight_by_edge_length:
        d = mesh.points[mesh.shared_edges[:, 0]] - mesh.points[mesh.shared_edges[:, 1]]
        edge_len = np.hypot(d[:, 0], d[:, 1])
    pixel_sigma = 0.0
    levels_report = {}
    if levels_255 is None and p.gray_levels != AUTO:
        # the user's levels: numbered by level as well, so material k is the k-th level
        levels_255, pixel_sigma = material_levels(
            img, scale, report=levels_report, **{k: getattr(p, k) for k in LEVEL_KEYS})
    fixed = levels_255 is not None
    if fixed:
        levels = np.sort(np.asarray(levels_255, float).ravel())
        if len(levels) == 0 or not np.all(np.isfinite(levels)):
            raise ParameterError(f"levels_255: need finite gray levels, got {levels_255!r}")
        if n_materials != AUTO and len(levels) != n_materials:
            raise ParameterError(f"levels_255: {len(levels)} levels given for n_materials={n_materials}")
    else:
        levels, pixel_sigma = material_levels(
            img, scale, report=levels_report, **{k: getattr(p, k) for k in LEVEL_KEYS})
    cut = dict({k: getattr(p, k) for k in CUT_KEYS}, edge_length=edge_len)
    seg = segment_triangles(f255, area, mesh.adjacency, cent, levels=levels, **cut)
    times = {}
    blur_px = None
    if p.blur_correction and len(seg.mode_gray) > 1:
        t0 = time.perf_counter()
        # in 0-255 units like f255; the image unclipped (f255's clip only bounds outliers)
        level = region_levels(seg.material, f255, area, mesh.adjacency)
        f_sharp, blur_px = blur_corrected_gray(
            f255, mesh.points, mesh.triangles, level, (img - offset) * factor,
            blur_min_self_weight=p.blur_min_self_weight, blur_max_px=p.blur_max_px)
        times["blur_correction"] = time.perf_counter() - t0
        seg = segment_triangles(np.clip(f_sharp, 0.0, 255.0), area, mesh.adjacency, cent,
                                levels=levels, **cut)
    # the index of the level each material was cut at
    material = np.searchsorted(levels, seg.mode_gray)[seg.material]
    if claim:
        material = claim_missing_levels(f255, material, levels, mesh.adjacency)
    if fixed:  # one numbering for every slice
        mat_gray = levels / factor + offset if factor else np.full(len(levels), offset)
    else:
        # numbered by mean gray in the input's units (the 0-255 copy is clipped)
        material, mat_gray, _ = order_by_gray(material, gray, area)
    return MeshLabels(material=material.astype(np.int64), material_gray=np.asarray(mat_gray, float),
                      levels_255=seg.mode_gray if not fixed else levels,
                      pixel_sigma=float(pixel_sigma), segmentation=seg, blur_px=blur_px,
                      times_s=times, levels_report=levels_report)
