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


def enclosed_volume(points, triangles):
    """Signed volume a closed triangle surface encloses (divergence theorem; positive for
    outward normals), summed about the points' centre so that a far origin costs no
    precision."""
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    tri = np.asarray(triangles, np.int64).reshape(-1, 3)
    if len(tri) == 0:
        return 0.0
    p = pts[tri] - 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    return float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0)


def self_intersecting_faces(points, triangles):
    """Faces that pymeshlab finds crossing another face of the same mesh.

    Coincident vertices are merged first: where pieces of a solid touch at a vertex the
    surface has one copy of it per piece, and faces meeting at two copies of one point
    would otherwise count as crossing."""
    import pymeshlab

    pts = np.asarray(points, np.float64).reshape(-1, 3)
    tri = np.asarray(triangles, np.int64).reshape(-1, 3)
    if len(tri) == 0:
        return 0
    uniq, inverse = np.unique(pts, axis=0, return_inverse=True)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=uniq,
                               face_matrix=inverse.ravel()[tri].astype(np.int32)))
    ms.compute_selection_by_self_intersections_per_face()
    return int(ms.current_mesh().selected_face_number())


def closed_surface_report(points, triangles, element_volume=None, rel_volume_tol=1e-9,
                          intersection_points=None):
    """Measure what makes a closed surface (a material's boundary) unfit to write.

    Everything :func:`mesh_check_report` measures, plus: boundary edges (a hole),
    self-intersecting faces (:func:`self_intersecting_faces`), the enclosed volume (which
    must be positive: outward normals) and, given ``element_volume`` (the volume of the
    solid's elements), its relative difference from it, which must stay within
    ``rel_volume_tol``.

    pymeshlab's face-face test decides nearly coplanar faces by rounding: faces of one
    flat side of a box, rotated into world coordinates, can come out as crossing. An
    affine map changes no intersection, so ``intersection_points`` (the same vertices in
    a frame where the flat sides are exactly flat, e.g. the box's own) may be given for
    that one test.

    Parameters
    ----------
    points : (n, 3) array_like
    triangles : (m, 3) int array_like
    element_volume : float, optional
    rel_volume_tol : float
    intersection_points : (n, 3) array_like, optional
        ``points`` under an affine map, for the self-intersection test.

    Returns
    -------
    report : dict
        Counts, volumes and ``ok`` (bool).

    Example
    -------
    >>> pts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    >>> r = closed_surface_report(pts, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], 1 / 6)
    >>> r["ok"], r["boundary_edges"]
    (True, 0)
    """
    import pymeshlab

    pts = np.asarray(points, np.float64).reshape(-1, 3)
    tri = np.asarray(triangles, np.int64).reshape(-1, 3)
    report = mesh_check_report(pts, tri)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=pts, face_matrix=tri.astype(np.int32)))
    report["boundary_edges"] = int(ms.get_topological_measures()["boundary_edges"])
    report["self_intersecting_faces"] = self_intersecting_faces(
        pts if intersection_points is None else intersection_points, tri)
    vol = enclosed_volume(pts, tri)
    report["enclosed_volume"] = vol
    report["inward"] = int(not vol > 0)
    if element_volume is not None:
        ev = float(element_volume)
        report["element_volume"] = ev
        err = abs(vol - ev) / max(abs(ev), 1e-300)
        report["volume_rel_error"] = err
        report["volume_mismatch"] = int(not err <= rel_volume_tol)
    counts = [k for k in report if k not in ("faces", "vertices", "ok", "enclosed_volume",
                                             "element_volume", "volume_rel_error")]
    report["ok"] = all(report[k] == 0 for k in counts)
    return report


def check_closed_surface(points, triangles, element_volume=None, what="surface",
                         intersection_points=None):
    """Raise MeshCheckError naming every failed check of :func:`closed_surface_report`;
    return the report if all pass."""
    report = closed_surface_report(points, triangles, element_volume,
                                   intersection_points=intersection_points)
    if not report["ok"]:
        bad = [f"{k}={v}" for k, v in report.items()
               if k not in ("faces", "vertices", "ok", "enclosed_volume", "element_volume",
                            "volume_rel_error", "volume_mismatch", "inward") and v]
        if report.get("inward"):
            bad.append(f"enclosed volume {report['enclosed_volume']:.6g} (not outward)")
        if report.get("volume_mismatch"):
            bad.append(f"encloses {report['enclosed_volume']:.12g}, its elements "
                       f"{report['element_volume']:.12g} (relative error "
                       f"{report['volume_rel_error']:.2g})")
        raise MeshCheckError(f"{what}: failed the closed-surface checks ({', '.join(bad)}); "
                             "nothing was written")
    return report
