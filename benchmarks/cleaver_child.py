"""Cleaver (itk-cleaver) on a label map, run in Cleaver's own environment (itk 5.3 and
numpy < 2: with the itk 5.4 that pip pulls in by default it crashes on first use; see
benchmarks/tet_baselines.py). Not imported by ctseg.

    CLEAVER_PYTHON benchmarks/cleaver_child.py LABELS.npy OUT.npz

LABELS.npy: (nz, ny, nx) small ints. Writes OUT.npz with ``points`` (index units, voxel
centres at integers), ``tetrahedra``, ``label`` (the input label of each tetrahedron) and
``wall_s`` (the meshing call alone) and ``peak_mib``."""
import resource
import sys
import time

import itk
import numpy as np


def main(src, out):
    labels = np.load(src)
    values = np.unique(labels)
    # Cleaver's indicator functions divide by the label: none may be 0
    image = itk.image_from_array((np.searchsorted(values, labels) + 1).astype(np.float32))
    t0 = time.perf_counter()
    tet_mesh, _ = itk.cleaver_image_to_mesh_filter(image)
    wall = time.perf_counter() - t0
    points = itk.array_from_vector_container(tet_mesh.GetPoints()).astype(np.float64)
    cells = itk.array_from_vector_container(tet_mesh.GetCellsArray()).reshape(-1, 6)
    index = itk.array_from_vector_container(tet_mesh.GetCellData()).astype(np.int64)
    inside = index < len(values)  # the last index is the padding round the image's cube
    np.savez(out, points=points - 0.5, tetrahedra=cells[inside, 2:].astype(np.int64),
             label=values[index[inside]], wall_s=wall,
             peak_mib=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)


if __name__ == "__main__":
    main(*sys.argv[1:3])
