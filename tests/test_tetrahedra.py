"""Delaunay tetrahedra of 3D sites (SPEC 9.4): they fill the box, none is flat, faces pair
up, quality measures are right."""
import numpy as np
import pytest

from ctseg.errors import MeshCheckError
from ctseg.tetrahedra import (delaunay_tetrahedra, face_graph, tetra_faces, tetra_quality,
                              tetra_volumes)


def _corners(box):
    return np.array([[x, y, z] for x in (0, box[0]) for y in (0, box[1]) for z in (0, box[2])], float)


def _grid_sites(n, jitter, seed=0):
    """A regular (n+1)^3 grid of sites, interior ones jittered: the face sites stay a
    regular grid, so Qhull meets many cospherical and coplanar sets."""
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(*[np.arange(n + 1.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    inner = (g > 0).all(1) & (g < n).all(1)
    g[inner] += rng.uniform(-jitter, jitter, (inner.sum(), 3))
    return g


@pytest.mark.parametrize("sites,box", [
    (np.vstack([_corners((10, 8, 6)), np.random.default_rng(0).uniform(0, 1, (500, 3)) * (10, 8, 6)]), (10, 8, 6)),
    (_grid_sites(6, 0.2), (6, 6, 6)),
    (_grid_sites(5, 0.0), (5, 5, 5)),  # every site on a regular grid: the worst case
])
def test_tetrahedra_fill_the_box_and_pair_their_faces(sites, box):
    mesh = delaunay_tetrahedra(sites, box)
    vol = tetra_volumes(mesh.points, mesh.tetrahedra)
    assert vol.min() > 0
    assert abs(vol.sum() - np.prod(box)) <= 1e-9 * np.prod(box)
    # sites moved (if at all) by far less than a voxel, and faces and edges kept
    assert np.abs(mesh.points - sites).max() < 1e-3
    for ax in range(3):
        on = np.isclose(sites[:, ax], 0) | np.isclose(sites[:, ax], box[ax])
        np.testing.assert_array_equal(mesh.points[on, ax], sites[on, ax])
    # every face is shared by two tetrahedra or lies on the box, outward
    bf = mesh.boundary_faces
    p = mesh.points[bf]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area = 0.5 * np.linalg.norm(normal, axis=1)
    box = np.asarray(box, float)
    assert np.isclose(area.sum(), 2 * (box[0] * box[1] + box[1] * box[2] + box[0] * box[2]), rtol=1e-9)
    assert np.all(np.einsum("ij,ij->i", normal, p.mean(axis=1) - box / 2) > 0)
    assert len(mesh.adjacency) * 2 + len(bf) == 4 * len(mesh.tetrahedra)


def test_shared_faces_are_outward_from_the_first_tetrahedron():
    mesh = delaunay_tetrahedra(_grid_sites(4, 0.25, seed=3), (4, 4, 4))
    p = mesh.points[mesh.shared_faces]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    c0 = mesh.points[mesh.tetrahedra[mesh.adjacency[:, 0]]].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", normal, p.mean(axis=1) - c0) > 0)


def test_a_missing_corner_is_refused():
    sites = np.vstack([_corners((2, 2, 2))[1:], [[1.0, 1.0, 1.0]]])
    with pytest.raises(MeshCheckError, match="fill"):
        delaunay_tetrahedra(sites, (2, 2, 2))


def test_face_graph_refuses_a_face_of_three_tetrahedra():
    tets = np.array([[0, 1, 2, 3], [0, 1, 2, 4], [0, 1, 2, 5]])
    with pytest.raises(MeshCheckError, match="more than two"):
        face_graph(tets)
    assert tetra_faces(tets).shape == (12, 3)


def test_quality_of_a_regular_and_a_sliver_tetrahedron():
    s = np.sqrt(8 / 9.0)
    reg = [[0, 0, 1], [s, 0, -1 / 3], [-s / 2, np.sqrt(2 / 3), -1 / 3], [-s / 2, -np.sqrt(2 / 3), -1 / 3]]
    q = tetra_quality(reg, [[0, 1, 2, 3]])
    assert np.isclose(q["min_dihedral_deg"], np.degrees(np.arccos(1 / 3)))
    assert np.isclose(q["min_radius_ratio"], 1.0)
    sliver = [[0, 0, 0], [1, 0, 0], [0.5, 0.5, 0.01], [0.5, -0.5, 0.01]]
    q = tetra_quality(sliver, [[0, 1, 2, 3]])
    assert q["min_dihedral_deg"] < 3 and q["min_radius_ratio"] < 0.1


def test_sliver_perturbation_removes_slivers_and_keeps_the_box():
    from ctseg.tetrahedra import dihedral_angles, perturb_slivers

    sites = _grid_sites(6, 0.08, seed=5)  # near-regular: many slivers
    box = np.array([6.0, 6.0, 6.0])
    before = delaunay_tetrahedra(sites, box)
    n0 = int(np.sum(dihedral_angles(before.points, before.tetrahedra).min(axis=1) < 5))
    pts, mesh, left = perturb_slivers(sites, box, 5.0, 12, seed=0)
    angles = dihedral_angles(mesh.points, mesh.tetrahedra).min(axis=1)
    assert n0 > 10 and left == int(np.sum(angles < 5)) and left < n0 / 4
    assert np.isclose(tetra_volumes(mesh.points, mesh.tetrahedra).sum(), 216.0, rtol=1e-9)
    for ax in range(3):  # face, edge and corner sites stay on their planes
        on = np.isclose(sites[:, ax], 0) | np.isclose(sites[:, ax], 6)
        np.testing.assert_array_equal(pts[on, ax], sites[on, ax])
    again, _, _ = perturb_slivers(sites, box, 5.0, 12, seed=0)
    np.testing.assert_array_equal(again, pts)
    assert dihedral_angles(*[[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]]]).shape == (1, 6)


def _tet_set(tets):
    return {tuple(t) for t in np.sort(tets, axis=1).tolist()}


@pytest.mark.parametrize("n_moved,on_faces", [(5, False), (60, False), (40, True)])
def test_local_update_gives_the_delaunay_tetrahedra_of_the_moved_sites(n_moved, on_faces):
    """The cavity around moved sites, re-triangulated alone, gives the tetrahedra a whole
    triangulation gives (random sites: one Delaunay triangulation), with face sites moving
    in their planes too."""
    from ctseg._retet import local_delaunay
    from ctseg.tetrahedra import FLAT_REL, QHULL_OPTIONS

    sites, box, rng = _random_box_sites(seed=2)
    old = delaunay_tetrahedra(sites, box)
    pool = np.arange(408, 468) if on_faces else np.arange(8, 408)
    moved = np.sort(rng.choice(pool, n_moved, replace=False))
    new = sites.copy()
    free = ~(np.isclose(sites[moved], 0.0) | np.isclose(sites[moved], box))
    new[moved] = np.clip(sites[moved] + rng.uniform(-0.2, 0.2, (n_moved, 3)) * free, 0.0, box)
    keep, added = local_delaunay(old.points, new, old.tetrahedra, moved, box, QHULL_OPTIONS,
                                 FLAT_REL)
    assert added is not None and 0 < (~keep).sum() < len(keep)
    tets = np.vstack([old.tetrahedra[keep], added])
    assert np.all(tetra_volumes(new, tets) > 0)
    assert _tet_set(tets) == _tet_set(delaunay_tetrahedra(new, box).tetrahedra)


@pytest.mark.parametrize("local", [True, False])
def test_sliver_perturbation_gives_the_mesh_of_whole_triangulations(monkeypatch, local):
    """Local updates every round (or, where every local patch fails, whole triangulations):
    the same sites and tetrahedra as a whole triangulation every round (the rule before the
    local update), positively oriented, with the face graph of those tetrahedra."""
    from ctseg import tetrahedra
    from ctseg.tetrahedra import SLIVER_STEP, dihedral_angles, perturb_slivers

    if not local:
        monkeypatch.setattr(tetrahedra, "local_delaunay", lambda *a, **k: (None, None))

    sites = _grid_sites(6, 0.08, seed=5)
    box = np.array([6.0, 6.0, 6.0])
    best = delaunay_tetrahedra(sites, box)
    angle = dihedral_angles(best.points, best.tetrahedra).min(axis=1)
    key = (int(np.sum(angle < 5)), -float(angle.min()))
    rng = np.random.default_rng(0)
    tol = 1e-9 * box
    for _ in range(12):  # the rounds with a whole triangulation each
        if key[0] == 0:
            break
        pts = best.points.copy()
        bad = np.unique(best.tetrahedra[angle < 5])
        edges = np.concatenate([best.tetrahedra[:, [i, j]] for i, j in
                                ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))])
        length = np.linalg.norm(pts[edges[:, 0]] - pts[edges[:, 1]], axis=1)
        shortest = np.full(len(pts), np.inf)
        np.minimum.at(shortest, edges[:, 0], length)
        np.minimum.at(shortest, edges[:, 1], length)
        free = ~((np.abs(pts[bad]) <= tol) | (np.abs(pts[bad] - box) <= tol))
        step = rng.uniform(-SLIVER_STEP, SLIVER_STEP, (len(bad), 3)) * shortest[bad, None] * free
        pts[bad] = np.clip(pts[bad] + step, 0.0, box)
        try:
            trial = delaunay_tetrahedra(pts, box)
        except MeshCheckError:
            continue
        a = dihedral_angles(trial.points, trial.tetrahedra).min(axis=1)
        if (int(np.sum(a < 5)), -float(a.min())) < key:
            best, angle, key = trial, a, (int(np.sum(a < 5)), -float(a.min()))
    pts, mesh, left = perturb_slivers(sites, box, 5.0, 12, seed=0)
    np.testing.assert_array_equal(pts, best.points)
    assert _tet_set(mesh.tetrahedra) == _tet_set(best.tetrahedra)
    assert len(mesh.tetrahedra) == len(best.tetrahedra)
    assert tetra_volumes(mesh.points, mesh.tetrahedra).min() > 0
    assert left == key[0]
    for got, want in zip((mesh.adjacency, mesh.shared_faces, mesh.boundary_faces),
                         face_graph(mesh.tetrahedra)):
        np.testing.assert_array_equal(got, want)


def test_packed_face_keys_sort_as_the_rows_do():
    """Faces as one integer each: the lexicographic order of the rows, the same unique rows
    and inverse as numpy's row-wise unique; past 21 bits a vertex index falls back to it."""
    from ctseg._retet import packed_keys, unique_rows

    rng = np.random.default_rng(4)
    for high in (50, 2 ** 21 - 1, 2 ** 30):
        rows = np.sort(rng.integers(0, high, (3000, 3)), axis=1)
        rows = np.vstack([rows, rows[:500]])  # duplicates
        key = packed_keys(rows)
        assert (key is None) == (high > 2 ** 21)
        if key is not None:
            np.testing.assert_array_equal(np.argsort(key, kind="stable"),
                                          np.lexsort(rows.T[::-1]))
        got, inverse = unique_rows(rows)
        want, want_inverse = np.unique(rows, axis=0, return_inverse=True)
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(inverse, want_inverse.ravel())


def _random_box_sites(seed=2):
    """The corners, 400 random sites inside a box and ten on each face (in their planes,
    exactly: a face of its four corners alone is a tie, cocircular); with the generator,
    for draws that follow."""
    box = np.array([10.0, 8.0, 6.0])
    rng = np.random.default_rng(seed)
    face = rng.uniform(0, 1, (60, 3)) * box
    axis = np.arange(60) % 3
    face[np.arange(60), axis] = np.where(np.arange(60) % 2, box[axis], 0.0)
    return np.vstack([_corners(box), rng.uniform(0, 1, (400, 3)) * box, face]), box, rng


def _exact_qhull_set(sites, box):
    """The tetrahedra of Qhull on the exact sites, the flat ones left out (the rule before
    Qhull was given a moved copy)."""
    from scipy.spatial import Delaunay

    from ctseg.tetrahedra import FLAT_REL, QHULL_OPTIONS
    tets = Delaunay(sites, qhull_options=QHULL_OPTIONS).simplices
    vol = np.abs(tetra_volumes(sites, tets))
    return _tet_set(tets[vol > FLAT_REL * vol.mean()])


def test_qhull_on_a_moved_copy_gives_the_tetrahedra_of_the_exact_sites():
    """Qhull runs on a copy of the sites moved by 1e-10 of the box (coplanar face sites
    make it slow): the tetrahedra are those of the exact sites, with exact points."""
    sites, box, _ = _random_box_sites()
    mesh = delaunay_tetrahedra(sites, box)
    np.testing.assert_array_equal(mesh.points, sites)
    assert _tet_set(mesh.tetrahedra) == _exact_qhull_set(sites, box)


def test_a_copy_moved_too_far_falls_back_to_the_exact_sites(monkeypatch):
    """Where the moved copy's tetrahedra are inverted at the exact sites (a move far beyond
    round-off), the exact sites are triangulated: still their Delaunay tetrahedra."""
    import ctseg._retet as retet
    from ctseg.tetrahedra import FLAT_REL, QHULL_OPTIONS
    sites, box, _ = _random_box_sites(seed=3)
    monkeypatch.setattr(retet, "_QHULL_JITTER", 0.02)
    tets = retet.delaunay_simplices(sites, box, QHULL_OPTIONS, FLAT_REL)
    vol = np.abs(tetra_volumes(sites, tets))
    assert _tet_set(tets[vol > FLAT_REL * vol.mean()]) == _exact_qhull_set(sites, box)
    # the moved copy alone would have given other tetrahedra (the check above can fail)
    size = 0.02 * np.linalg.norm(box)
    from scipy.spatial import Delaunay
    copy = sites + np.random.default_rng(0).uniform(-size, size, sites.shape)
    assert _tet_set(Delaunay(copy, qhull_options=QHULL_OPTIONS).simplices) != _exact_qhull_set(sites, box)


def test_point_in_tetrahedra_against_every_tetrahedron():
    """The cavity test of the local update (candidate cells near each point) against the
    test over every cell."""
    from scipy.spatial import Delaunay

    from ctseg._retet import _in_any
    rng = np.random.default_rng(4)
    pts = rng.uniform(0, 5, (60, 3))
    cells = pts[Delaunay(pts).simplices]
    cells = cells[rng.random(len(cells)) < 0.5]  # a cavity with holes
    queries = np.vstack([rng.uniform(-1, 6, (300, 3)), cells.mean(axis=1)[:20], cells[:20, 0]])
    base = cells[:, 0]
    inv = np.linalg.inv(np.transpose(cells[:, 1:] - base[:, None], (0, 2, 1)))
    lam = np.einsum("cij,qcj->qci", inv, queries[:, None] - base[None])
    brute = ((lam >= -1e-9).all(axis=2) & (lam.sum(axis=2) <= 1 + 1e-9)).any(axis=1)
    got = _in_any(queries, cells)
    assert 0 < got.sum() < len(got)
    np.testing.assert_array_equal(got, brute)
