"""The stages of the 3D method (SPEC 9), one function each: what
:func:`ctseg.pipeline3d.segment_volume_3d` runs in order and the VTK stage filters
(:mod:`ctseg.filters`) call one at a time, so that both share one implementation.

:func:`density_3d` (9.1) -> :func:`cvt_sites_3d` (9.2-9.3) -> :func:`tetrahedra_3d` (9.4) ->
:func:`ctseg.tetra_gray.tetra_gray` (9.5) -> :func:`label_tetrahedra` (9.6) ->
:func:`ctseg.surfaces.material_interfaces` and :func:`ctseg.surfaces.material_surface`
(9.7). Points are physical coordinates of the box, (x, y, z) = (i, j, k) x spacing;
:func:`tetra_mesh` rebuilds the face graph of tetrahedra read back from elsewhere (a VTK
grid)."""
import dataclasses
from dataclasses import dataclass

import numpy as np

from ._validate import check_spacing
from .blur import blur_corrected_gray_3d, region_levels
from .cvt3d import coarse_sites_3d, lloyd_cvt_3d
from .density import density_volume
from .errors import InputError, MeshCheckError, ParameterError
from .labelling import CUT_KEYS
from .levels import volume_levels
from .levels3d import checked_levels
from .mixed_tetra import relabel_beyond_iso50, relabel_mixed, tetra_spread
from .params import AUTO, DEFAULTS, resolve
from .partial_volume import claim_missing_levels, relabel_partial_volume_pieces
from .pipeline import DENSITY_KEYS
from .recursive_cut import order_by_gray, resolved_min_material_area, segment_triangles
from .site_budget import site_budget_3d
from .sites import initial_sites_3d
from .subpixel import EDGE_PX, subpixel_mesh
from .surfaces import repair_pinched_edges
from .tetra_gray import VoxelOverlaps
from .tetrahedra import TetraMesh, face_graph, perturb_slivers, tetra_volumes


def default_n_sites_3d(shape, voxels_per_site=DEFAULTS.voxels_per_site):
    """Default number of sites in 3D: one per ``voxels_per_site`` voxels, at least 64 and
    at most one per voxel.

    Example
    -------
    >>> default_n_sites_3d((64, 64, 64), voxels_per_site=256)
    1024
    """
    n = int(np.prod([int(s) for s in shape]))
    return int(min(n, max(64, round(n / voxels_per_site))))


def _untimed(name, fraction, fn, *args, **kwargs):
    """The stage runner of a stage function called alone: runs ``fn``, nothing recorded."""
    return fn(*args, **kwargs)


def _spacing(spacing):
    return check_spacing((1.0, 1.0, 1.0) if spacing is None else spacing)


def n_sites_3d(volume, params=None):
    """The number of CVT sites of a volume: ``n_sites``, or with AUTO
    :func:`ctseg.site_budget.site_budget_3d` of the gray volume (``site_rule``,
    ``voxels_per_site``, ``min_pixels_per_site``, ``density_sigma_px``).

    Returns
    -------
    n_sites : int
    report : dict
        :func:`ctseg.site_budget.site_budget_3d`'s report; ``rule`` 'given' when
        ``n_sites`` was.

    Raises
    ------
    ParameterError
        More sites than voxels.

    Example
    -------
    >>> n_sites_3d(np.zeros((20, 20, 20)), {"voxels_per_site": 100})[0]
    80
    >>> n_sites_3d(np.zeros((8, 8, 8)), {"n_sites": 70})[0]
    70
    """
    p = resolve(params)
    vol = np.asarray(volume)
    if p.n_sites == AUTO:
        return site_budget_3d(vol, p.voxels_per_site, p.min_pixels_per_site, p.site_rule,
                              p.density_sigma_px)
    if p.n_sites > vol.size:
        raise ParameterError(f"n_sites: {p.n_sites} sites for a volume of {vol.size} voxels")
    return int(p.n_sites), {"n_sites": int(p.n_sites), "rule": "given",
                            "reason": "n_sites given"}


def density_3d(image, params=None, spacing=None):
    """3D stage 1 (SPEC 9.1): the density volume of ``image`` (nz, ny, nx) with the
    density parameters (:func:`ctseg.density.density_volume`)."""
    p = resolve(params)
    return density_volume(image, _spacing(spacing), **{k: getattr(p, k) for k in DENSITY_KEYS})


def cvt_sites_3d(rho, params=None, spacing=None, *, n_sites=None, progress=None, timed=None):
    """3D stages 2-3 (SPEC 9.2-9.3): initial sites (:func:`ctseg.sites.initial_sites_3d`)
    and the voxel CVT (:func:`ctseg.cvt3d.lloyd_cvt_3d`) of a density volume; with
    ``fine_iter_3d`` > 0 Lloyd runs first on 2 x 2 x 2 voxel blocks
    (:func:`ctseg.cvt3d.coarse_sites_3d`, to ``max_iter``), then at most ``fine_iter_3d``
    iterations on the voxels.

    Parameters
    ----------
    rho : (nz, ny, nx) ndarray
        From :func:`density_3d`.
    params, spacing
        As :func:`segment_volume_3d`.
    n_sites : int, optional
        Default ``params.n_sites``; needed when that is 'auto' (the count comes from the
        gray volume, :func:`n_sites_3d`, which the density does not show).
    progress : callable, optional
        ``progress(iteration, max_iter)`` after every Lloyd iteration.
    timed : callable, optional
        A stage runner (:func:`ctseg.pipeline.stage_runner`) recording 'initial_sites',
        'coarse_cvt' and 'cvt'.

    Returns
    -------
    ctseg.cvt3d.CVT3DResult
        Sites (x, y, z) physical, with their classes.
    """
    p = resolve(params)
    sp = _spacing(spacing)
    run = timed or _untimed
    if n_sites is None:
        if p.n_sites == AUTO:
            raise ParameterError("n_sites: 'auto' needs the gray volume; pass "
                                 "n_sites=n_sites_3d(volume, params)[0]")
        n_sites = p.n_sites
    sites0 = run("initial_sites", 0.1, initial_sites_3d, rho, n_sites, sp, init=p.init,
                 seed=p.seed, ward_block_px=p.ward_block_px)
    lloyd = dict(tol_px=p.tol_px, max_iter=p.max_iter, progress=progress,
                 energy_rtol_3d=p.energy_rtol_3d, overrelaxation_3d=p.overrelaxation_3d)
    coarse_iter = 0
    if p.fine_iter_3d:
        if progress is not None:  # the coarse run reports the first half, the fine one the rest
            lloyd["progress"] = lambda it, n: progress(it, 2 * n)
        sites0, coarse_iter = run("coarse_cvt", 0.15, coarse_sites_3d, rho, sites0, sp, **lloyd)
        lloyd["progress"] = progress
        if coarse_iter:
            lloyd["max_iter"] = p.fine_iter_3d
            if progress is not None:
                lloyd["progress"] = lambda it, n: progress(n + it, 2 * n)
    return dataclasses.replace(run("cvt", 0.2, lloyd_cvt_3d, rho, sites0, sp, **lloyd),
                               coarse_iter=coarse_iter)


def tetrahedra_3d(sites, shape, params=None, spacing=None):
    """3D stage 4 (SPEC 9.4): the Delaunay tetrahedra of CVT sites over the box of voxel
    centres of a volume of ``shape`` (nz, ny, nx), slivers perturbed away
    (:func:`ctseg.tetrahedra.perturb_slivers` with ``sliver_min_dihedral_deg``,
    ``sliver_rounds`` and ``seed``).

    Returns
    -------
    mesh : ctseg.tetrahedra.TetraMesh
    slivers : int
        Tetrahedra left below the angle.
    """
    p = resolve(params)
    box = (np.array(tuple(shape)[::-1], float) - 1.0) * _spacing(spacing)
    _, mesh, slivers = perturb_slivers(sites, box, p.sliver_min_dihedral_deg, p.sliver_rounds,
                                       seed=p.seed)
    return mesh, slivers


def subpixel_boundary_3d(image, points, tetrahedra, gray, material, params=None, spacing=None,
                         renumber=True):
    """3D stage 8 (SPEC 10): the vertices between exactly two materials moved to the ISO-50
    crossing of the gray (:func:`ctseg.subpixel.subpixel_mesh` on the tetrahedra, moves of
    at most ``subpixel_max_shift`` of the shortest incident edge, crossings on a step only:
    :data:`ctseg.subpixel.EDGE_PX`), no tetrahedron inverted, squashed below a fifth of its
    volume or turned into a sliver (smallest dihedral angle below
    ``sliver_min_dihedral_deg`` and its own); the labels stay.

    Parameters
    ----------
    image : (nz, ny, nx) ndarray
        The volume the mesh was labelled on (after any streak correction).
    points : (n, 3) ndarray
        Physical box coordinates (a :class:`ctseg.tetrahedra.TetraMesh`'s).
    tetrahedra : (m, 4) int ndarray
    gray, material : (m,) array_like
        From :func:`label_tetrahedra` (input units; 0..K-1).
    params, spacing
        As :func:`segment_volume_3d`.
    renumber : bool
        Number the materials again by their mean gray (False with given levels).

    Returns
    -------
    ctseg.subpixel.MovedMesh
        Points in the box's physical coordinates.

    Example
    -------
    >>> vol = np.where(np.arange(12) < 5.7, 10.0, 90.0)[None, None, :].repeat(12, 0).repeat(12, 1)
    >>> mesh, _ = tetrahedra_3d(np.array([[x, y, z] for x in (0, 5, 11) for y in (0, 11)
    ...                                   for z in (0, 11)] + [[5.0, 5.5, 5.5]], float), vol.shape)
    >>> from ctseg.tetra_gray import tetra_gray
    >>> cx = mesh.points[mesh.tetrahedra].mean(axis=1)[:, 0]
    >>> gray = tetra_gray(vol, mesh.points, mesh.tetrahedra)
    >>> out = subpixel_boundary_3d(vol, mesh.points, mesh.tetrahedra, gray, (cx > 5).astype(int))
    >>> centre = np.argmin(np.abs(mesh.points - [5.0, 5.5, 5.5]).sum(axis=1))
    >>> out.n_moved, round(float(out.points[centre, 0]), 1)  # the edge is at x = 5.5
    (1, 5.5)
    """
    p = resolve(params)
    return subpixel_mesh(image, points, tetrahedra, gray, material,
                         p.subpixel_max_shift, renumber, spacing=_spacing(spacing),
                         min_dihedral_deg=p.sliver_min_dihedral_deg, edge_px=EDGE_PX)


def tetra_mesh(points, tetrahedra):
    """A :class:`ctseg.tetrahedra.TetraMesh` of given points and tetrahedra (the face
    graph built as :func:`ctseg.tetrahedra.delaunay_tetrahedra` builds it); negatively
    oriented tetrahedra get two vertices swapped.

    Raises
    ------
    InputError
        Not (n, 3) points and (m, 4) vertex indices, or a face shared by more than two
        tetrahedra.

    Example
    -------
    >>> mesh = tetra_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]],
    ...                   [[0, 1, 2, 3], [1, 3, 2, 4]])
    >>> mesh.adjacency.tolist(), mesh.tetrahedra[1].tolist()  # the second one turned
    ([[0, 1]], [1, 2, 3, 4])
    """
    pts = np.asarray(points, np.float64)
    tets = np.array(tetrahedra, np.int64)
    if pts.ndim != 2 or pts.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] != 4:
        raise InputError(f"tetrahedra: expected (n, 3) points and (m, 4) vertex indices, got "
                         f"shapes {pts.shape} and {tets.shape}")
    if len(tets) and (tets.min() < 0 or tets.max() >= len(pts)):
        raise InputError("tetrahedra: a vertex index outside the points")
    neg = tetra_volumes(pts, tets) < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    try:
        adjacency, shared, bfaces, owner = face_graph(tets)
    except MeshCheckError as exc:
        raise InputError(str(exc)) from None
    return TetraMesh(points=pts, tetrahedra=tets, adjacency=adjacency, shared_faces=shared,
                     boundary_faces=bfaces, boundary_owner=owner)


@dataclass
class TetraLabels:
    """Outcome of :func:`label_tetrahedra`.

    Attributes
    ----------
    material : (m,) int64 ndarray, 0..K-1 by ascending gray
    material_gray : (K,) float64 ndarray, input units
    levels_255 : (L,) ndarray, the material levels used (0-255 scale)
    scale : (offset, factor), the gray map onto 0-255
    pixel_sigma : float, the noise of the flat voxels (0-255 scale)
    graphcut_calls : int, of the last labelling
    blur_px : float or None, the fitted blur (None without blur correction)
    relabelled : int, tetrahedra relabelled for manifold surfaces
    mixed_relabelled, iso50_relabelled, pieces_relabelled : int, tetrahedra (pieces) relabelled
        by :func:`ctseg.mixed_tetra.relabel_mixed`, :func:`ctseg.mixed_tetra.relabel_beyond_iso50`
        and :func:`ctseg.partial_volume.relabel_partial_volume_pieces`
    levels_report : dict, how the levels were chosen (:func:`ctseg.levels3d.checked_levels`)
    """

    material: np.ndarray
    material_gray: np.ndarray
    levels_255: np.ndarray
    scale: tuple
    pixel_sigma: float
    graphcut_calls: int
    blur_px: object
    relabelled: int
    levels_report: dict
    mixed_relabelled: int
    iso50_relabelled: int
    pieces_relabelled: int


def label_tetrahedra(image, mesh, gray, params=None, spacing=None, *, levels=None, timed=None,
                     overlaps=None):
    """3D stages 6-7 (SPEC 9.6): one material per tetrahedron, from the gray levels, the
    recursive graph cut on the tetrahedron graph and the blur correction, with the rules
    of :func:`segment_volume_3d` (see its Notes); then pinched edges repaired
    (:func:`ctseg.surfaces.repair_pinched_edges`) and materials numbered by gray.

    Parameters
    ----------
    image : (nz, ny, nx) ndarray
        The volume the mesh was made on (after any streak correction).
    mesh : ctseg.tetrahedra.TetraMesh
        Physical coordinates (:func:`tetrahedra_3d` or :func:`tetra_mesh`).
    gray : (m,) array_like
        Tetrahedron mean gray in the volume's units (:func:`ctseg.tetra_gray.tetra_gray`).
    params, spacing
        As :func:`segment_volume_3d`.
    levels : (scale, levels_255, sigma_255), optional
        The gray map and material levels of the flat voxels; default measured on
        ``image`` (:func:`ctseg.levels.volume_levels`). They are checked against the
        tetrahedra's grays first (:func:`ctseg.levels3d.checked_levels`).
    timed : callable, optional
        A stage runner (:func:`ctseg.pipeline.stage_runner`) recording 'level_check',
        'graphcut', 'blur_correction', 'graphcut_2', 'mixed_relabel', 'iso50_relabel',
        'piece_relabel' and 'manifold_repair'.
    overlaps : ctseg.tetra_gray.VoxelOverlaps, optional
        The mesh's voxel overlaps on ``image``'s shape, if kept from the gray: every mean
        over the mesh then reads them instead of clipping the tetrahedra again (default:
        computed here, once).

    Returns
    -------
    TetraLabels

    Raises
    ------
    InputError
        ``gray`` not one value per tetrahedron.
    """
    p = resolve(params)
    sp = _spacing(spacing)
    run = timed or _untimed
    image = np.asarray(image, np.float64)
    gray = np.asarray(gray, np.float64)
    if gray.shape != (len(mesh.tetrahedra),):
        raise InputError(f"gray: expected one value per tetrahedron ({len(mesh.tetrahedra)}), "
                         f"got shape {gray.shape}")
    if levels is None:
        levels = volume_levels(image, p, 0)[:3]
    scale, levels, pixel_sigma = levels
    offset, factor = scale
    if overlaps is None:
        overlaps = VoxelOverlaps(mesh.points, mesh.tetrahedra, image.shape, sp)
    volume_vox = tetra_volumes(mesh.points, mesh.tetrahedra) / float(np.prod(sp))
    cent = mesh.points[mesh.tetrahedra].mean(axis=1)

    cut = {k: getattr(p, k) for k in CUT_KEYS}
    if p.weight_by_edge_length:  # the shared faces' areas, in voxel faces (as 2D's pixels)
        a, b, c = (mesh.points[mesh.shared_faces[:, i]] for i in range(3))
        area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        cut["edge_length"] = area / float(np.prod(sp)) ** (2.0 / 3.0)
    vol255, mean255 = (image - offset) * factor, (gray - offset) * factor
    f255 = np.clip(mean255, 0.0, 255.0)

    def check_levels():  # the tetrahedra's spreads serve the levels and the mixed rule
        spread = tetra_spread(vol255, overlaps, mean255)
        return spread, checked_levels(levels, pixel_sigma, f255, volume_vox, p, *spread)
    spread, (levels, levels_report) = run("level_check", 0.79, check_levels)
    # interior: most of the element's voxels are flat (the un-sharpened density below
    # half its range, as the flat pixels that measure the levels)
    strength = density_volume(image, sp, density_sigma_px=p.flat_sigma_px, density_floor=p.density_floor,
                              density_saturation=p.density_saturation, density_ridge=0.0)
    flat = (strength - p.density_floor) < 0.5
    interior = overlaps.tetra_mean(flat.astype(np.float64)) >= 0.5
    cut["interior"] = interior
    # the first pass without the thin-layer rules: a band of blurred-edge elements with an
    # intermediate gray must not predict a layer to the blur correction
    seg = run("graphcut", 0.8, segment_triangles, f255, volume_vox, mesh.adjacency, cent,
              levels=levels, thin_layers=not p.blur_correction, **cut)
    blur_px = None
    if p.blur_correction and len(seg.mode_gray) > 1:
        def sharpen():
            level = region_levels(seg.material, f255, volume_vox, mesh.adjacency)
            return blur_corrected_gray_3d(f255, mesh.points, mesh.tetrahedra, level, vol255, sp,
                                          blur_min_self_weight=p.blur_min_self_weight,
                                          blur_max_px=p.blur_max_px, overlaps=overlaps)
        f_sharp, blur_px = run("blur_correction", 0.85, sharpen)
        seg = run("graphcut_2", 0.88, segment_triangles, np.clip(f_sharp, 0.0, 255.0),
                  volume_vox, mesh.adjacency, cent, levels=levels, **cut)
    material = np.searchsorted(levels, seg.mode_gray)[seg.material]
    material, mixed = run("mixed_relabel", 0.89, relabel_mixed, vol255, mesh.points,
                          mesh.tetrahedra, material, levels, sp, mean_255=mean255,
                          adjacency=mesh.adjacency, overlaps=overlaps, spread=spread)
    # noise of the flat voxels' 3 x 3 means: neighbour differences count a porous volume's edges
    material, beyond = run("iso50_relabel", 0.895, relabel_beyond_iso50, f255, material,
                           levels, mesh.adjacency, 3.0 * pixel_sigma)
    layer_vox = 4.0 * resolved_min_material_area(p.min_material_area, volume_vox)
    material, pieces = run("piece_relabel", 0.897, relabel_partial_volume_pieces, f255,
                           material, levels, mesh.adjacency, volume_vox, interior, layer_vox)
    if p.n_materials != AUTO and p.gray_levels == AUTO:  # the K materials asked for get elements
        material = claim_missing_levels(f255, material, levels, mesh.adjacency)
    material, relabelled = run("manifold_repair", 0.9, repair_pinched_edges, mesh, material,
                               volume_vox)
    # materials numbered by level; those no tetrahedron holds are dropped from the count
    material, mat_gray, _ = order_by_gray(material, gray, volume_vox)
    return TetraLabels(material=material.astype(np.int64),
                       material_gray=np.asarray(mat_gray, float), levels_255=levels,
                       scale=(offset, factor), pixel_sigma=pixel_sigma,
                       graphcut_calls=int(seg.graphcut_calls), blur_px=blur_px,
                       relabelled=int(relabelled), levels_report=levels_report,
                       mixed_relabelled=int(mixed), iso50_relabelled=int(beyond),
                       pieces_relabelled=int(pieces))
