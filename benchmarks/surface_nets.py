"""A label map's material surfaces by VTK's vtkSurfaceNets3D (the voxel baselines' meshes in
benchmarks/volume3d.py): triangles between labels, each material's closed surface (the
volume padded with one voxel of background so that surfaces close on the box), its
non-manifold edges, and the interface vertices per pair of labels."""
import numpy as np

PAD = 255  # background label of the padding


def surface_nets(labels, spacing):
    """Run vtkSurfaceNets3D (triangles, default smoothing) on ``labels`` (nz, ny, nx) of
    small non-negative ints with voxel centres at (i, j, k) x spacing.

    Returns
    -------
    points : (n, 3) ndarray, physical (x, y, z)
    triangles : (t, 3) int64 ndarray
    pair : (t, 2) int64 ndarray, the labels either side (PAD outside the box)
    """
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk, vtk_to_numpy

    lab = np.pad(np.asarray(labels, np.uint8), 1, constant_values=PAD)
    img = vtk.vtkImageData()
    img.SetDimensions(*lab.shape[::-1])
    img.SetSpacing(*spacing)
    img.SetOrigin(*(-np.asarray(spacing, float)))
    img.GetPointData().SetScalars(numpy_to_vtk(lab.ravel(), deep=True))
    nets = vtk.vtkSurfaceNets3D()
    nets.SetInputData(img)
    nets.SetBackgroundLabel(PAD)
    nets.SetOutputMeshTypeToTriangles()
    for i, v in enumerate(np.unique(lab[lab != PAD])):
        nets.SetLabel(i, float(v))
    nets.Update()
    out = nets.GetOutput()
    pts = vtk_to_numpy(out.GetPoints().GetData()).astype(float)
    tri = vtk_to_numpy(out.GetPolys().GetConnectivityArray()).reshape(-1, 3).astype(np.int64)
    pair = vtk_to_numpy(out.GetCellData().GetArray("BoundaryLabels")).reshape(-1, 2).astype(np.int64)
    return pts, tri, np.sort(pair, axis=1)


def closed_surface_report(triangles, pair):
    """Per label: the triangles of its closed surface, the edges used by other than 2 of
    them (non-manifold where more, open where fewer)."""
    out = {}
    for m in np.unique(pair[pair != PAD]):
        tri = triangles[np.any(pair == m, axis=1)]
        edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
        _, uses = np.unique(edges, axis=0, return_counts=True)
        out[int(m)] = {"faces": int(len(tri)), "non_manifold_edges": int(np.sum(uses > 2)),
                       "boundary_edges": int(np.sum(uses < 2))}
    return out
