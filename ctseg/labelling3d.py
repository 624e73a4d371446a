"""3D stages 6-7 (SPEC 9.6): one material per tetrahedron, the 3D counterpart of
:func:`ctseg.labelling.label_mesh`: the levels checked against the tetrahedra, the
recursive graph cut on the tetrahedron graph, the blur correction, the partial-volume
rules and the manifold repair, on the functions the 2D labelling uses."""
from dataclasses import dataclass

import numpy as np

from .blur import blur_corrected_gray_3d, region_levels
from .density import density_volume
from .errors import InputError
from .labelling import CUT_KEYS
from .levels import volume_levels
from .levels3d import checked_levels
from .mixed_tetra import own_vote_share, relabel_beyond_iso50, relabel_mixed, tetra_spread
from .params import AUTO, resolve
from .partial_volume import claim_missing_levels, relabel_partial_volume_pieces
from .recursive_cut import order_by_gray, resolved_min_material_area, segment_triangles
from .stages3d import _spacing, _untimed
from .surfaces import repair_pinched_edges
from .tetra_gray import VoxelOverlaps
from .tetrahedra import tetra_volumes


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
    del strength, flat  # volumes the later stages do not need: a lower peak
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
                           material, levels, mesh.adjacency, volume_vox, interior, layer_vox,
                           own_share=lambda el, m: own_vote_share(vol255, overlaps, m, levels, el))
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
