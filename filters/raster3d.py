"""Tetrahedra to voxels, and Dice per material of a 3D segmentation against truth labels.

Nothing here needs VTK; it lives beside the 3D writers until it joins ``ctseg.raster`` and
``ctseg.metrics``."""
import numpy as np

from ctseg.errors import InputError, MeshCheckError

CANDIDATES_PER_CHUNK = 4_000_000
"""(tetrahedron, voxel) pairs tested at once: bounds the memory of :func:`tetra_label_volume`."""

BARY_TOL = 1e-9
"""Barycentric slack: a voxel centre on a face (or the box) counts as inside."""


def tetra_label_volume(points, tetrahedra, material, shape, spacing=(1.0, 1.0, 1.0)):
    """Label every voxel centre with the material of the tetrahedron it lies in.

    Voxel (k, j, i) has its centre at (i, j, k) x spacing, the coordinates of the
    tetrahedra of :class:`ctseg.pipeline3d.TetraSegmentation`. Each tetrahedron tests
    the voxel centres of its bounding box by their barycentric coordinates; a centre on a
    face shared by two tetrahedra takes the later one's material.

    Parameters
    ----------
    points : (n, 3) array_like
    tetrahedra : (m, 4) int array_like
    material : (m,) int array_like
    shape : (nz, ny, nx)
    spacing : (3,) array_like

    Returns
    -------
    labels : (nz, ny, nx) int64 ndarray

    Raises
    ------
    MeshCheckError
        Voxel centres no tetrahedron holds (the tetrahedra do not fill the box).

    Example
    -------
    >>> from ctseg.tetrahedra import delaunay_tetrahedra
    >>> c = np.array([[x, y, z] for x in (0, 2) for y in (0, 1) for z in (0, 1)], float)
    >>> mesh = delaunay_tetrahedra(np.vstack([c, [[1.0, 0.5, 0.5]]]), (2, 1, 1))
    >>> mat = (mesh.points[mesh.tetrahedra].mean(axis=1)[:, 0] > 1).astype(int)
    >>> lab = tetra_label_volume(mesh.points, mesh.tetrahedra, mat, (5, 5, 9), (0.25,) * 3)
    >>> lab[2, 2, [1, 7]].tolist()  # voxel centres (0.25, 0.5, 0.5) and (1.75, 0.5, 0.5)
    [0, 1]
    """
    shape = tuple(int(s) for s in shape)
    pts = np.asarray(points, float) / np.asarray(spacing, float)
    tets = np.asarray(tetrahedra, np.int64).reshape(-1, 4)
    mat = np.asarray(material, np.int64)
    P = pts[tets]  # (m, 4, 3), index units
    top = np.array(shape[::-1]) - 1
    lo = np.clip(np.ceil(P.min(axis=1) - 1e-7), 0, top).astype(np.int64)
    hi = np.clip(np.floor(P.max(axis=1) + 1e-7), 0, top).astype(np.int64)
    dims = np.maximum(hi - lo + 1, 0)
    count = dims.prod(axis=1)
    edges = P[:, 1:] - P[:, :1]  # (m, 3, 3): rows b-a, c-a, d-a
    det = np.linalg.det(edges)
    ok = np.abs(det) > 0
    inv = np.zeros_like(edges)
    inv[ok] = np.linalg.inv(np.transpose(edges[ok], (0, 2, 1)))
    labels = np.full(shape, -1, np.int64)
    flat = labels.reshape(-1)
    nx, ny = shape[2], shape[1]
    cum = np.cumsum(count)
    start = 0
    while start < len(tets):
        base = cum[start - 1] if start else 0
        stop = max(start + 1, int(np.searchsorted(cum, base + CANDIDATES_PER_CHUNK, "right")))
        t = np.repeat(np.arange(start, stop), count[start:stop])
        local = np.arange(len(t)) - np.repeat(cum[start:stop] - count[start:stop] - base,
                                              count[start:stop])
        d = dims[t]
        ijk = lo[t] + np.column_stack([local % d[:, 0], (local // d[:, 0]) % d[:, 1],
                                       local // (d[:, 0] * d[:, 1])])
        lam = np.einsum("nij,nj->ni", inv[t], ijk - P[t, 0])
        inside = ok[t] & np.all(lam >= -BARY_TOL, axis=1) & (lam.sum(axis=1) <= 1 + BARY_TOL)
        v = ijk[inside]
        flat[(v[:, 2] * ny + v[:, 1]) * nx + v[:, 0]] = mat[t[inside]]
        start = stop
    missing = int(np.sum(labels < 0))
    if missing:
        raise MeshCheckError(f"tetrahedra: {missing} voxel centre(s) lie in no tetrahedron")
    return labels


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
    from ctseg.metrics import dice_per_label

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
