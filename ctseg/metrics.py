"""Accuracy against ground truth: per-material Dice and boundary distance in pixels."""
import numpy as np
from scipy.spatial import cKDTree

from .errors import InputError
from .raster import label_image, subpixel_label_image, tetra_label_volume, volume_labels


def dice_per_label(pred, truth, n_labels=None):
    """Dice coefficient 2|A∩B|/(|A|+|B|) for each label 0..n_labels-1 (nan if both empty)."""
    pred = np.asarray(pred).ravel()
    truth = np.asarray(truth).ravel()
    if n_labels is None:
        n_labels = int(max(pred.max(), truth.max())) + 1
    out = np.full(n_labels, np.nan)
    for k in range(n_labels):
        a, b = pred == k, truth == k
        s = a.sum() + b.sum()
        if s:
            out[k] = 2.0 * np.sum(a & b) / s
    return out


def matched_dice_per_label(pred, truth):
    """Dice of each true label after mapping every found label to the true label it
    overlaps most, so that a false extra material (an artefact split off a true one) costs
    only the voxels it holds, whatever its gray.

    Parameters
    ----------
    pred, truth : int array_like of one shape
        Found and true labels, each >= 0.

    Returns
    -------
    dice : (truth.max() + 1,) float ndarray
        As :func:`dice_per_label` of the mapped labels.

    Example
    -------
    >>> truth = np.array([0, 0, 0, 1, 1, 1])
    >>> pred = np.array([0, 2, 0, 1, 1, 0])   # label 2 is a false material inside 0
    >>> np.round(matched_dice_per_label(pred, truth), 3).tolist()
    [0.857, 0.8]
    """
    pred, truth = np.asarray(pred).ravel(), np.asarray(truth).ravel()
    n_true = int(truth.max()) + 1
    counts = np.zeros((int(pred.max()) + 1, n_true), np.int64)
    np.add.at(counts, (pred, truth), 1)
    return dice_per_label(counts.argmax(axis=1)[pred], truth, n_true)


def truth_boundary_points(truth, supersample=1):
    """Points (x, y) in pixel units midway between neighbouring truth cells of different label."""
    lab = np.asarray(truth)
    s = float(supersample)
    r, c = np.nonzero(lab[:, 1:] != lab[:, :-1])
    h = np.column_stack([(c + 1.0) / s - 0.5, (r + 0.5) / s - 0.5])
    r, c = np.nonzero(lab[1:, :] != lab[:-1, :])
    v = np.column_stack([(c + 0.5) / s - 0.5, (r + 1.0) / s - 0.5])
    return np.concatenate([h, v])


def sample_segments(points, edges, step_px=0.25):
    """Points along line segments, both ends included, at most ``step_px`` apart.

    Parameters
    ----------
    points : (n, 2) ndarray
    edges : (k, 2) int ndarray
        Segments as pairs of indices into ``points``.
    step_px : float
        Largest spacing of the samples along a segment.

    Returns
    -------
    samples : (s, 2) ndarray
    """
    p0, p1 = points[edges[:, 0]], points[edges[:, 1]]
    n = np.maximum(2, np.ceil(np.hypot(*(p1 - p0).T) / step_px).astype(int) + 1)
    idx = np.repeat(np.arange(len(edges)), n)
    t = np.concatenate([np.linspace(0, 1, k) for k in n]) if len(n) else np.zeros(0)
    return p0[idx] + t[:, None] * (p1[idx] - p0[idx])


def boundary_distance(points, boundary_edges, truth, supersample=1, step_px=0.25):
    """Mean distances (px) between the mesh's material boundary and the true boundary.

    Returns a dict: ``mesh_to_truth`` (mean over points sampled every ``step_px`` along the
    mesh boundary of the distance to the nearest true boundary point), ``truth_to_mesh``
    (the reverse, catching missed boundaries) and ``mean`` (their average). The true
    boundary is located to 1/(2*supersample) px.
    """
    tb = truth_boundary_points(truth, supersample)
    if len(boundary_edges) == 0 or len(tb) == 0:
        inf = float("inf") if (len(boundary_edges) == 0) != (len(tb) == 0) else 0.0
        return {"mesh_to_truth": inf, "truth_to_mesh": inf, "mean": inf}
    mb = sample_segments(np.asarray(points, float), np.asarray(boundary_edges), step_px)
    d1 = cKDTree(tb).query(mb)[0].mean()
    d2 = cKDTree(mb).query(tb)[0].mean()
    return {"mesh_to_truth": float(d1), "truth_to_mesh": float(d2), "mean": float(0.5 * (d1 + d2))}


def evaluate(seg, truth, supersample_truth=None, supersample=1):
    """Dice per material and boundary distance of a SegmentedMesh against truth labels.

    ``truth`` labels are per pixel, numbered by ascending gray like the materials;
    ``supersample_truth`` (optional) is a finer truth map (``supersample`` sub-pixels per
    pixel side) for the boundary distance and for ``dice_subpixel``: Dice of the mesh
    against the fine truth, sub-pixel by sub-pixel. Per-pixel truth is a majority vote
    that must break ties (a pixel half polymer, half air is called air), and an edge through
    pixel centres then counts a whole row of pixels wrong whichever way the mesh decides;
    the sub-pixel Dice measures the area where mesh and part really disagree.
    """
    pred = label_image(seg.points, seg.triangles, seg.material, seg.shape)
    n = int(max(pred.max(), np.max(truth))) + 1
    dice = dice_per_label(pred, truth, n)
    bt = truth if supersample_truth is None else supersample_truth
    bd = boundary_distance(seg.points, seg.boundary_edges, bt, supersample)
    out = {"dice": [float(d) for d in dice], "min_dice": float(np.nanmin(dice)),
           "n_materials_found": int(seg.n_materials), "n_materials_true": int(np.max(truth)) + 1,
           "boundary_px": bd}
    if supersample_truth is not None:
        fine, covered = subpixel_label_image(seg.points, seg.triangles, seg.material,
                                             seg.shape, supersample)
        fine_truth = np.asarray(supersample_truth)
        n = max(n, int(fine_truth.max()) + 1)
        sub = dice_per_label(fine[covered], fine_truth[covered], n)
        out["dice_subpixel"] = [float(d) for d in sub]
        out["min_dice_subpixel"] = float(np.nanmin(sub))
    return out


def evaluate_volume(vseg, truth):
    """Dice per material over a whole volume, and the boundary distance averaged over the
    slices that have a true boundary, of a :class:`ctseg.volume.VolumeSegmentation`."""
    truth = np.asarray(truth, np.int64)
    pred = volume_labels(vseg, truth.shape)
    n = int(max(pred.max(), truth.max())) + 1
    dice = dice_per_label(pred, truth, n)
    dist = []
    for k, seg in enumerate(vseg.slices):
        t = np.take(truth, k, axis=vseg.axis)
        if len(np.unique(t)) > 1:
            dist.append(boundary_distance(seg.points, seg.boundary_edges, t))
    mean = {key: float(np.mean([d[key] for d in dist])) if dist else 0.0
            for key in ("mesh_to_truth", "truth_to_mesh", "mean")}
    return {"dice": [float(d) for d in dice], "min_dice": float(np.nanmin(dice)),
            "n_materials_found": int(vseg.n_materials), "n_materials_true": int(truth.max()) + 1,
            "boundary_px": mean, "slices_with_boundaries": len(dist)}


def evaluate_tetra(result, truth):
    """Dice per material of a TetraSegmentation against per-voxel truth labels (numbered by
    ascending gray like the materials), the tetrahedra rasterised by
    :func:`tetra_label_volume`.

    Returns
    -------
    dict
        ``dice`` (per label, NaN where neither has it), ``min_dice``,
        ``n_materials_found``, ``n_materials_true``.

    Raises
    ------
    InputError
        Truth of another shape than the segmented volume.
    """
    truth = np.asarray(truth)
    if truth.shape != tuple(result.shape):
        raise InputError(f"truth: shape {truth.shape} differs from the volume's {tuple(result.shape)}")
    truth = truth.astype(np.int64)
    pred = tetra_label_volume(result.points, result.tetrahedra, result.material, result.shape,
                              result.spacing)
    n = int(max(pred.max(), truth.max())) + 1
    dice = dice_per_label(pred, truth, n)
    return {"dice": [float(v) for v in dice], "min_dice": float(np.nanmin(dice)),
            "n_materials_found": int(result.n_materials), "n_materials_true": int(truth.max()) + 1}
