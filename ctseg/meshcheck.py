"""The checks every mesh must pass before ctseg writes it (pymeshlab plus exact numpy tests)."""
import numpy as np

from .errors import MeshCheckError


def mesh_check_report(points, triangles, rel_area_tol=1e-12):
    """Measure what makes a triangle mesh unfit to write.

    Uses pymeshlab's topological measures (non-manifold edges and vertices, unreferenced
    vertices) and its duplicate / null face removal filters (a face count that drops means
    duplicated or zero-area faces), plus an exact orientation test: every interior edge
    must be traversed once in each direction by its two triangles.

    Parameters
    ----------
    points : (n, 2) or (n, 3) array_like
    triangles : (m, 3) int array_like

    Returns
    -------
    report : dict
        Counts, and ``ok`` (bool).
    """
    import pymeshlab

    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim == 2 and pts.shape[1] == 2:
        pts = np.column_stack([pts, np.zeros(len(pts))])
    tri = np.asarray(triangles, dtype=np.int32).reshape(-1, 3)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=pts, face_matrix=tri))
    topo = ms.get_topological_measures()
    n_faces = ms.current_mesh().face_number()
    ms.meshing_remove_duplicate_faces()
    dup = n_faces - ms.current_mesh().face_number()
    ms.meshing_remove_null_faces()
    null = n_faces - dup - ms.current_mesh().face_number()
    # exact zero-area test in the mesh's own plane (pymeshlab's null test is exact equality)
    p = pts[tri]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    span = np.ptp(pts, axis=0)
    scale = max(float(np.sort(span)[-1] * np.sort(span)[-2]), 1e-300)
    degenerate = int(np.sum(area2 <= 2 * rel_area_tol * scale))
    # orientation: directed edges must be unique
    directed = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    _, counts = np.unique(directed, axis=0, return_counts=True)
    inconsistent = int(np.sum(counts > 1))
    report = {
        "faces": int(n_faces),
        "vertices": int(len(pts)),
        "non_manifold_edges": int(topo["non_two_manifold_edges"]),
        "non_manifold_vertices": int(topo["non_two_manifold_vertices"]),
        "unreferenced_vertices": int(topo["unreferenced_vertices"]),
        "duplicated_faces": int(dup),
        "null_faces": int(null),
        "degenerate_faces": degenerate,
        "inconsistently_oriented_edges": inconsistent,
    }
    report["ok"] = all(v == 0 for k, v in report.items() if k not in ("faces", "vertices"))
    return report


def check_mesh(points, triangles, what="mesh"):
    """Raise MeshCheckError naming every failed check; return the report if all pass."""
    report = mesh_check_report(points, triangles)
    if not report["ok"]:
        bad = ", ".join(f"{k}={v}" for k, v in report.items()
                        if k not in ("faces", "vertices", "ok") and v)
        raise MeshCheckError(f"{what}: failed the mesh checks ({bad}); nothing was written")
    return report
