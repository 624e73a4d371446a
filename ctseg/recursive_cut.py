"""The recursive graph-cut segmentation of an element graph into materials (paper 6 and
8; SPEC 7): the split of components, and the leaves turned into materials."""
from dataclasses import dataclass

import numpy as np

from .errors import ParameterError
from .graph import connected_pieces, nearest_level_core
from .graphcut import edge_distances, graphcut_split
from .levels import dominant_spread, material_modes
from .params import AUTO, DEFAULTS, check
from .partial_volume import (label_fragmented_layers, label_partial_volume_leaves,
                             partial_volume_elements)


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
    nearest, in_core = nearest_level_core(f, means)
    leaf = np.zeros(m, np.int64)
    leaf_material = []
    # a component with the adjacency rows inside it (in their order): a split reads only
    # its own edges
    stack = [(np.arange(m), np.arange(len(adjacency)), 0)]
    calls = deepest = 0
    in_comp = np.full(m, -1, np.int64)
    distance = edge_distances(centroids, adjacency)  # each cut reads its edges' share
    while stack:
        comp, rows, depth = stack.pop()
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
        in_comp[comp] = np.arange(len(comp))
        local = in_comp[adjacency[rows]]
        el = None if edge_length is None else edge_length[rows]
        labels, _ = graphcut_split(f[comp], local, None, seeds=(in_comp[s0], in_comp[s1]),
                                   edge_length=el, edge_distance=distance[rows], **cut_params)
        calls += 1
        # each side goes on as its connected pieces: a piece cut off far from the rest of
        # its side (a partial-volume triangle whose gray matches that side) is judged alone;
        # a piece's edges are the same-side edges between its elements
        same = labels[local[:, 0]] == labels[local[:, 1]]
        same_edges = local[same]
        n_pieces, piece = connected_pieces(same_edges, len(comp))
        order = np.argsort(piece, kind="stable")
        bounds = np.searchsorted(piece[order], np.arange(n_pieces + 1))
        edge_piece = piece[same_edges[:, 0]]
        edge_order = np.argsort(edge_piece, kind="stable")
        edge_bounds = np.searchsorted(edge_piece[edge_order], np.arange(n_pieces + 1))
        inner = rows[same][edge_order]
        for q in range(n_pieces - 1, -1, -1):
            stack.append((comp[order[bounds[q]:bounds[q + 1]]],
                          inner[edge_bounds[q]:edge_bounds[q + 1]], depth + 1))
    leaf_material = np.array(leaf_material, np.int64)
    label_fragmented_layers(area, leaf, leaf_material, adjacency, nearest, in_core,
                             min_layer_area, k_modes)
    label_partial_volume_leaves(f, area, leaf, leaf_material, adjacency, means,
                                 min_layer_area / 4.0)
    return leaf_material[leaf], leaf, calls, deepest


def order_by_gray(material, gray, area):
    """Renumber materials 0..K-1 by the area-weighted mean gray of what each holds.

    On a coarse mesh the partial-volume rules can make that order differ from the order of
    the gray levels, so numbering always follows what the triangles hold.

    Returns
    -------
    material : (m,) int64 ndarray
    mean_gray : (K,) ndarray, ascending; equal means (a mixture's can equal another
        material's) keep the order of their input labels
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


def resolved_min_material_area(min_material_area, area):
    """``min_material_area``, checked, with 'auto' resolved for elements of sizes ``area``:
    a thousandth of their total, at least 16 pixels (voxels in 3D)."""
    value = check("min_material_area", min_material_area)
    return max(16.0, 1e-3 * float(np.sum(area))) if value == AUTO else value


def segment_triangles(gray, area, adjacency, centroids, *,
                      step_threshold_255=DEFAULTS.step_threshold_255, merge_k=DEFAULTS.merge_k,
                      merge_rel=DEFAULTS.merge_rel, merge_floor_255=DEFAULTS.merge_floor_255,
                      merge_threshold_255=DEFAULTS.merge_threshold_255,
                      min_triangles=DEFAULTS.min_triangles, max_depth=DEFAULTS.max_depth,
                      min_material_area=DEFAULTS.min_material_area,
                      min_pocket_area=DEFAULTS.min_pocket_area, n_materials=DEFAULTS.n_materials,
                      theta_255=DEFAULTS.theta_255, lam=DEFAULTS.lam, beta=DEFAULTS.beta,
                      eps_255=DEFAULTS.eps_255, edge_length=None, levels=None,
                      thin_layers=True, interior=None):
    """Recursive graph-cut segmentation of an element graph (triangles or tetrahedra) into
    materials.

    Notes
    -----
    Rules (SPEC 7, with the choices made where it leaves room; ``docs/method.md`` has the
    measurements behind them):

    1. Material gray levels come first, given as ``levels`` or else from the data.
       Elements whose gray differs from every neighbour's by at most
       ``step_threshold_255`` are *interior* (not straddling a boundary). The modes of the
       size-weighted histogram of interior grays (smoothed by the noise sigma of interior
       elements in the largest material) are the candidate materials
       (:func:`ctseg.levels.material_modes`); neighbouring modes merge unless a valley
       below half the lower peak separates them by at least ``max(merge_floor_255,
       merge_k * sigma) + merge_rel * gray`` (or ``merge_threshold_255``) gray levels;
       the term proportional to the gray allows for beam hardening, whose errors grow
       with attenuation. A mode holding less than ``min_material_area`` is not a
       material. Merging compares modes, never chains of single elements, so
       intermediate partial-volume grays cannot join two materials.
    2. Start from all elements as one component. While a component holds, in two or more
       materials, >= ``min_pocket_area`` of elements whose gray lies in the material's
       core (within a quarter of the gap to the neighbouring levels; the paper: "while
       the gray range is above a threshold"), cut it in two with
       :func:`ctseg.graphcut.graphcut_split` and recurse on both sides. The seeds are the
       interior elements closest to the darkest and brightest materials present, not the
       paper's darkest and brightest elements, which in a real scan are single noisy or
       partial-volume elements. Each side of a cut recurses as its connected pieces (the
       seed sets of eq. 8 can pull a far-away partial-volume element to a side by gray
       alone). ``min_triangles`` and ``max_depth`` guard against endless splitting.
    3. Each leaf becomes the material that holds most of its interior size, or else, if
       it covers at least 4 x ``min_material_area``, the one material whose core holds its
       elements (a thin wall has few interior elements). Any other leaf is a
       partial-volume mix or a small pocket (a steel/polymer mix can have aluminium's
       gray, so gray alone cannot tell): if its gray lies between the materials of the
       leaves around it, it joins the closest of those, else the material closest in
       gray. Two exceptions for thin layers, which have no interior elements: adjacent
       such leaves that together cover 4 x ``min_material_area``, more than half of it in
       one material's core, are that material
       (:func:`ctseg.partial_volume.label_fragmented_layers`); and a leaf of at least
       ``min_material_area`` whose gray lies in the core of a material between its
       neighbours' is that material (too large to be a mixed band).
    4. Then element by element (twice): an element that is not interior and whose gray
       lies between the levels of two materials among its own and its neighbours' takes
       the closer of those, i.e. the material that covers most of it
       (:func:`ctseg.partial_volume.partial_volume_elements`).
    5. Materials are numbered 0..K-1 by ascending gray; ``n_materials=K`` merges the least
       separated modes until K remain (ParameterError if the data show fewer than K).

    Parameters
    ----------
    gray : (m,) array_like
        Element gray values on the 0-255 scale.
    area : (m,) array_like
        Element sizes (areas in px^2, or volumes).
    adjacency : (k, 2) int array_like
        Adjacent element pairs.
    centroids : (m, d) array_like
        Element barycentres.
    step_threshold_255, merge_k, merge_rel, merge_floor_255, merge_threshold_255,
    min_triangles, max_depth, min_material_area, min_pocket_area, n_materials
        The rules above; ranges and defaults in :mod:`ctseg.params`.
    theta_255, lam, beta, eps_255, edge_length
        Passed to the graph cut (SPEC 6).
    thin_layers : bool
        Apply the two thin-layer exceptions of rule 3 (off: every leaf without interior
        elements is a partial-volume mix; the 3D mode's first pass, whose blur correction
        then tells a real layer from a blurred edge).
    interior : (m,) bool array_like, optional
        Which elements lie inside a material, instead of rule 1's step test (the 3D mode
        uses the image's flat voxels: its elements can be smaller than the blur, so a
        band of them along an edge has small steps between them).
    levels : (K,) array_like, optional
        Material gray levels found elsewhere (e.g.
        :func:`ctseg.levels.pixel_material_levels` on the image, which sees far more
        samples than the elements); replaces rule 1.

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

    Example
    -------
    >>> import numpy as np
    >>> gray = np.r_[np.full(6, 20.0), np.full(6, 200.0)]
    >>> pairs = np.column_stack([np.arange(11), np.arange(1, 12)])
    >>> cent = np.column_stack([np.arange(12.0), np.zeros(12)])
    >>> seg = segment_triangles(gray, np.full(12, 10.0), pairs, cent, min_material_area=5)
    >>> seg.material.tolist()
    [0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1]
    """
    f = np.asarray(gray, float)
    area = np.asarray(area, float)
    adjacency = np.asarray(adjacency, np.int64).reshape(-1, 2)
    centroids = np.asarray(centroids, float)
    if (f.ndim != 1 or len(f) == 0 or area.shape != f.shape or centroids.ndim != 2
            or len(centroids) != len(f)):
        raise ParameterError("segment_triangles: gray, area and centroids must describe the "
                             "same elements")
    s = step_noise(f, adjacency, area)
    step_threshold = check("step_threshold_255", step_threshold_255)
    if step_threshold == AUTO:
        step_threshold = max(4.0 * s, 2.0)
    merge_k, merge_rel = check("merge_k", merge_k), check("merge_rel", merge_rel)
    merge_floor = check("merge_floor_255", merge_floor_255)
    merge_threshold = check("merge_threshold_255", merge_threshold_255)
    min_triangles = check("min_triangles", min_triangles)
    max_depth = check("max_depth", max_depth)
    min_material_area = resolved_min_material_area(min_material_area, area)
    min_pocket_area = check("min_pocket_area", min_pocket_area)
    n_materials = check("n_materials", n_materials)
    n_materials = None if n_materials == AUTO else n_materials
    if edge_length is not None:
        edge_length = np.asarray(edge_length, float)
        if edge_length.shape != (len(adjacency),):
            raise ParameterError(f"edge_length: expected shape ({len(adjacency)},), got {edge_length.shape}")
    cut_params = dict(theta_255=check("theta_255", theta_255), lam=check("lam", lam),
                      beta=check("beta", beta), eps_255=check("eps_255", eps_255))

    if interior is None:
        interior = interior_triangles(f, adjacency, step_threshold, 0.5 * merge_rel)
    else:
        interior = np.asarray(interior, bool)
        if interior.shape != f.shape:
            raise ParameterError(f"interior: expected one flag per element ({len(f)}), got "
                                 f"shape {interior.shape}")
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
        if merge_threshold == AUTO:
            base = max(merge_floor, merge_k * sigma)
            separation = lambda level: base + merge_rel * level  # noqa: E731
        else:
            separation = lambda level: merge_threshold  # noqa: E731
        means, edges = material_modes(f[interior], area[interior], max(sigma, 0.5),
                                      min_material_area if n_materials is None else 0.0,
                                      separation, n_modes=n_materials)
    material, leaf, calls, deepest = _recursive_split(
        f, area, adjacency, centroids, interior, edges, means, min_pocket_area,
        4.0 * min_material_area if thin_layers else np.inf, min_triangles, max_depth,
        cut_params, edge_length)
    material = partial_volume_elements(f, material, interior, adjacency, means)
    material, mat_gray, used = order_by_gray(material, f, area)
    return MaterialSegmentation(material=material, material_gray=mat_gray,
                                mode_gray=means[used], leaf=leaf, graphcut_calls=calls,
                                max_depth_reached=deepest, step_noise=s,
                                step_threshold=step_threshold, material_noise=sigma)
