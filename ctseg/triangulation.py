"""Stage 4: Delaunay triangulation of the CVT sites and triangle adjacency (paper 5.4, SPEC 4)."""
from dataclasses import dataclass

import numpy as np
from scipy.spatial import Delaunay, QhullError

from .errors import InputError


@dataclass
class TriangleMesh:
    """A 2D triangle mesh in pixel-index coordinates.

    Attributes
    ----------
    points : (n, 2) float64 ndarray
        Vertices (x, y) = (col, row).
    triangles : (m, 3) int64 ndarray
        Vertex indices, counter-clockwise in (x, y).
    adjacency : (k, 2) int64 ndarray
        Pairs of triangles sharing an edge, first index smaller.
    shared_edges : (k, 2) int64 ndarray
        The vertex pair of the edge each adjacent pair shares.
    """

    points: np.ndarray
    triangles: np.ndarray
    adjacency: np.ndarray
    shared_edges: np.ndarray


def triangle_areas(points, triangles):
    """Signed areas (positive for counter-clockwise in x, y)."""
    p = points[triangles]
    return 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))


def triangle_edges(triangles):
    """All edges of all triangles: (3m, 2) sorted vertex pairs and the owning triangle."""
    t = np.asarray(triangles)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e.sort(axis=1)
    owner = np.tile(np.arange(len(t)), 3)
    return e, owner


def edge_adjacency(triangles):
    """Triangles sharing an edge: (pairs, shared_edges, boundary_edges).

    ``pairs`` (k, 2): adjacent triangle pairs, smaller index first, sorted;
    ``shared_edges`` (k, 2): the vertex pair each shares; ``boundary_edges``: edges used by
    one triangle only. Raises InputError if an edge is used by more than two triangles.
    """
    e, owner = triangle_edges(triangles)
    if len(e) == 0:
        z = np.zeros((0, 2), np.int64)
        return z, z, z
    order = np.lexsort((owner, e[:, 1], e[:, 0]))
    e, owner = e[order], owner[order]
    same = np.all(e[1:] == e[:-1], axis=1)
    if np.any(same[1:] & same[:-1]):
        raise InputError("mesh: an edge is shared by more than two triangles (non-manifold)")
    first = np.flatnonzero(same)
    pairs = np.column_stack([owner[first], owner[first + 1]])
    pairs.sort(axis=1)
    shared = e[first]
    single = np.ones(len(e), bool)
    single[first] = False
    single[first + 1] = False
    o = np.lexsort((pairs[:, 1], pairs[:, 0]))
    return pairs[o].astype(np.int64), shared[o].astype(np.int64), e[single].astype(np.int64)


def delaunay_mesh(sites, rel_area_tol=1e-12):
    """Delaunay triangulation of the sites, counter-clockwise, with triangle adjacency.

    Parameters
    ----------
    sites : (n, 2) array_like
        Distinct points (x, y), not all collinear, n >= 3.
    rel_area_tol : float
        Triangles with area below ``rel_area_tol`` times the hull's bounding-box area are
        degenerate; none may be emitted (an error is raised if Qhull produces one).

    Returns
    -------
    TriangleMesh
        Points are the sites (in the same order); a site Qhull could not use (a duplicate)
        raises InputError instead of leaving a vertex without triangles.

    Raises
    ------
    InputError
        Fewer than 3 sites, all collinear, duplicates, or a degenerate triangle.

    References
    ----------
    Yang et al. 2014, section 5.4 (the paper uses CGAL; Qhull gives the same triangulation
    up to the choice among co-circular configurations).

    Example
    -------
    >>> import numpy as np
    >>> mesh = delaunay_mesh(np.array([[0, 0], [4, 0], [0, 3], [4, 3], [2, 1.5]], float))
    >>> len(mesh.triangles), float(triangle_areas(mesh.points, mesh.triangles).sum())
    (4, 12.0)
    """
    pts = np.asarray(sites, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3:
        raise InputError(f"sites: need at least 3 points of shape (n, 2), got {pts.shape}")
    if len(np.unique(pts, axis=0)) != len(pts):
        raise InputError("sites: duplicate points cannot be triangulated")
    try:
        tri = Delaunay(pts)
    except QhullError as exc:
        raise InputError(f"sites: cannot triangulate (all collinear?): {str(exc).splitlines()[0]}") from None
    t = tri.simplices.astype(np.int64)
    if len(tri.coplanar):
        raise InputError(f"sites: {len(tri.coplanar)} site(s) could not be triangulated")
    area = triangle_areas(pts, t)
    t[area < 0] = t[area < 0][:, [0, 2, 1]]
    span = np.ptp(pts, axis=0)
    if np.any(np.abs(area) <= rel_area_tol * span[0] * span[1]):
        raise InputError("sites: the triangulation has a degenerate (zero-area) triangle")
    # one order whatever Qhull's: each triangle starts at its smallest vertex (the cyclic,
    # counter-clockwise order kept), triangles sorted; sites that moved by a rounding error
    # (a world -> index round trip) then give the same mesh, not a permutation of it
    t = np.take_along_axis(t, (np.argmin(t, axis=1)[:, None] + np.arange(3)) % 3, axis=1)
    t = t[np.lexsort((t[:, 2], t[:, 1], t[:, 0]))]
    return triangle_mesh(pts, t)


def triangle_mesh(points, triangles):
    """A :class:`TriangleMesh` (with its adjacency) from points and triangles made elsewhere,
    e.g. read back from a file or a VTK pipeline.

    Raises
    ------
    InputError
        Triangles that index missing points, or an edge shared by more than two triangles.
    """
    pts = np.asarray(points, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(t) and (t.min() < 0 or t.max() >= len(pts)):
        raise InputError(f"mesh: triangles refer to points outside 0..{len(pts) - 1}")
    pairs, shared, _ = edge_adjacency(t)
    return TriangleMesh(points=pts, triangles=t, adjacency=pairs, shared_edges=shared)
