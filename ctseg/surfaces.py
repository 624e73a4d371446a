"""3D stage 7 (SPEC 9.7): the interfaces between materials and each material's closed
surface, made manifold where pieces of one material touch at a vertex or an edge."""
from dataclasses import dataclass

import numpy as np

from .errors import MeshCheckError
from .graph import connected_pieces, neighbour_lists
from .tetrahedra import tetra_volumes

MAX_RELABEL_ROUNDS = 50
"""Rounds of the edge rule of :func:`repair_pinched_edges` before its last resort."""


@dataclass
class MaterialSurface:
    """The closed surface of one material: outward-oriented triangles over its own
    vertices (a mesh vertex where pieces of the material touch appears once per piece)."""

    material: int
    points: np.ndarray
    triangles: np.ndarray
    source_vertex: np.ndarray  # mesh vertex of each surface vertex
    enclosed_volume: float
    element_volume: float


def material_interfaces(mesh, material):
    """Faces between tetrahedra of different materials.

    Returns
    -------
    faces : (f, 3) int64 ndarray
        Oriented from ``material_a`` to ``material_b`` (the normal points into b).
    material_a, material_b : (f,) int64 ndarrays
        ``material_a < material_b``.

    Example
    -------
    >>> from ctseg.tetrahedra import delaunay_tetrahedra
    >>> c = np.array([[x, y, z] for x in (0, 2) for y in (0, 1) for z in (0, 1)], float)
    >>> mesh = delaunay_tetrahedra(np.vstack([c, [[1.0, 0.5, 0.5]]]), (2, 1, 1))
    >>> mat = (mesh.points[mesh.tetrahedra].mean(axis=1)[:, 0] > 1).astype(int)
    >>> faces, a, b = material_interfaces(mesh, mat)
    >>> bool(np.all(a < b))
    True
    """
    mat = np.asarray(material, np.int64)
    t0, t1 = mesh.adjacency[:, 0], mesh.adjacency[:, 1]
    cut = mat[t0] != mat[t1]
    faces = mesh.shared_faces[cut].copy()  # outward from t0
    m0, m1 = mat[t0[cut]], mat[t1[cut]]
    flip = m0 > m1
    faces[flip] = faces[flip][:, ::-1]
    return faces, np.minimum(m0, m1), np.maximum(m0, m1)


def _surface_faces(mesh, mat, k):
    """Outward triangles of material k's solid and the tetrahedron each belongs to."""
    t0, t1 = mesh.adjacency[:, 0], mesh.adjacency[:, 1]
    out0 = (mat[t0] == k) & (mat[t1] != k)
    out1 = (mat[t1] == k) & (mat[t0] != k)
    own_b = mat[mesh.boundary_owner] == k
    faces = np.concatenate([mesh.shared_faces[out0], mesh.shared_faces[out1][:, ::-1],
                            mesh.boundary_faces[own_b]])
    owner = np.concatenate([t0[out0], t1[out1], mesh.boundary_owner[own_b]])
    return faces, owner


def _edges_of(triangles):
    """Undirected edges of every triangle corner pair: (3 f, 2) sorted vertex pairs, the
    triangle of each, and the corners (0-2) at its two ends."""
    tri = np.asarray(triangles, np.int64)
    j0 = np.repeat([[0, 1, 2]], len(tri), axis=0).T.ravel()
    j1 = (j0 + 1) % 3
    t = np.tile(np.arange(len(tri)), 3)
    ends = np.column_stack([tri[t, j0], tri[t, j1]])
    return ends, t, j0, j1


def _edge_counts(triangles):
    ends, _, _, _ = _edges_of(triangles)
    return np.unique(np.sort(ends, axis=1), axis=0, return_counts=True)


def _split_fans(triangles, n_points):
    """One vertex copy per fan: the triangles around a vertex joined through the edges
    they share at it. A vertex where two pieces touch, or where the surface meets itself,
    so becomes a manifold vertex per piece. Every edge must have exactly two triangles.

    Returns
    -------
    triangles : (f, 3) int64 ndarray, over the copies
    source : (c,) int64 ndarray, the input vertex of each copy
    """
    tri = np.asarray(triangles, np.int64)
    ends, t, j0, j1 = _edges_of(tri)
    key = np.sort(ends, axis=1)
    order = np.lexsort(key.T[::-1])
    first, second = order[0::2], order[1::2]
    # corner (t, j) is node 3 t + j; the two triangles of an edge share both its ends
    a0, a1 = 3 * t[first] + j0[first], 3 * t[first] + j1[first]
    # the other triangle runs the edge the other way: its j1 end is our j0 end
    b0, b1 = 3 * t[second] + j1[second], 3 * t[second] + j0[second]
    _, piece = connected_pieces(np.concatenate([np.column_stack([a0, b0]),
                                                np.column_stack([a1, b1])]), 3 * len(tri))
    used, copy = np.unique(piece, return_inverse=True)
    source = np.empty(len(used), np.int64)
    source[copy] = tri.ravel()
    return copy.reshape(-1, 3), source


def material_surface(mesh, material, k):
    """The closed, outward-oriented surface of material ``k``'s tetrahedra.

    Its triangles are the material's interface faces and its faces on the box. Where
    pieces of the material, or pieces of what surrounds it, touch at a single vertex, the
    vertex gets one copy per fan of triangles (:func:`_split_fans`), so the surface is a
    manifold there; pieces touching along an edge must be resolved first
    (:func:`repair_pinched_edges`).

    Returns
    -------
    MaterialSurface

    Raises
    ------
    MeshCheckError
        An edge of the surface with other than two triangles.
    """
    mat = np.asarray(material, np.int64)
    faces, _ = _surface_faces(mesh, mat, k)
    _, counts = _edge_counts(faces)
    if np.any(counts != 2):
        raise MeshCheckError(f"material {k}: {int(np.sum(counts != 2))} surface edge(s) "
                             "with other than two triangles (pinched edges not repaired)")
    tris, source = _split_fans(faces, len(mesh.points))
    pts = mesh.points[source]
    p = pts[tris]
    enclosed = float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0)
    inside = float(tetra_volumes(mesh.points, mesh.tetrahedra[mat == k]).sum())
    return MaterialSurface(material=int(k), points=pts, triangles=tris, source_vertex=source,
                           enclosed_volume=enclosed, element_volume=inside)


def pinched_edges(mesh, material, k):
    """Mesh edges (sorted vertex pairs) with more than two triangles of material ``k``'s
    surface: two pieces of the material, or of its surroundings, touch along the edge."""
    faces, _ = _surface_faces(mesh, np.asarray(material, np.int64), k)
    uniq, counts = _edge_counts(faces)
    return uniq[counts != 2]


class _EdgeStars:
    """The tetrahedra around each mesh edge, the faces between them and the box faces
    holding the edge (all fixed by the mesh, cached per edge), for local recounts of the
    surface triangles at an edge as materials change."""

    def __init__(self, mesh):
        tets = mesh.tetrahedra
        order = np.argsort(tets.ravel(), kind="stable")
        self.start = np.searchsorted(tets.ravel()[order], np.arange(len(mesh.points) + 1))
        self.owner = order // 4
        self.tets = tets
        self.boundary = {}
        for f, t in zip(mesh.boundary_faces, mesh.boundary_owner):
            self.boundary.setdefault(int(t), []).append(frozenset(f.tolist()))
        self.cache = {}

    def around(self, a, b):
        return self.star(a, b)[0]

    def star(self, a, b):
        key = (a, b) if a < b else (b, a)
        hit = self.cache.get(key)
        if hit is None:
            ta = self.owner[self.start[a]:self.start[a + 1]]
            tb = self.owner[self.start[b]:self.start[b + 1]]
            around = np.intersect1d(ta, tb)
            verts = [set(self.tets[t].tolist()) for t in around]
            pairs = [(int(around[i]), int(around[j])) for i in range(len(around))
                     for j in range(i + 1, len(around)) if len(verts[i] & verts[j]) == 3]
            on_box = [int(t) for t in around for f in self.boundary.get(int(t), ())
                      if a in f and b in f]
            hit = self.cache[key] = (around, pairs, on_box)
        return hit

    def triangle_counts(self, a, b, mat):
        """{material: surface triangles of that material holding edge (a, b)}."""
        _, pairs, on_box = self.star(a, b)
        counts = {}
        for s, t in pairs:
            ms, mt = mat[s], mat[t]
            if ms != mt:
                counts[ms] = counts.get(ms, 0) + 1
                counts[mt] = counts.get(mt, 0) + 1
        for t in on_box:
            counts[mat[t]] = counts.get(mat[t], 0) + 1
        return counts

    def pinched(self, a, b, mat):
        return any(c > 2 for c in self.triangle_counts(a, b, mat).values())


_TET_EDGES = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))


def repair_pinched_edges(mesh, material, volume):
    """Relabel a few tetrahedra so that no material's surface has an edge with more than
    two triangles (two pieces of a material, or of its surroundings, touching along an
    edge: the one configuration a vertex copy per fan cannot make manifold).

    A tetrahedron's material decides the surfaces at its own six edges only, so each move
    is judged exactly by recounting those: for a pinched edge, every tetrahedron around it
    is tried with each material of its face neighbours, and the move that removes the most
    pinched edges among its six (ties: the smallest tetrahedron) is made; if none removes
    any, all tetrahedra around the edge take the material holding most of their volume.
    Repeated until no pinched edge is left. Those moves can cycle; after
    :data:`MAX_RELABEL_ROUNDS` passes, all tetrahedra around a pinched edge take the
    highest material number among them. Each such move raises the sum of the material
    numbers (a pinched edge has two materials around it), so the repair always ends.

    Parameters
    ----------
    mesh : TetraMesh
    material : (m,) int array_like
    volume : (m,) array_like
        Tetrahedron volumes.

    Returns
    -------
    material : (m,) int64 ndarray
        A changed copy.
    relabelled : int
        How many tetrahedra changed material.
    """
    mat = np.array(material, np.int64)
    vol = np.asarray(volume, float)
    before = mat.copy()
    stars = _EdgeStars(mesh)
    tets = mesh.tetrahedra
    nb_start, nb = neighbour_lists(mesh.adjacency, len(mat))

    def edges_of(t):
        return [tuple(sorted((int(tets[t, i]), int(tets[t, j])))) for i, j in _TET_EDGES]

    def n_pinched(edges):
        return sum(stars.pinched(u, v, mat) for u, v in edges)

    def edge_rule(around):
        """The move for one pinched edge; returns the tetrahedra it relabelled."""
        best = None
        for t in around:
            edges = edges_of(t)
            old, was = mat[t], n_pinched(edges)
            for m in set(mat[nb[nb_start[t]:nb_start[t + 1]]].tolist()) - {old}:
                mat[t] = m
                score = (n_pinched(edges) - was, vol[t], int(t), m)
                mat[t] = old
                best = score if best is None or score < best else best
        if best is not None and best[0] < 0:
            mat[best[2]] = best[3]
            return [best[2]]
        # no single tetrahedron helps: the whole star of the edge takes the material
        # holding most of its volume
        mat[around] = int(np.argmax(np.bincount(mat[around], vol[around])))
        return around

    todo = sorted({tuple(e) for k in np.unique(mat) for e in pinched_edges(mesh, mat, k)})
    passes = 0
    while todo:
        touched = set()
        for a, b in todo:
            if not stars.pinched(a, b, mat):
                continue
            around = stars.around(a, b)
            if passes < MAX_RELABEL_ROUNDS:
                changed = edge_rule(around)
            else:  # the last resort: raises sum(mat), so the loop ends
                mat[around] = mat[around].max()
                changed = around
            for t in changed:
                touched.update(edges_of(t))
        todo = sorted(e for e in touched | set(todo) if stars.pinched(e[0], e[1], mat))
        passes += 1
    return mat, int(np.sum(mat != before))
