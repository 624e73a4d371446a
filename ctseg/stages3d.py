"""The stages of the 3D method (SPEC 9), one function each: what
:func:`ctseg.pipeline3d.segment_volume_3d` runs in order and the VTK stage filters
(:mod:`ctseg.filters`) call one at a time, so that both share one implementation.

:func:`density_3d` (9.1) -> :func:`cvt_sites_3d` (9.2-9.3) -> :func:`tetrahedra_3d` (9.4) ->
:func:`ctseg.tetra_gray.tetra_gray` (9.5) -> :func:`ctseg.labelling3d.label_tetrahedra` (9.6) ->
:func:`ctseg.surfaces.material_interfaces` and :func:`ctseg.surfaces.material_surface`
(9.7). Points are physical coordinates of the box, (x, y, z) = (i, j, k) x spacing;
:func:`tetra_mesh` rebuilds the face graph of tetrahedra read back from elsewhere (a VTK
grid)."""
import dataclasses

import numpy as np

from ._validate import check_spacing
from .cvt3d import coarse_sites_3d, lloyd_cvt_3d
from .density import density_volume
from .density_capped import capped_density_volume
from .errors import InputError, MeshCheckError, ParameterError
from .params import AUTO, DEFAULTS, resolve
from .pipeline import DENSITY_KEYS
from .site_budget import site_budget_3d
from .sites import initial_sites_3d
from .subpixel import EDGE_PX, subpixel_mesh
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


def density_3d(image, params=None, spacing=None, cap=None):
    """3D stage 1 (SPEC 9.1): the density volume of ``image`` (nz, ny, nx) with the
    density parameters (:func:`ctseg.density.density_volume`); with a ``cap`` (input
    units, :func:`density_cap`), raised where the volume clipped at the cap shows edges
    that the densest material hides (:func:`ctseg.density_capped.capped_density_volume`)."""
    p = resolve(params)
    kwargs = {k: getattr(p, k) for k in DENSITY_KEYS}
    if cap is None:
        return density_volume(image, _spacing(spacing), **kwargs)
    return capped_density_volume(image, cap, _spacing(spacing), **kwargs)


def density_cap(levels_255, gray_scale):
    """The cap of :func:`density_3d`: the second-highest material level, in input units,
    when there are at least three materials (the densest one's edges can hide a third
    one's); None otherwise.

    Parameters
    ----------
    levels_255 : sequence of float
        Material levels on the 0-255 scale.
    gray_scale : (offset, factor)
        The input's rescaling to that scale, ``gray_255 = (gray - offset) * factor``.

    Returns
    -------
    cap : float or None

    Example
    -------
    >>> density_cap([20.0, 200.0, 80.0], (1000.0, 0.1))
    1800.0
    >>> density_cap([20.0, 200.0], (1000.0, 0.1)) is None
    True
    """
    if len(levels_255) < 3:
        return None
    offset, factor = gray_scale
    return float(np.sort(np.asarray(levels_255, float))[-2] / factor + offset)


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
