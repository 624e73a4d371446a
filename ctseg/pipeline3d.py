"""The method in 3D (SPEC 9): a volume -> segmented tetrahedra and closed per-material
surfaces, from the gray values at once (no label map first).

:func:`segment_volume_3d` runs the stages of :mod:`ctseg.stages3d` and the labelling of
:mod:`ctseg.labelling3d` in order (the VTK stage filters call the same functions one at a
time)."""
from dataclasses import dataclass, field, replace

import numpy as np

from ._allocation import bulk_allocations
from ._validate import as_volume, check_spacing, check_value_range
from .beam_hardening import correct_streaks_volume
from .errors import InputError
from .levels import volume_levels
from .params import AUTO, resolve
from .pipeline import monotone_progress, stage_runner
from .resources import SITE_3D_BYTES, VOLUME_3D_BYTES_PER_VOXEL, check_memory
from .labelling3d import label_tetrahedra
from .stages3d import (cvt_sites_3d, default_n_sites_3d, density_3d, density_cap,  # noqa: F401
                       n_sites_3d, subpixel_boundary_3d, tetrahedra_3d)
from .surfaces import material_interfaces, material_surface
from .tetra_gray import VoxelOverlaps
from .tetrahedra import tetra_quality


@dataclass
class TetraSegmentation:
    """A segmented tetrahedral mesh of a volume, in physical coordinates of the box
    (x, y, z) = (i, j, k) x spacing; world coordinates add the volume's origin and
    direction (the VTK layer does).

    Attributes
    ----------
    points : (n, 3) float64 ndarray
    tetrahedra : (m, 4) int64 ndarray, positively oriented
    material : (m,) int64 ndarray, 0..K-1 by ascending gray
    gray : (m,) float64 ndarray, mean gray in the input's units
    adjacency : (a, 2) int64 ndarray, tetrahedra sharing a face
    interfaces : (f, 3) int64 ndarray
        Faces between materials, oriented from ``interface_materials[:, 0]`` (the lower
        number) to ``[:, 1]``.
    interface_materials : (f, 2) int64 ndarray
    surfaces : list of ctseg.surfaces.MaterialSurface
        One closed, outward-oriented, manifold surface per material.
    material_gray : (K,) float64 ndarray, input units
    spacing : (3,) float64 ndarray
    shape : tuple, the volume's (nz, ny, nx)
    diagnostics : dict
    """

    points: np.ndarray
    tetrahedra: np.ndarray
    material: np.ndarray
    gray: np.ndarray
    adjacency: np.ndarray
    interfaces: np.ndarray
    interface_materials: np.ndarray
    surfaces: list
    material_gray: np.ndarray
    spacing: np.ndarray
    shape: tuple
    diagnostics: dict = field(default_factory=dict)

    @property
    def n_materials(self):
        return len(self.material_gray)


def check_shape_3d(shape, name="volume"):
    """Refuse a shape the 3D mode cannot mesh: not 3D, or under 2 voxels along an axis, whose
    name (numpy order z, y, x) the message gives with the slices mode that works.

    Raises
    ------
    InputError

    Example
    -------
    >>> check_shape_3d((6, 1, 14))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ctseg.errors.InputError: volume: shape (6, 1, 14) has 1 voxel along y; ... --axis y)
    """
    shape = tuple(int(n) for n in shape)
    if len(shape) != 3:
        raise InputError(f"{name}: shape {shape}; 3D mode needs a volume of at least 2 voxels "
                         "along every axis (one slice: use slices mode)")
    if min(shape) < 2:
        axis = "zyx"[int(np.argmin(shape))]
        raise InputError(f"{name}: shape {shape} has {min(shape)} voxel along {axis}; 3D mode needs a "
                         "volume of at least 2 voxels along every axis (slices across "
                         f"{axis} work: axis='{axis}', CLI --axis {axis})")


@bulk_allocations()
def segment_volume_3d(volume, params=None, *, spacing=None, progress=None, **overrides):
    """Segment a volume into tetrahedra with one material each, and closed surfaces.

    density (SPEC 9.1) -> Ward sites on voxel blocks (9.2) -> voxel CVT (9.3) -> Delaunay
    tetrahedra, slivers perturbed away (9.4, :func:`ctseg.tetrahedra.perturb_slivers`) ->
    exact tetrahedron gray (9.5) -> recursive graph cut on the
    tetrahedron graph with the levels and rules of 2D (9.6) -> with ``subpixel_boundary``,
    vertices between two materials moved to the ISO-50 crossing (SPEC 10,
    :func:`ctseg.stages3d.subpixel_boundary_3d`) -> interfaces and closed surfaces per
    material (9.7). Each stage is a function of :mod:`ctseg.stages3d` (the labelling of
    :mod:`ctseg.labelling3d`), which the VTK stage filters call too.

    Parameters
    ----------
    volume : (nz, ny, nx) array_like
    params : ctseg.params.SegmentParams or dict, optional
    spacing : (3,) array_like, optional
        Voxel size along x, y, z (default 1): distances, densities, volumes and the CVT
        energy are physical.
    progress : callable, optional
        ``progress(fraction_done, stage)``.
    **overrides
        Single parameters by name.

    Returns
    -------
    TetraSegmentation

    Raises
    ------
    InputError
        Not a finite 3D volume of at least 2 voxels a side.
    ParameterError
        A bad parameter or spacing.

    Notes
    -----
    The material levels are the volume's (:func:`ctseg.levels.volume_levels`); with
    ``streak_correction`` every z slice through metal is first corrected against them,
    as in slices mode, once a probe of every 4th such slice finds streaks
    (:func:`ctseg.beam_hardening.correct_streaks_volume`). With three or more levels the
    density is raised where the volume clipped at the second-highest level shows edges
    that the densest material's hide (:func:`ctseg.stages3d.density_cap`,
    :func:`ctseg.density_capped.capped_density_volume`; ``diagnostics["density_cap"]``).
    Where the flat voxels hold
    partial volume (their spread more than twice the tetrahedra's), the labelling takes
    the levels of the tetrahedron grays instead, and a level that the homogeneous
    tetrahedra (voxels spreading as the noise) show between two levels, and none
    explains, is added (:func:`ctseg.levels3d.checked_levels`; ``diagnostics["levels"]``
    says which).
    Tetrahedra straddling a boundary whose voxels mostly vote for other materials are
    relabelled (:func:`ctseg.mixed_tetra.relabel_mixed`; ``diagnostics["relabelled_mixed"]``),
    and between two materials of high contrast a boundary tetrahedron whose gray lies beyond
    the half-way gray takes its neighbour's material (:func:`ctseg.mixed_tetra.relabel_beyond_iso50`;
    ``diagnostics["relabelled_iso50"]``). A piece of a material that touches a darker
    and a brighter one and holds no interior tetrahedron is their partial-volume mix and
    takes the darkest or the brightest material it touches, whichever level is nearer its
    gray, unless it is as large as a thin layer
    (:func:`ctseg.partial_volume.relabel_partial_volume_pieces`;
    ``diagnostics["relabelled_pieces"]``).
    Pieces of a material touching along an edge only are joined or separated by
    relabelling the tetrahedra around that edge (:func:`ctseg.surfaces.repair_pinched_edges`),
    so every surface is a closed manifold; ``diagnostics["relabelled_for_manifold"]``
    counts them. With ``blur_correction`` the grays are corrected for the blur the first
    labelling predicts and labelled again, as in 2D (:func:`ctseg.blur.blur_corrected_gray_3d`).

    Two rules differ from 2D because tetrahedra along an edge can be smaller than the
    blur: an element is interior when most of its voxels are flat (the un-sharpened
    density below half its range), not when its steps to its neighbours are small (a band
    of small elements in an edge's blur has small steps between them); and the first
    labelling, whose blur the correction predicts, leaves out the thin-layer rules (a
    band of blurred-edge elements with an intermediate gray must not predict a layer of
    the intermediate material); the second labelling applies them.

    While it runs, large arrays reuse the C heap instead of fresh page mappings
    (:func:`ctseg._allocation.bulk_allocations`); the results do not depend on it.

    Example
    -------
    >>> from ctseg.phantoms import make_volume
    >>> seg = segment_volume_3d(make_volume(12, 24, seed=1).image, n_sites=300)
    >>> all(abs(s.enclosed_volume - s.element_volume) < 1e-9 * s.element_volume
    ...     for s in seg.surfaces)
    True
    """
    p = resolve(params, **overrides)
    vol = as_volume(volume)
    check_value_range(vol, "volume")
    check_shape_3d(vol.shape)
    sp = check_spacing((1.0, 1.0, 1.0) if spacing is None else spacing)
    report = monotone_progress(progress)
    times, peaks = {}, {}
    timed = stage_runner(report, times, peaks)

    image = vol.astype(np.float64)
    scale, levels, pixel_sigma, _ = timed("levels", 0.0, volume_levels, image, p, 0)
    streak_weights, streak_probed, streak_halo_px = [], 0, []
    if p.streak_correction and len(levels) > 1:
        image, streak_weights, streak_probed, streak_halo_px = timed(
            "streak_correction", 0.02, correct_streaks_volume, image, p, gray_scale=scale,
            levels_255=levels)
    n_sites, site_report = timed("site_budget", 0.04, n_sites_3d, image, p)
    check_memory(max(0, n_sites - default_n_sites_3d(image.shape, p.voxels_per_site))
                 * SITE_3D_BYTES + image.size * VOLUME_3D_BYTES_PER_VOXEL,
                 f"meshing a {' x '.join(map(str, image.shape))} volume with {n_sites} sites "
                 "in 3D", "set n_sites or site_rule='area', crop or downsample it, or use "
                 "slices mode")
    cap = density_cap(levels, scale)
    rho = timed("density", 0.05, density_3d, image, p, sp, cap)
    cvt = cvt_sites_3d(rho, p, sp, n_sites=n_sites, timed=timed,
                       progress=lambda it, n: report(0.2 + 0.5 * it / max(n, 1), "cvt"))
    # the density and the voxels' region labels are done with: the labelling's peak is lower
    del rho
    cvt = replace(cvt, labels=None)
    mesh, slivers = timed("tetrahedra", 0.7, tetrahedra_3d, cvt.sites, image.shape, p, sp)

    def gray_of():  # the overlaps, kept for every later mean over the mesh
        overlaps = VoxelOverlaps(mesh.points, mesh.tetrahedra, image.shape, sp)
        return overlaps, overlaps.tetra_mean(image)
    overlaps, gray = timed("tetra_gray", 0.75, gray_of)
    labels = label_tetrahedra(image, mesh, gray, p, sp, levels=(scale, levels, pixel_sigma),
                              timed=timed, overlaps=overlaps)
    del overlaps
    material, mat_gray = labels.material, labels.material_gray
    n_moved = 0
    if p.subpixel_boundary:  # the labels stay; the mesh's vertices move
        moved = timed("subpixel_boundary", 0.92, subpixel_boundary_3d, image, mesh.points,
                      mesh.tetrahedra, gray, material, p, sp, renumber=p.gray_levels == AUTO)
        mesh = replace(mesh, points=moved.points)
        gray, material, n_moved = moved.gray, moved.material, moved.n_moved
        if moved.material_gray is not None:
            mat_gray = moved.material_gray
    faces, mat_a, mat_b = material_interfaces(mesh, material)
    report(0.95, "surfaces")
    surfaces = timed("surfaces", 0.95, lambda: [material_surface(mesh, material, k)
                                               for k in range(len(mat_gray))])
    quality = tetra_quality(mesh.points, mesh.tetrahedra)
    report(1.0, "done")
    diagnostics = {
        "mode": "3d",
        "volume_shape": list(vol.shape),
        "spacing": [float(v) for v in sp],
        "n_sites": int(n_sites),
        "sites": site_report,
        "n_vertices": int(len(mesh.points)),
        "n_tetrahedra": int(len(mesh.tetrahedra)),
        "n_interface_triangles": int(len(faces)),
        "n_materials": int(len(mat_gray)),
        "material_gray": [float(v) for v in mat_gray],
        "material_levels_255": [float(v) for v in labels.levels_255],
        "levels": labels.levels_report,
        "material_noise_255": float(pixel_sigma),
        "gray_rescale": {"offset": float(scale[0]), "factor": float(scale[1])},
        "density_cap": cap,
        "times_s": times,
        "peak_memory_mib": peaks,
        "total_time_s": float(sum(times.values())),
        "cvt_energy": [float(e) for e in cvt.energy],
        "lloyd_iterations": int(cvt.n_iter),
        "coarse_lloyd_iterations": int(cvt.coarse_iter),
        "lloyd_converged": bool(cvt.converged),
        "empty_regions": int(cvt.empty_regions),
        "graphcut_calls": labels.graphcut_calls,
        "blur_px": labels.blur_px,
        "relabelled_for_manifold": labels.relabelled,
        "relabelled_mixed": labels.mixed_relabelled,
        "relabelled_iso50": labels.iso50_relabelled,
        "relabelled_pieces": labels.pieces_relabelled,
        "subpixel_moved": int(n_moved),
        "element_quality": quality,
        "slivers_left": int(slivers),
        "streak_weights": streak_weights,
        "streak_halo_px": streak_halo_px,
        "streak_slices_probed": streak_probed,
        "surfaces": [{"material": s.material, "triangles": int(len(s.triangles)),
                      "vertices": int(len(s.points)), "enclosed_volume": s.enclosed_volume,
                      "element_volume": s.element_volume} for s in surfaces],
        "parameters": p.to_dict(),
    }
    return TetraSegmentation(points=mesh.points, tetrahedra=mesh.tetrahedra,
                             material=material, gray=gray,
                             adjacency=mesh.adjacency, interfaces=faces,
                             interface_materials=np.column_stack([mat_a, mat_b]),
                             surfaces=surfaces, material_gray=mat_gray,
                             spacing=sp, shape=tuple(vol.shape), diagnostics=diagnostics)
