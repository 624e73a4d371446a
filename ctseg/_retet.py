"""Local update of a Delaunay tetrahedralisation after a few of its sites moved (the sliver
perturbation of :func:`ctseg.tetrahedra.perturb_slivers`).

A tetrahedron of the old triangulation stays Delaunay for the moved sites when none of its
vertices moved and no moved site's new position lies in its circumsphere (its sphere was
empty of the old sites, and still is). The others form the cavity, which the Delaunay
tetrahedra of the cavity's own vertices (the moved sites among them) fill again: those of
them inside the cavity are the new triangulation's there. Borderline spheres go to the
cavity (re-triangulating a Delaunay tetrahedron gives it back), and the patch is checked:
its boundary must be the cavity's, face for face, and its volume the cavity's; where it is
not (round-off on near-cospherical sites, coplanar sites inside) the caller triangulates
everything again. Private: :func:`ctseg.tetrahedra.perturb_slivers` is the entry point.
"""
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import Delaunay, QhullError, cKDTree

from . import _threads
from ._sets import unique_ints

# the faces of tetrahedron (0, 1, 2, 3), as in ctseg.tetrahedra
_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])

_QHULL_JITTER = 1e-8
"""Qhull triangulates a copy of the sites moved by up to this share of the box's diagonal:
exactly coplanar sites on the box's faces (and near-cospherical near-regular ones) send it
into its slow facet merging, four times the time of as many sites inside; the copy's
tetrahedra are the exact sites' wherever those are not flat. At 1e-10 the CVT's
near-regular sites were still within Qhull's round-off often enough to keep it merging
(README, *Accuracy in 3D*); the move stays far below any tetrahedron's size."""

_EXACT_OPTIONS = " Qz"
"""Added to the options for the exact sites: a point at infinity, for cospherical sites
(near-regular sets, the box's cocircular face sites). The moved copy does without it: there
it only costs Qhull time, for the same tetrahedra."""

_SPHERE_MARGIN = 1e-6
"""A tetrahedron whose circumsphere a moved site misses by less than this share of its
radius joins the cavity."""


def _volumes(pts, tets):
    p = pts[tets]
    e = p[:, 1:] - p[:, :1]
    return np.einsum("ij,ij->i", np.cross(e[:, 0], e[:, 1]), e[:, 2]) / 6.0


def flat_off_face(pts, tets, vol, box, flat_rel):
    """Flat tetrahedra (|volume| at most ``flat_rel`` of the mean), and which of them do
    not lie on one face of the box."""
    flat = vol <= flat_rel * max(vol.mean(), 1e-300)
    return flat, ~_on_box(pts[tets[flat]], box)


def delaunay_simplices(pts, box, options, flat_rel):
    """Qhull's Delaunay tetrahedra of ``pts`` (indices, (m, 4)), found on a copy moved by up
    to :data:`_QHULL_JITTER` of the box's diagonal (a fixed random draw) and oriented
    positively there. Where a tetrahedron that is not flat (|volume| above ``flat_rel`` of
    the mean) has a negative volume at the exact sites, the exact sites are triangulated
    instead. Flat tetrahedra come out as Qhull gives them, for the caller to sort out.

    Raises
    ------
    scipy.spatial.QhullError
        Qhull fails on the exact sites too.
    """
    size = _QHULL_JITTER * float(np.linalg.norm(box))
    copy = pts + np.random.default_rng(0).uniform(-size, size, pts.shape)
    try:
        tets = Delaunay(copy, qhull_options=options).simplices.astype(np.int64)
    except QhullError:
        tets = None
    if tets is not None:
        neg = _volumes(copy, tets) < 0
        tets[neg] = tets[neg][:, [0, 2, 1, 3]]
        vol = _volumes(pts, tets)
        if not np.any(vol < -flat_rel * max(np.abs(vol).mean(), 1e-300)):
            return tets
    return Delaunay(pts, qhull_options=options + _EXACT_OPTIONS).simplices.astype(np.int64)


def circumspheres(pts, tets):
    """Circumcentres and radii; a flat tetrahedron gets an infinite radius."""
    p = pts[tets]
    a, b, c = (p[:, i] - p[:, 0] for i in (1, 2, 3))
    bc, ca, ab = np.cross(b, c), np.cross(c, a), np.cross(a, b)
    den = 2.0 * np.einsum("ij,ij->i", a, bc)
    num = (np.sum(a * a, axis=1)[:, None] * bc + np.sum(b * b, axis=1)[:, None] * ca
           + np.sum(c * c, axis=1)[:, None] * ab)
    with np.errstate(divide="ignore", invalid="ignore"):
        off = num / den[:, None]
        radius = np.where(den != 0, np.linalg.norm(off, axis=1), np.inf)
    return p[:, 0] + np.where(np.isfinite(off), off, 0.0), radius


def _face_keys(tets):
    """(4 m, 3) sorted vertex triples of every face, face f of tet t at row 4 t + f."""
    return np.sort(tets[:, _FACES].reshape(-1, 3), axis=1)


_KEY_BITS = 21


def packed_keys(triples):
    """Sorted vertex triples (f, 3) as one int64 each, in their lexicographic order; None
    when a vertex index needs more than 21 bits. One integer sorts several times faster
    than three columns, in the same order."""
    t = np.asarray(triples, np.int64)
    if len(t) and int(t.max()) >> _KEY_BITS:
        return None
    return (t[:, 0] << 2 * _KEY_BITS) | (t[:, 1] << _KEY_BITS) | t[:, 2]


def unique_rows(triples):
    """``np.unique(triples, axis=0, return_inverse=True)`` (as a flat inverse), by the
    packed keys where they fit."""
    key = packed_keys(triples)
    if key is None:
        rows, inverse = np.unique(triples, axis=0, return_inverse=True)
        return rows, inverse.ravel()
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    return triples[first], inverse.ravel()


def local_delaunay(old, new, tets, moved, box, options, flat_rel, spheres=None):
    """The Delaunay tetrahedra of sites ``new`` from those (``tets``) of ``old``, where
    only the sites ``moved`` differ.

    Parameters
    ----------
    old, new : (n, 3) ndarrays
    tets : (m, 4) int64 ndarray
        Positively oriented, the box-face flat ones left out (as
        :func:`ctseg.tetrahedra.delaunay_tetrahedra` gives them).
    moved : (k,) int ndarray
    box : (3,) ndarray
    options : str
        Qhull options.
    flat_rel : float
        As :data:`ctseg.tetrahedra.FLAT_REL`.
    spheres : (centres, radii), optional
        :func:`circumspheres` of ``tets`` at ``old``, if known (a caller that updates
        them with the tetrahedra saves computing them all every round).

    Returns
    -------
    keep : (m,) bool ndarray
        The old tetrahedra kept.
    added : (a, 4) int64 ndarray
        The new ones, positively oriented; ``None`` (and ``keep`` None) where the patch
        fails its checks.
    """
    moved = np.asarray(moved, np.int64)
    if not len(moved):
        return np.ones(len(tets), bool), np.zeros((0, 4), np.int64)
    centre, radius = circumspheres(old, tets) if spheres is None else spheres
    # every centre against the moved sites, on all cores (each query its own)
    dist = cKDTree(new[moved]).query(centre, workers=_threads.workers())[0]
    is_moved = np.zeros(len(new), bool)
    is_moved[moved] = True
    cavity = (dist <= radius * (1.0 + _SPHERE_MARGIN)) | is_moved[tets].any(axis=1)
    cav = tets[cavity]
    local = unique_ints(cav)
    if len(local) < 5:
        return None, None
    try:
        lt = local[delaunay_simplices(new[local], box, options, flat_rel)]
    except Exception:  # noqa: BLE001 (Qhull's errors: triangulate everything instead)
        return None, None
    vol = _volumes(new, lt)
    lt[vol < 0] = lt[vol < 0][:, [0, 2, 1, 3]]
    vol = np.abs(vol)
    flat, inside = flat_off_face(new, lt, vol, box, flat_rel)
    if inside.any():
        return None, None  # coplanar sites inside the box: the caller jitters them
    lt, vol = lt[~flat], vol[~flat]
    # the cavity's boundary: its faces found once among its tetrahedra
    ck = _face_keys(cav)
    lk = _face_keys(lt)
    faces, ids = unique_rows(np.vstack([ck, lk]))
    cid, lid = ids[:len(ck)], ids[len(ck):]
    n_ids = int(ids.max()) + 1
    bound = np.bincount(cid, minlength=n_ids) == 1
    # the patch's pieces: tetrahedra joined across faces that are not the cavity's boundary
    order = np.argsort(lid, kind="stable")
    sl = lid[order]
    pair = np.flatnonzero((sl[1:] == sl[:-1]) & ~bound[sl[:-1]])
    a, b = order[pair] // 4, order[pair + 1] // 4
    n_comp, comp = connected_components(
        coo_matrix((np.ones(len(a)), (a, b)), shape=(len(lt), len(lt))), directed=False)
    # a piece is inside when one of its centroids lies in a cavity tetrahedron
    first = np.unique(comp, return_index=True)[1]
    inside_piece = np.zeros(n_comp, bool)
    inside_piece[comp[first]] = _in_any(new[lt[first]].mean(axis=1), old[cav])
    sel = inside_piece[comp]
    added, vol_added = lt[sel], vol[sel]
    # checks: the patch's boundary inside the box is the cavity's, face for face (on the
    # box, four cocircular sites of a face may be split along the other diagonal); the
    # volumes agree
    count = np.bincount(lid[np.repeat(sel, 4)], minlength=n_ids)
    on_box = _on_box(new[faces], box)
    if np.any(count > 2) or not np.array_equal((count == 1) & ~on_box, bound & ~on_box):
        return None, None
    total = float(np.prod(box))
    if abs(vol_added.sum() - _volumes(new, cav).sum()) > 1e-9 * total:
        return None, None
    if not np.all(np.isin(local, added)):
        return None, None
    return ~cavity, added


def _on_box(tri, box):
    """Whether each triangle (f, 3, 3) lies in one face plane of the box."""
    out = np.zeros(len(tri), bool)
    for ax in range(3):
        for level in (0.0, box[ax]):
            out |= np.all(np.abs(tri[:, :, ax] - level) <= 1e-9 * max(box[ax], 1.0), axis=1)
    return out


def _in_any(points, cells):
    """Whether each point lies in (or on) one of the tetrahedra ``cells`` (c, 4, 3).

    Only the cells whose centroid lies within the largest centroid-to-corner distance of
    the point can hold it; those are tested."""
    out = np.zeros(len(points), bool)
    if not len(cells) or not len(points):
        return out
    base = cells[:, 0]
    inv = np.linalg.pinv(np.transpose(cells[:, 1:] - base[:, None], (0, 2, 1)))
    centroid = cells.mean(axis=1)
    reach = 1.001 * float(np.linalg.norm(cells - centroid[:, None], axis=2).max())
    for i, near in enumerate(cKDTree(centroid).query_ball_point(points, reach)):
        c = np.asarray(near, np.int64)
        lam = np.einsum("cij,cj->ci", inv[c], points[i] - base[c])
        out[i] = np.any((lam >= -1e-9).all(axis=1) & (lam.sum(axis=1) <= 1.0 + 1e-9))
    return out
