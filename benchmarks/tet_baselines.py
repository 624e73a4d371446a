"""The tetrahedral meshers ctseg's 3D mode is measured against (benchmarks/volume3d.py):
CGAL Mesh_3 through pygalmesh and Cleaver through itk-cleaver, each on a finished label
map (they mesh labels, they do not segment). Neither is a ctseg dependency:

- pygalmesh 0.10.7 (the ``bench3d`` extra) has no wheel; it builds against CGAL and Eigen
  (Debian: ``apt-get install libcgal-dev libeigen3-dev``, then ``pip install
  ".[bench3d]"``, about 5 minutes).
- itk-cleaver 1.3.1 crashes on first use with the itk 5.4 pip pulls in; it runs in an
  environment of its own (``python3 -m venv .venv-cleaver && .venv-cleaver/bin/pip install "itk==5.3.0"
  "numpy<2" "itk-cleaver==1.3.1"``), called as a subprocess (benchmarks/cleaver_child.py).

Both give points in physical units (voxel centres at index x spacing, as ctseg's),
tetrahedra and the input label of each tetrahedron.
"""
import os
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def cgal_mesh(labels, spacing, max_cell_circumradius_vox=3.0, max_facet_distance_vox=0.5):
    """CGAL Mesh_3 (pygalmesh.generate_from_array) on ``labels`` (nz, ny, nx), every label
    meshed (CGAL leaves label 0 out: labels are shifted by one). Sizes in voxels of the
    finest spacing."""
    import pygalmesh

    values = np.unique(labels)
    # CGAL reports its progress on the C++ stdout whatever ``verbose`` says: sent to
    # /dev/null (the benchmark's child speaks JSON on stdout)
    sys.stdout.flush()
    saved, null = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    shifted = (np.searchsorted(values, labels) + 1).astype(np.uint8)
    sp = np.asarray(spacing, float)
    h = float(sp.min())
    # pygalmesh takes the array as (x, y, z)
    try:
        mesh = pygalmesh.generate_from_array(np.ascontiguousarray(shifted.transpose(2, 1, 0)), tuple(sp),
                                             max_cell_circumradius=max_cell_circumradius_vox * h,
                                             max_facet_distance=max_facet_distance_vox * h, verbose=False)
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)
    tets = mesh.get_cells_type("tetra").astype(np.int64)
    ref = np.asarray(mesh.get_cell_data("medit:ref", "tetra"), np.int64)
    # CGAL's image domain puts voxel i's centre at (i + 1/2) x spacing
    points = np.asarray(mesh.points, float) - 0.5 * sp
    return points, tets, values[ref - 1]


def cleaver_mesh(labels, spacing, python):
    """Cleaver on ``labels`` in the environment of ``python`` (see the module docstring):
    points, tetrahedra, labels, and the meshing call's own time and peak memory."""
    with tempfile.TemporaryDirectory() as tmp:
        src, out = os.path.join(tmp, "labels.npy"), os.path.join(tmp, "mesh.npz")
        np.save(src, np.asarray(labels))
        run = subprocess.run([python, os.path.join(HERE, "cleaver_child.py"), src, out],
                             capture_output=True, text=True)
        if run.returncode:
            raise RuntimeError(f"cleaver failed: {run.stderr.strip()[-500:]}")
        d = np.load(out)
        # only the vertices of the kept tetrahedra (Cleaver meshes a cube round the image),
        # in physical units (Cleaver meshes in index units)
        used, tets = np.unique(d["tetrahedra"], return_inverse=True)
        points = d["points"][used] * np.asarray(spacing, float)
        return (points, tets.reshape(-1, 4), d["label"], float(d["wall_s"]), float(d["peak_mib"]))


def label_voxels(points, tetrahedra, material, shape, spacing, outside):
    """Each voxel's material: that of the tetrahedra overlapping most of it (exact
    overlaps, :func:`ctseg.tetra_gray.voxel_overlaps`); ``outside`` where none reaches it
    (CGAL rounds the box's edges and corners off)."""
    from ctseg.tetra_gray import voxel_overlaps

    # their meshes reach the voxels' outer faces, half a voxel beyond the box of voxel
    # centres that voxel_overlaps takes: measured in the volume padded by one voxel
    padded = tuple(int(n) + 2 for n in shape)
    tet, vox, ov = voxel_overlaps(np.asarray(points, float) + np.asarray(spacing, float), tetrahedra,
                                  padded, spacing)
    mat = np.asarray(material, np.int64)
    k, n = int(mat.max()) + 1, int(np.prod(padded))
    acc = np.bincount(vox * k + mat[tet], weights=ov, minlength=n * k).reshape(n, k)
    labels = np.argmax(acc, axis=1)
    labels[acc.sum(axis=1) == 0] = outside
    return labels.reshape(padded)[1:-1, 1:-1, 1:-1]


def tet_surface_report(tetrahedra, material):
    """Each material's closed surface from its tetrahedra (faces with one side in the
    material): faces, and edges used by more than 2 (non-manifold) or fewer (open) of
    them; plus the vertices of the faces between each pair of materials."""
    tets = np.asarray(tetrahedra, np.int64)
    mat = np.asarray(material, np.int64)
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 2, 3]], tets[:, [0, 1, 3]], tets[:, [0, 1, 2]]])
    owner = np.tile(np.arange(len(tets)), 4)
    key, inv, count = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    first = np.full(len(key), -1)
    second = np.full(len(key), -1)
    order = np.argsort(inv, kind="stable")
    starts = np.searchsorted(inv[order], np.arange(len(key)))
    first[:] = owner[order[starts]]
    two = count == 2
    second[two] = owner[order[starts[two] + 1]]
    ma = mat[first]
    mb = np.where(two, mat[np.maximum(second, 0)], -1)
    report, pairs = {}, {}
    for m in np.unique(mat):
        on = (ma == m) ^ (mb == m)
        tri = key[on]
        edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [0, 2]]]), axis=1)
        _, uses = np.unique(edges, axis=0, return_counts=True)
        report[int(m)] = {"faces": int(on.sum()), "non_manifold_edges": int(np.sum(uses > 2)),
                          "boundary_edges": int(np.sum(uses < 2))}
    inner = two & (ma != mb)
    lo, hi = np.minimum(ma, mb)[inner], np.maximum(ma, mb)[inner]
    for a, b in np.unique(np.column_stack([lo, hi]), axis=0):
        rows = (lo == a) & (hi == b)
        pairs[(int(a), int(b))] = np.unique(key[inner][rows])
    return report, pairs
