"""3D stage 4 (SPEC 9.4): the Delaunay tetrahedra of the CVT sites, their face graph and
their quality."""
from dataclasses import dataclass

import numpy as np

from ._retet import (circumspheres, delaunay_simplices, flat_off_face, local_delaunay,
                     packed_keys)
from ._sets import unique_ints
from .errors import MeshCheckError

# |volume| below this share of the mean tetrahedron volume counts as flat (zero volume
# up to round-off: four sites on one face of the box, cocircular)
FLAT_REL = 1e-10

QHULL_OPTIONS = "Qbb Qc Q12 Qt"
"""Qhull's options for the Delaunay tetrahedra (Qt: triangulated output). Qhull sees a
slightly moved copy of the sites (:mod:`ctseg._retet`), so no four are exactly cospherical;
the exact sites, where they must be triangulated, get Qz as well."""

SLIVER_STEP = 0.1
"""Largest move of a sliver's vertex in :func:`perturb_slivers`, as a share of its
shortest edge."""


@dataclass
class TetraMesh:
    """Tetrahedra over a box, in physical coordinates.

    Attributes
    ----------
    points : (n, 3) float64 ndarray
        (x, y, z) = (i, j, k) index times spacing.
    tetrahedra : (m, 4) int64 ndarray
        Positively oriented (:func:`tetra_volumes` > 0).
    adjacency : (a, 2) int64 ndarray
        Pairs of tetrahedra sharing a face.
    shared_faces : (a, 3) int64 ndarray
        The vertices of each shared face.
    boundary_faces : (b, 3) int64 ndarray
        Faces of one tetrahedron only (on the box), oriented outward.
    boundary_owner : (b,) int64 ndarray
        The tetrahedron each boundary face belongs to.
    """

    points: np.ndarray
    tetrahedra: np.ndarray
    adjacency: np.ndarray
    shared_faces: np.ndarray
    boundary_faces: np.ndarray
    boundary_owner: np.ndarray


def tetra_volumes(points, tetrahedra):
    """Signed volumes: positive when (b - a, c - a, d - a) is right-handed.

    Example
    -------
    >>> tetra_volumes([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]]).tolist()
    [0.16666666666666666]
    """
    p = np.asarray(points, float)[np.asarray(tetrahedra, np.int64)]
    a, b, c, d = p[:, 0], p[:, 1], p[:, 2], p[:, 3]
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


# the faces of tetrahedron (0, 1, 2, 3), each opposite one vertex, ordered so that its
# normal points out of a positively oriented tetrahedron
_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


def tetra_faces(tetrahedra):
    """Every face of every tetrahedron, outward-oriented: (4 m, 3), face f of tet t at
    row 4 t + f (the face opposite vertex f)."""
    tets = np.asarray(tetrahedra, np.int64)
    return tets[:, _FACES].reshape(-1, 3)


def face_graph(tetrahedra):
    """Faces shared by two tetrahedra, and faces of one only.

    Returns
    -------
    adjacency : (a, 2) int64 ndarray
    shared_faces : (a, 3) int64 ndarray
        Oriented outward from ``adjacency[:, 0]``.
    boundary_faces : (b, 3) int64 ndarray
        Oriented outward.
    boundary_owner : (b,) int64 ndarray

    Raises
    ------
    MeshCheckError
        A face shared by more than two tetrahedra (not a conforming mesh).
    """
    faces = tetra_faces(tetrahedra)
    key = np.sort(faces, axis=1)
    packed = packed_keys(key)
    if packed is None:
        order = np.lexsort(key.T[::-1])
        sk = key[order]
        new = np.r_[True, np.any(sk[1:] != sk[:-1], axis=1)]
    else:  # the same stable order from one integer per face
        order = np.argsort(packed, kind="stable")
        sk = packed[order]
        new = np.r_[True, sk[1:] != sk[:-1]]
    group = np.cumsum(new) - 1
    counts = np.bincount(group)
    if counts.max(initial=0) > 2:
        raise MeshCheckError(f"tetrahedra: {int((counts > 2).sum())} face(s) shared by more "
                             "than two tetrahedra")
    first = np.flatnonzero(new)
    pair = counts == 2
    a, b = order[first[pair]], order[first[pair] + 1]
    single = order[first[~pair]]
    return (np.column_stack([a // 4, b // 4]), faces[a], faces[single], single // 4)


def _jitter(pts, box, size, seed):
    """Move every site by up to ``size`` along the axes on which it is free (a site on a
    box face stays on it, one on an edge on its line)."""
    rng = np.random.default_rng(seed)
    on_bound = (np.abs(pts) <= 1e-9 * np.maximum(box, 1.0)) | (np.abs(pts - box) <= 1e-9 * np.maximum(box, 1.0))
    out = pts + np.where(on_bound, 0.0, rng.uniform(-size, size, pts.shape))
    return np.clip(out, 0.0, box)


def delaunay_tetrahedra(sites, box):
    """The Delaunay tetrahedra of sites that include the box's 8 corners.

    Flat tetrahedra with their four sites on one face of the box (which Qhull may join)
    are left out: their neighbours' faces then cover that part of the box face. Flat
    tetrahedra inside the box (four coplanar sites, as near-regular site sets give) would
    open a hole if left out: the sites off the box's faces and edges are then moved by up
    to 1e-6 of the box's diagonal along their free axes (a fixed random draw, so the same
    sites give the same mesh) and triangulated again, up to three times with a tenfold
    larger move each time. The tetrahedra must then fill the box exactly (volumes
    summing to its volume) and every site must be a vertex.

    Parameters
    ----------
    sites : (n, 3) array_like
        Physical coordinates, within ``[0, box]``.
    box : (3,) array_like
        The box's extent (x, y, z); its corner at the origin.

    Returns
    -------
    TetraMesh
        Its points are the sites (as moved, if they were).

    Raises
    ------
    MeshCheckError
        The tetrahedra do not fill the box, a site is no vertex, or flat tetrahedra remain
        inside the box.

    Example
    -------
    >>> import numpy as np
    >>> corners = np.array([[x, y, z] for x in (0, 2) for y in (0, 1) for z in (0, 1)], float)
    >>> mesh = delaunay_tetrahedra(np.vstack([corners, [[1.0, 0.5, 0.5]]]), (2, 1, 1))
    >>> float(tetra_volumes(mesh.points, mesh.tetrahedra).sum())
    2.0
    """
    return _with_faces(*_delaunay(sites, box))


def _delaunay(sites, box):
    """:func:`delaunay_tetrahedra`'s (points, tetrahedra), checked, without the face graph."""
    pts = np.asarray(sites, float)
    box = np.asarray(box, float)
    size = 1e-6 * float(np.linalg.norm(box))
    for attempt in range(4):
        tets = delaunay_simplices(pts, box, QHULL_OPTIONS, FLAT_REL)
        vol = tetra_volumes(pts, tets)
        neg = vol < 0
        tets[neg] = tets[neg][:, [0, 2, 1, 3]]
        vol = np.abs(vol)
        flat, inside = flat_off_face(pts, tets, vol, box, FLAT_REL)
        if not inside.any():
            break
        if attempt == 3:
            raise MeshCheckError(f"tetrahedra: {int(inside.sum())} flat tetrahedra inside the "
                                 "box (coplanar sites) after moving the sites")
        pts = _jitter(np.asarray(sites, float), box, size * 10 ** attempt, attempt)
    _check_cover(pts, tets[~flat], vol[~flat], box)
    return pts, tets[~flat]


def _check_cover(pts, tets, vol, box):
    """Tetrahedra of volumes ``vol`` must fill the box exactly and use every site."""
    total = float(np.prod(box))
    if vol.min(initial=0.0) < 0:
        raise MeshCheckError(f"tetrahedra: {int(np.sum(vol < 0))} negatively oriented")
    if abs(vol.sum() - total) > 1e-9 * total:
        raise MeshCheckError(f"tetrahedra: they fill {vol.sum():.12g} of the box's "
                             f"{total:.12g} (a corner site missing?)")
    used = unique_ints(tets)
    if len(used) != len(pts):
        raise MeshCheckError(f"tetrahedra: {len(pts) - len(used)} site(s) are no vertex "
                             "(coincident sites)")


def _with_faces(pts, tets):
    """The TetraMesh of positively oriented tetrahedra, with its face graph."""
    adjacency, shared, bfaces, owner = face_graph(tets)
    return TetraMesh(points=pts, tetrahedra=tets, adjacency=adjacency, shared_faces=shared,
                     boundary_faces=bfaces, boundary_owner=owner)


def dihedral_angles(points, tetrahedra):
    """The six dihedral angles (degrees) of every tetrahedron, (m, 6)."""
    p = np.asarray(points, float)[np.asarray(tetrahedra, np.int64)]
    normals = []
    for f in range(4):
        a, b, c = (p[:, i] for i in _FACES[f])
        normals.append(np.cross(b - a, c - a))
    n = np.stack(normals, axis=1)
    unit = n / np.maximum(np.linalg.norm(n, axis=2), 1e-300)[:, :, None]
    out = np.empty((len(p), 6))
    for e, (f, g) in enumerate(((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))):
        out[:, e] = np.degrees(np.arccos(np.clip(-np.einsum("ij,ij->i", unit[:, f], unit[:, g]), -1.0, 1.0)))
    return out


def _shortest_edges(pts, tets, which):
    """The length of the shortest edge at each vertex ``which``: over the tetrahedra that
    hold one of them (every edge at a vertex is in one)."""
    mark = np.zeros(len(pts), bool)
    mark[which] = True
    near = tets[mark[tets].any(axis=1)]
    edges = np.concatenate([near[:, [i, j]] for i, j in
                            ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))])
    length = np.linalg.norm(pts[edges[:, 0]] - pts[edges[:, 1]], axis=1)
    shortest = np.full(len(pts), np.inf)
    np.minimum.at(shortest, edges[:, 0], length)
    np.minimum.at(shortest, edges[:, 1], length)
    return shortest[which]


def perturb_slivers(sites, box, min_dihedral_deg, rounds, seed):
    """Move the vertices of slivers a little and triangulate again, keeping the best.

    Each round, every vertex of a tetrahedron whose smallest dihedral angle is below
    ``min_dihedral_deg`` moves by a random step of up to :data:`SLIVER_STEP` of its
    shortest edge,
    along its free axes only (a site on a box face stays on it, one on an edge on its
    line, corners stay); the site set whose tetrahedra have the fewest such slivers
    (ties: the larger smallest angle) is kept. The same sites and seed give the same
    result.

    Only the tetrahedra around the moved sites change: each round re-triangulates that
    cavity alone (:func:`ctseg._retet.local_delaunay`: the tetrahedra whose circumsphere
    holds a moved site, or that have one as a vertex), and all the sites only where that
    patch fails its checks. The result is checked as :func:`delaunay_tetrahedra` checks a
    whole triangulation (exact cover of the box, every site a vertex), and triangulated
    whole where it fails.

    Parameters
    ----------
    sites : (n, 3) array_like
    box : (3,) array_like
    min_dihedral_deg : float
    rounds : int
    seed : int

    Returns
    -------
    sites : (n, 3) ndarray
    mesh : TetraMesh
        Of the sites returned.
    slivers : int
        Tetrahedra left below the angle.
    """
    box = np.asarray(box, float)
    # the face graph only of the tetrahedra kept; whole triangulations come checked
    best_pts, best_tets = _delaunay(np.asarray(sites, float), box)
    checked = True
    angle = dihedral_angles(best_pts, best_tets).min(axis=1)
    best_key = (int(np.sum(angle < min_dihedral_deg)), -float(angle.min()))
    spheres = circumspheres(best_pts, best_tets)
    rng = np.random.default_rng(seed)
    tol = 1e-9 * np.maximum(box, 1.0)
    for _ in range(rounds):
        if best_key[0] == 0:
            break
        pts = best_pts.copy()
        bad = unique_ints(best_tets[angle < min_dihedral_deg])
        shortest = _shortest_edges(pts, best_tets, bad)
        free = ~((np.abs(pts[bad]) <= tol) | (np.abs(pts[bad] - box) <= tol))
        step = rng.uniform(-SLIVER_STEP, SLIVER_STEP, (len(bad), 3)) * shortest[:, None] * free
        pts[bad] = np.clip(pts[bad] + step, 0.0, box)
        keep, added = local_delaunay(best_pts, pts, best_tets, bad, box, QHULL_OPTIONS,
                                     FLAT_REL, spheres)
        sph = None
        whole = added is None
        if not whole:
            tets = np.vstack([best_tets[keep], added])
            a = np.concatenate([angle[keep], dihedral_angles(pts, added).min(axis=1)])
            # the kept tetrahedra's vertices did not move: their spheres stay
            sph = tuple(np.concatenate([kept[keep], fresh])
                        for kept, fresh in zip(spheres, circumspheres(pts, added)))
        else:
            try:
                pts, tets = _delaunay(pts, box)
            except MeshCheckError:
                continue
            a = dihedral_angles(pts, tets).min(axis=1)
        key = (int(np.sum(a < min_dihedral_deg)), -float(a.min()))
        if key < best_key:
            best_pts, best_tets, checked, angle, best_key = pts, tets, whole, a, key
            spheres = circumspheres(pts, tets) if sph is None else sph
    if not checked:
        try:
            _check_cover(best_pts, best_tets, tetra_volumes(best_pts, best_tets), box)
        except MeshCheckError:  # a patch's round-off: the best sites triangulated whole
            best_pts, best_tets = _delaunay(best_pts, box)
            angle = dihedral_angles(best_pts, best_tets).min(axis=1)
            best_key = (int(np.sum(angle < min_dihedral_deg)),)
    best_mesh = _with_faces(best_pts, best_tets)
    return best_mesh.points, best_mesh, best_key[0]


def tetra_quality(points, tetrahedra):
    """Element quality for finite-element use: dihedral angles and radius ratios.

    Returns
    -------
    dict
        ``min_dihedral_deg``, ``p1_dihedral_deg`` (1st percentile over all dihedral
        angles), ``max_dihedral_deg``, ``min_radius_ratio``, ``mean_radius_ratio``
        (3 x inradius / circumradius: 1 for the regular tetrahedron, 0 for a flat one).

    Example
    -------
    >>> s = np.sqrt(8 / 9.0)
    >>> reg = [[0, 0, 1], [s, 0, -1 / 3], [-s / 2, np.sqrt(2 / 3), -1 / 3], [-s / 2, -np.sqrt(2 / 3), -1 / 3]]
    >>> q = tetra_quality(reg, [[0, 1, 2, 3]])
    >>> round(q["min_dihedral_deg"], 2), round(q["min_radius_ratio"], 6)
    (70.53, 1.0)
    """
    p = np.asarray(points, float)[np.asarray(tetrahedra, np.int64)]
    if len(p) == 0:
        return {"min_dihedral_deg": 0.0, "p1_dihedral_deg": 0.0, "max_dihedral_deg": 0.0,
                "min_radius_ratio": 0.0, "mean_radius_ratio": 0.0}
    # outward face normals (face f opposite vertex f), with areas as lengths
    normals = []
    for f in range(4):
        a, b, c = (p[:, i] for i in _FACES[f])
        normals.append(0.5 * np.cross(b - a, c - a))
    n = np.stack(normals, axis=1)  # (m, 4, 3)
    area = np.linalg.norm(n, axis=2)
    unit = n / np.maximum(area, 1e-300)[:, :, None]
    angles = []
    for f, g in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)):
        cos = np.clip(-np.einsum("ij,ij->i", unit[:, f], unit[:, g]), -1.0, 1.0)
        angles.append(np.degrees(np.arccos(cos)))
    dihedral = np.concatenate(angles)
    vol = np.abs(np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]),
                           p[:, 3] - p[:, 0])) / 6.0
    r_in = 3.0 * vol / np.maximum(area.sum(axis=1), 1e-300)
    # circumcentre: solve 2 (x_i - x_0) . c = |x_i|^2 - |x_0|^2
    A = 2.0 * (p[:, 1:] - p[:, :1])
    rhs = np.sum(p[:, 1:] ** 2, axis=2) - np.sum(p[:, :1] ** 2, axis=2)
    ok = np.abs(np.linalg.det(A)) > 1e-300
    centre = np.zeros((len(p), 3))
    if ok.any():
        centre[ok] = np.linalg.solve(A[ok], rhs[ok][:, :, None])[:, :, 0]
    r_out = np.where(ok, np.linalg.norm(centre - p[:, 0], axis=1), np.inf)
    ratio = 3.0 * r_in / r_out
    return {"min_dihedral_deg": float(dihedral.min()),
            "p1_dihedral_deg": float(np.percentile(dihedral, 1)),
            "max_dihedral_deg": float(dihedral.max()),
            "min_radius_ratio": float(ratio.min()), "mean_radius_ratio": float(ratio.mean())}
