"""Interfaces and closed per-material surfaces of a tetrahedral labelling (SPEC 9.7)."""
import numpy as np
import pytest

from ctseg.meshcheck import mesh_check_report
from ctseg.surfaces import (material_interfaces, material_surface, pinched_edges,
                            repair_pinched_edges)
from ctseg.tetrahedra import TetraMesh, delaunay_tetrahedra, face_graph, tetra_volumes

# the six tetrahedra of a unit cube along its main diagonal (Freudenthal / Kuhn)
_KUHN = [(0, 1, 3, 7), (0, 1, 5, 7), (0, 2, 3, 7), (0, 2, 6, 7), (0, 4, 5, 7), (0, 4, 6, 7)]


def cube_mesh(n):
    """n^3 unit cubes, six tetrahedra each: a conforming mesh whose cubes can be labelled
    to touch at a vertex or along an edge only."""
    idx = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)  # [x, y, z]
    pts = np.stack(np.meshgrid(*[np.arange(n + 1.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    tets, cube = [], []
    for x in range(n):
        for y in range(n):
            for z in range(n):
                corner = [idx[x + dx, y + dy, z + dz] for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)]
                for t in _KUHN:
                    tets.append([corner[i] for i in t])
                    cube.append((x, y, z))
    tets = np.array(tets, np.int64)
    neg = tetra_volumes(pts, tets) < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    adjacency, shared, bfaces, owner = face_graph(tets)
    mesh = TetraMesh(points=pts, tetrahedra=tets, adjacency=adjacency, shared_faces=shared,
                     boundary_faces=bfaces, boundary_owner=owner)
    return mesh, np.array(cube)


def assert_closed_manifolds(mesh, material):
    vol = tetra_volumes(mesh.points, mesh.tetrahedra)
    total = 0.0
    for k in np.unique(material):
        s = material_surface(mesh, material, k)
        report = mesh_check_report(s.points, s.triangles)
        assert report["ok"], (k, report)
        edges = np.sort(np.concatenate([s.triangles[:, [0, 1]], s.triangles[:, [1, 2]],
                                        s.triangles[:, [2, 0]]]), axis=1)
        assert set(np.unique(edges, axis=0, return_counts=True)[1]) == {2}  # closed
        element = vol[material == k].sum()
        assert abs(s.enclosed_volume - element) <= 1e-9 * element  # outward and closed
        assert abs(s.element_volume - element) <= 1e-12 * element
        total += s.enclosed_volume
    assert np.isclose(total, vol.sum(), rtol=1e-12)


def test_pieces_touching_at_a_vertex_get_a_vertex_each():
    mesh, cube = cube_mesh(2)
    mat = (np.all(cube == 0, axis=1) | np.all(cube == 1, axis=1)).astype(int)  # diagonal cubes
    assert all(len(pinched_edges(mesh, mat, k)) == 0 for k in (0, 1))
    s = material_surface(mesh, mat, 1)
    centre = int(np.flatnonzero(np.all(mesh.points == 1.0, axis=1))[0])
    assert np.sum(s.source_vertex == centre) == 2  # one copy per cube
    assert len(s.triangles) == 2 * 12
    assert_closed_manifolds(mesh, mat)


def test_pieces_touching_along_an_edge_are_relabelled():
    mesh, cube = cube_mesh(2)
    mat = (((cube[:, 0] == 0) & (cube[:, 1] == 0)) | ((cube[:, 0] == 1) & (cube[:, 1] == 1))).astype(int)
    assert len(pinched_edges(mesh, mat, 1)) > 0
    with pytest.raises(Exception, match="other than two"):
        material_surface(mesh, mat, 1)
    fixed, changed = repair_pinched_edges(mesh, mat, tetra_volumes(mesh.points, mesh.tetrahedra))
    assert 0 < changed < 12  # a few tetrahedra, not whole cubes
    assert_closed_manifolds(mesh, fixed)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_labellings_become_closed_manifolds(seed):
    rng = np.random.default_rng(seed)
    box = np.array([6.0, 5.0, 4.0])
    corners = np.array([[x, y, z] for x in (0, box[0]) for y in (0, box[1]) for z in (0, box[2])])
    sites = np.vstack([corners, rng.uniform(0, 1, (700, 3)) * box])
    mesh = delaunay_tetrahedra(sites, box)
    c = mesh.points[mesh.tetrahedra].mean(axis=1)
    mat = (np.linalg.norm(c - box / 2, axis=1) < 1.6).astype(int)
    mat[c[:, 2] < 1.0] = 2
    mat[rng.random(len(mat)) < 0.08] = 3  # speckle: many pinches of every kind
    fixed, _ = repair_pinched_edges(mesh, mat, tetra_volumes(mesh.points, mesh.tetrahedra))
    assert_closed_manifolds(mesh, fixed)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_last_resort_raises_labels_and_ends_manifold(seed, monkeypatch):
    """With the edge rule's passes spent (none here), each pinched edge's star takes its
    highest material: labels only go up, and every surface ends closed and manifold."""
    import ctseg.surfaces as surfaces
    monkeypatch.setattr(surfaces, "MAX_RELABEL_ROUNDS", 0)
    rng = np.random.default_rng(seed)
    box = np.array([6.0, 5.0, 4.0])
    corners = np.array([[x, y, z] for x in (0, box[0]) for y in (0, box[1]) for z in (0, box[2])])
    mesh = delaunay_tetrahedra(np.vstack([corners, rng.uniform(0, 1, (700, 3)) * box]), box)
    mat = rng.integers(0, 3, len(mesh.tetrahedra))
    mat[rng.random(len(mat)) < 0.6] = 0  # sparse speckle of 1 and 2: pinches everywhere
    assert sum(len(pinched_edges(mesh, mat, k)) for k in range(3)) > 0
    fixed, changed = surfaces.repair_pinched_edges(mesh, mat, tetra_volumes(mesh.points, mesh.tetrahedra))
    assert changed > 0 and np.all(fixed >= mat)
    assert_closed_manifolds(mesh, fixed)


def test_interfaces_are_the_surfaces_shared_faces():
    mesh, cube = cube_mesh(3)
    mat = np.where(cube[:, 0] < 1, 0, np.where(cube[:, 2] < 2, 1, 2))
    faces, a, b = material_interfaces(mesh, mat)
    assert np.all(a < b) and len(faces) > 0
    # each interface triangle's normal points from a into b
    p = mesh.points[faces]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    cent = mesh.points[mesh.tetrahedra].mean(axis=1)
    for f, (ma, mb) in enumerate(zip(a, b)):
        near = np.argsort(np.linalg.norm(cent - p[f].mean(axis=0), axis=1))[:2]
        side = {mat[t]: cent[t] for t in near}
        assert set(side) == {ma, mb}
        assert np.dot(normal[f], side[mb] - side[ma]) > 0
    # and every interface triangle is on both materials' surfaces
    for k in (0, 1, 2):
        s = material_surface(mesh, mat, k)
        on = {frozenset(t) for t in s.source_vertex[s.triangles].tolist()}
        mine = [frozenset(f) for f, x, y in zip(faces.tolist(), a, b) if k in (x, y)]
        assert all(f in on for f in mine)
