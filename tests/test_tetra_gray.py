"""SPEC 9.5: exact volume-weighted tetrahedron grays, their transpose and the overlaps,
against independent references (convex hulls of the clipped vertices, point sampling)."""
import itertools

import numpy as np
import pytest
from scipy.spatial import ConvexHull, Delaunay
from scipy.spatial import QhullError

from ctseg.errors import InputError, ParameterError
from ctseg.tetra_gray import tetra_gray, voxel_mean_of_tetrahedra, voxel_overlaps
from ctseg.tetrahedra import tetra_volumes
from oracles import box_share


def random_mesh(shape, n, seed, spacing=(1.0, 1.0, 1.0)):
    """Delaunay tetrahedra of n random points plus the 8 box corners, in physical units."""
    rng = np.random.default_rng(seed)
    top = np.array([shape[2] - 1, shape[1] - 1, shape[0] - 1], float) * spacing
    corners = np.array(list(itertools.product((0, 1), repeat=3)), float) * top
    pts = np.vstack([corners, rng.uniform(0, 1, (n, 3)) * top])
    tets = Delaunay(pts).simplices
    vol = tetra_volumes(pts, tets)
    return pts, tets[np.abs(vol) > 1e-12 * np.abs(vol).mean()]


def kuhn_mesh(shape, step):
    """Each cube of a grid of the given step split into 6 tetrahedra (Kuhn): with step 1/2
    every vertex lies on a voxel plane or a voxel centre, and every face on a plane."""
    axes = [np.arange(0, n - 1 + 1e-9, step) for n in shape[::-1]]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    pts = grid.reshape(-1, 3)
    dims = grid.shape[:3]
    tets = []
    for a, b, c in itertools.product(*(range(d - 1) for d in dims)):
        for perm in itertools.permutations(range(3)):
            cur = np.array([a, b, c])
            path = [np.ravel_multi_index(cur, dims)]
            for ax in perm:
                cur[ax] += 1
                path.append(np.ravel_multi_index(cur, dims))
            tets.append(path)
    return pts, np.array(tets)


def hull_overlap(tet, lo, hi):
    """Exact volume of tetrahedron ∩ box, as the convex hull of the vertices of the
    intersection (independent of the kernel's plane sweep)."""
    a = tet[0]
    T = (tet[1:] - a).T
    cand = [tet[(tet >= lo - 1e-12).all(1) & (tet <= hi + 1e-12).all(1)]]
    box = np.array(list(itertools.product(*zip(lo, hi))), float)
    lam = np.linalg.solve(T, (box - a).T).T
    cand.append(box[(lam >= -1e-12).all(1) & (lam.sum(1) <= 1 + 1e-12)])
    for i, j in itertools.combinations(range(4), 2):  # tet edges x box faces
        p, q = tet[i], tet[j]
        for ax in range(3):
            if p[ax] == q[ax]:
                continue
            for level in (lo[ax], hi[ax]):
                s = (level - p[ax]) / (q[ax] - p[ax])
                x = p + s * (q - p)
                if 0 <= s <= 1 and np.all(x >= lo - 1e-12) and np.all(x <= hi + 1e-12):
                    cand.append(x[None])
    for f in itertools.combinations(range(4), 3):  # box edges x tet faces
        u, v, w = tet[list(f)]
        nrm = np.cross(v - u, w - u)
        for ax in range(3):
            if nrm[ax] == 0:
                continue
            for p in box[box[:, ax] == lo[ax]]:
                x = p.copy()
                x[ax] = p[ax] + (nrm @ (u - p)) / nrm[ax]
                if not lo[ax] <= x[ax] <= hi[ax]:
                    continue
                lam = np.linalg.solve(T, x - a)
                if np.all(lam >= -1e-12) and lam.sum() <= 1 + 1e-12:
                    cand.append(x[None])
    pts = np.unique(np.round(np.vstack(cand), 13), axis=0)
    if len(pts) < 4:
        return 0.0
    try:
        return ConvexHull(pts).volume
    except QhullError:  # flat: no volume
        return 0.0


def cell_bounds(flat, shape):
    k, j, i = np.unravel_index(flat, shape)
    c = np.array([i, j, k], float)
    top = np.array([shape[2] - 1, shape[1] - 1, shape[0] - 1], float)
    return np.maximum(c - 0.5, 0.0), np.minimum(c + 0.5, top)


@pytest.fixture(scope="module")
def mesh():
    shape = (6, 7, 9)
    pts, tets = random_mesh(shape, 60, seed=1)
    return shape, pts, tets


def test_volume_times_gray_is_the_image_integral(mesh):
    shape, pts, tets = mesh
    V = np.random.default_rng(2).uniform(-50, 300, shape)
    g = tetra_gray(V, pts, tets)
    integral = np.sum(V * box_share(shape))
    assert np.isclose(np.sum(np.abs(tetra_volumes(pts, tets)) * g), integral, rtol=1e-9)


def test_anisotropic_spacing_gives_the_same_grays_and_integral():
    shape, spacing = (7, 6, 5), (0.1, 0.1, 0.3)
    pts, tets = random_mesh(shape, 60, seed=3, spacing=spacing)
    V = np.random.default_rng(4).uniform(0, 100, shape)
    g = tetra_gray(V, pts, tets, spacing=spacing)
    integral = np.sum(V * box_share(shape)) * np.prod(spacing)
    assert np.isclose(np.sum(np.abs(tetra_volumes(pts, tets)) * g), integral, rtol=1e-9)
    np.testing.assert_allclose(g, tetra_gray(V, pts / spacing, tets), rtol=1e-12)


def test_overlaps_sum_to_each_tetrahedron_and_each_voxel_share(mesh):
    shape, pts, tets = mesh
    t, v, a = voxel_overlaps(pts, tets, shape)
    assert np.all(a > 0) and len(np.unique(t * np.prod(shape) + v)) == len(t)
    np.testing.assert_allclose(np.bincount(t, a, len(tets)), np.abs(tetra_volumes(pts, tets)),
                               rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(np.bincount(v, a, np.prod(shape)).reshape(shape),
                               box_share(shape), rtol=0, atol=1e-12)


def test_overlaps_match_the_convex_hull_reference(mesh):
    shape, pts, tets = mesh
    t, v, a = voxel_overlaps(pts, tets, shape)
    got = {(ti, vi): ai for ti, vi, ai in zip(t.tolist(), v.tolist(), a)}
    for ti in range(0, len(tets), max(1, len(tets) // 12)):
        tet = pts[tets[ti]]
        lo = np.floor(tet.min(0) + 0.5)
        hi = np.ceil(tet.max(0) - 0.5)
        for i, j, k in itertools.product(*(range(int(p), int(q) + 1) for p, q in zip(lo, hi))):
            flat = np.ravel_multi_index((k, j, i), shape)
            ref = hull_overlap(tet, *cell_bounds(flat, shape))
            assert abs(got.get((ti, flat), 0.0) - ref) < 1e-9, (ti, (k, j, i))


def test_grays_match_point_sampling_of_the_voxels(mesh):
    """Slow reference: 16^3 jittered samples per voxel (one uniform in each sub-cube),
    barycentric point-in-tetrahedron test. Unbiased; only the sub-cubes the tetrahedron's
    surface cuts vary, each by at most its volume c, so sd <= c sqrt(n_cut / 4), n_cut
    bounded by the samples within a half-diagonal of a face plane. Checked to 5 sd."""
    shape, pts, tets = mesh
    V = np.random.default_rng(5).uniform(0, 10, shape)
    g = tetra_gray(V, pts, tets)
    rng = np.random.default_rng(6)
    s = 16
    grid = np.stack(np.meshgrid(*[np.arange(s)] * 3, indexing="ij"), -1).reshape(-1, 3)
    t_all, v_all, a_all = voxel_overlaps(pts, tets, shape)
    for ti in (0, len(tets) // 3, 2 * len(tets) // 3):
        tet = pts[tets[ti]]
        T = (tet[1:] - tet[0]).T
        # inward unit normals and offsets of the faces: d_f(x) = n_f . x - o_f >= 0 inside
        normals, offsets = [], []
        for f in range(4):
            u, v, w = np.delete(tet, f, axis=0)
            n = np.cross(v - u, w - u)
            n /= np.linalg.norm(n) * np.sign(n @ (tet[f] - u))
            normals.append(n)
            offsets.append(n @ u)
        normals, offsets = np.array(normals), np.array(offsets)
        lo, hi = np.floor(tet.min(0) + 0.5), np.ceil(tet.max(0) - 0.5)
        exact = dict(zip(v_all[t_all == ti].tolist(), a_all[t_all == ti]))
        sum_w = sum_wv = var_w = var_wv = 0.0
        for i, j, k in itertools.product(*(range(int(p), int(q) + 1) for p, q in zip(lo, hi))):
            flat = int(np.ravel_multi_index((k, j, i), shape))
            c0, c1 = cell_bounds(flat, shape)
            h = (c1 - c0) / s
            x = c0 + (grid + rng.uniform(0, 1, grid.shape)) * h
            lam = np.linalg.solve(T, (x - tet[0]).T).T
            inside = (lam >= 0).all(1) & (lam.sum(1) <= 1)
            cube = np.prod(h)
            centres = c0 + (grid + 0.5) * h
            near = (centres @ normals.T - offsets).min(1)
            n_cut = np.count_nonzero(np.abs(near) <= 0.5 * np.linalg.norm(h))
            sampled = inside.sum() * cube
            sd = cube * np.sqrt(n_cut / 4)
            assert abs(exact.get(flat, 0.0) - sampled) <= 5 * sd + 1e-12, (ti, flat)
            sum_w += sampled
            sum_wv += sampled * V.ravel()[flat]
            var_w += sd ** 2
            var_wv += (sd * V.ravel()[flat]) ** 2
        vol = abs(tetra_volumes(pts, tets[ti:ti + 1])[0])
        assert abs(sum_w - vol) <= 5 * np.sqrt(var_w)
        assert abs(sum_wv - g[ti] * vol) <= 5 * np.sqrt(var_wv)


def test_constant_volume_gives_the_constant(mesh):
    shape, pts, tets = mesh
    np.testing.assert_allclose(tetra_gray(np.full(shape, 7.25), pts, tets), 7.25,
                               rtol=1e-14)


def test_linear_volume_matches_the_piecewise_constant_reference(mesh):
    shape, pts, tets = mesh
    k, j, i = np.indices(shape)
    V = 3.0 + 2.0 * i - 0.5 * j + 1.5 * k
    g = tetra_gray(V, pts, tets)
    for ti in range(0, len(tets), max(1, len(tets) // 6)):
        tet = pts[tets[ti]]
        lo, hi = np.floor(tet.min(0) + 0.5), np.ceil(tet.max(0) - 0.5)
        num = den = 0.0
        for a, b, c in itertools.product(*(range(int(p), int(q) + 1) for p, q in zip(lo, hi))):
            w = hull_overlap(tet, *cell_bounds(np.ravel_multi_index((c, b, a), shape), shape))
            num += w * V[c, b, a]
            den += w
        assert np.isclose(g[ti], num / den, rtol=1e-9)


def test_faces_on_voxel_planes_leave_no_slivers():
    """Vertices on the planes i + 1/2 and at voxel centres, faces on the planes: each
    tetrahedron lies in one voxel and gets exactly one overlap."""
    shape = (3, 4, 5)
    pts, tets = kuhn_mesh(shape, 0.5)
    t, v, a = voxel_overlaps(pts, tets, shape)
    assert len(t) == len(tets) and np.array_equal(t, np.arange(len(tets)))
    np.testing.assert_allclose(a, 1 / 48, rtol=1e-12)
    np.testing.assert_allclose(np.bincount(v, a, np.prod(shape)).reshape(shape),
                               box_share(shape), atol=1e-12)
    V = np.random.default_rng(6).uniform(0, 1, shape)
    np.testing.assert_allclose(tetra_gray(V, pts, tets), V.ravel()[v], rtol=1e-13)


def test_coarse_kuhn_mesh_with_vertices_on_planes_is_shared_out_exactly():
    shape = (4, 7, 7)  # grid 0, 1.5, 3, 4.5, 6: on the planes 1.5, 4.5, centres 3, 6
    pts, tets = kuhn_mesh(shape, 1.5)
    t, v, a = voxel_overlaps(pts, tets, shape)
    assert np.all(a > 1e-12)
    np.testing.assert_allclose(np.bincount(v, a, np.prod(shape)).reshape(shape),
                               box_share(shape), atol=1e-12)
    np.testing.assert_allclose(np.bincount(t, a, len(tets)), np.abs(tetra_volumes(pts, tets)),
                               rtol=1e-12)
    for ti in (0, 7, len(tets) - 1):
        tet = pts[tets[ti]]
        for flat, ai in zip(v[t == ti], a[t == ti]):
            assert abs(ai - hull_overlap(tet, *cell_bounds(flat, shape))) < 1e-9


def test_faces_edges_and_vertices_on_a_plane_are_split_exactly():
    """A face, an edge or a vertex on the plane z = 3/2 (other coordinates not binary
    fractions, so a flat piece would not come out exactly 0), the other vertices on one
    side (nothing may land across the plane) or on both (zero-length edges in the cut)."""
    rng = np.random.default_rng(10)
    shape = (4, 5, 5)
    V = rng.uniform(0, 1, shape)
    for n_on, side in itertools.product((3, 2, 1), (-1, 1, 0)):
        if n_on == 3 and side == 0:
            continue
        for _ in range(15):
            tet = rng.uniform(0.3, 3.7, (4, 3))
            tet[:n_on, 2] = 1.5
            off = side * rng.uniform(0.1, 1.4, 4 - n_on)
            if side == 0:
                off = rng.uniform(0.1, 1.4, 4 - n_on) * np.r_[-1, 1, -1][:4 - n_on]
            tet[n_on:, 2] = 1.5 + off
            t, v, a = voxel_overlaps(tet, [[0, 1, 2, 3]], shape)
            k = v // (shape[1] * shape[2])
            if side:
                assert np.all(k <= 1) if side < 0 else np.all(k >= 2), (n_on, side, k, a)
            assert np.isclose(a.sum(), abs(tetra_volumes(tet, [[0, 1, 2, 3]])[0]), rtol=1e-12)
            for f, ai in zip(v, a):
                assert abs(ai - hull_overlap(tet, *cell_bounds(f, shape))) < 1e-9
            ref = np.dot(a, V.ravel()[v]) / a.sum()
            assert np.isclose(tetra_gray(V, tet, [[0, 1, 2, 3]])[0], ref, rtol=1e-12)


def test_tiny_tetrahedron_gets_its_voxel_value():
    V = np.arange(27, dtype=float).reshape(3, 3, 3)
    tiny = np.array([[1.1, 0.8, 1.3], [1.2, 0.8, 1.3], [1.1, 0.9, 1.3], [1.1, 0.8, 1.35]])
    assert tetra_gray(V, tiny, [[0, 1, 2, 3]])[0] == V[1, 1, 1]
    t, v, a = voxel_overlaps(tiny, [[0, 1, 3, 2]], V.shape)  # either orientation
    assert v.tolist() == [13] and np.isclose(a[0], abs(tetra_volumes(tiny, [[0, 1, 2, 3]])[0]))
    across = tiny + [0.35, 0, 0]  # x from 1.45 to 1.55: half in each voxel along x
    g = tetra_gray(V, across, [[0, 1, 2, 3]])[0]
    ref = sum(hull_overlap(across, *cell_bounds(f, V.shape)) * V.ravel()[f] for f in (13, 14))
    assert np.isclose(g, ref / abs(tetra_volumes(across, [[0, 1, 2, 3]])[0]), rtol=1e-9)


def test_voxel_mean_is_the_adjoint_of_tetra_gray(mesh):
    """<A v, u> = <v, A^T u> with A the overlap matrix, through the two public functions
    (tetra_gray = A v / row sums, voxel_mean_of_tetrahedra = A^T u / column sums)."""
    shape, pts, tets = mesh
    rng = np.random.default_rng(7)
    v_img = rng.uniform(0, 5, shape)
    u = rng.uniform(0, 9, len(tets))
    mean, covered = voxel_mean_of_tetrahedra(u, pts, tets, shape)
    vol = np.abs(tetra_volumes(pts, tets))
    lhs = np.sum(vol * tetra_gray(v_img, pts, tets) * u)
    assert np.isclose(lhs, np.sum(v_img * covered * mean), rtol=1e-12)
    t, v, a = voxel_overlaps(pts, tets, shape)
    expect = np.bincount(v, a * u[t], np.prod(shape)) / np.bincount(v, a, np.prod(shape))
    np.testing.assert_allclose(mean.ravel(), expect, rtol=1e-12)
    np.testing.assert_allclose(covered, box_share(shape), atol=1e-12)


def test_voxels_without_tetrahedra_get_zero():
    pts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    mean, covered = voxel_mean_of_tetrahedra([5.0], pts, [[0, 1, 2, 3]], (3, 3, 3))
    assert mean[0, 0, 0] == 5.0 and mean[2, 2, 2] == 0.0 and covered[2, 2, 2] == 0.0
    assert np.isclose(covered.sum(), 1 / 6)


def test_large_tetrahedra_and_points_a_hair_outside_the_box():
    shape = (12, 11, 13)
    pts, tets = random_mesh(shape, 3, seed=8)
    pts = pts + np.where(pts == 0, -1e-10, 0)  # within the tolerance
    V = np.random.default_rng(9).uniform(0, 1, shape)
    g = tetra_gray(V, pts, tets)
    vol = np.abs(tetra_volumes(np.clip(pts, 0, None), tets))
    assert np.isclose(np.sum(vol * g), np.sum(V * box_share(shape)), rtol=1e-9)


@pytest.mark.parametrize("volume, points, tets, spacing, error", [
    (np.zeros((4, 4)), None, None, (1, 1, 1), InputError),  # 2D
    (np.full((3, 3, 3), np.nan), None, None, (1, 1, 1), InputError),
    (np.zeros((3, 3, 3), complex), None, None, (1, 1, 1), InputError),
    (np.zeros((1, 3, 3)), None, None, (1, 1, 1), ParameterError),  # too thin
    (None, np.zeros((4, 2)), None, (1, 1, 1), InputError),
    (None, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 2.5]], None, (1, 1, 1), InputError),
    (None, None, [[0, 1, 2]], (1, 1, 1), InputError),
    (None, None, [[0, 1, 2, 4]], (1, 1, 1), InputError),
    (None, None, [[0, 1, 2, -1]], (1, 1, 1), InputError),
    (None, None, [[0.0, 1.0, 2.0, 3.0]], (1, 1, 1), InputError),
    (None, None, [[0, 1, 2, 2]], (1, 1, 1), InputError),  # flat
    (None, None, None, (1, 0, 1), ParameterError),
    (None, None, None, (1, 1), ParameterError),
    (None, None, None, (1, np.inf, 1), ParameterError),
])
def test_bad_input_is_refused(volume, points, tets, spacing, error):
    volume = np.zeros((3, 3, 3)) if volume is None else volume
    points = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]] if points is None else points
    tets = [[0, 1, 2, 3]] if tets is None else tets
    with pytest.raises(error):
        tetra_gray(volume, points, tets, spacing=spacing)


def test_bad_input_of_the_transpose_is_refused():
    pts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    with pytest.raises(InputError, match="values"):
        voxel_mean_of_tetrahedra([1.0, 2.0], pts, [[0, 1, 2, 3]], (3, 3, 3))
    with pytest.raises(InputError, match="values"):
        voxel_mean_of_tetrahedra([np.nan], pts, [[0, 1, 2, 3]], (3, 3, 3))
    with pytest.raises(ParameterError, match="shape"):
        voxel_overlaps(pts, [[0, 1, 2, 3]], (3, 3))
    with pytest.raises(ParameterError, match="shape"):
        voxel_overlaps(pts, [[0, 1, 2, 3]], (3, 3.0, 3))


@pytest.mark.parametrize("chunk, slack, redone, threaded", [
    (7, 1.0, False, True), (7, 1.0, False, False), (40, 0.0, True, True),
    (40, 0.3, True, True), (10 ** 6, 0.0, True, True)])
def test_overlap_rows_do_not_depend_on_the_chunks_or_their_buffers(monkeypatch, chunk, slack,
                                                                   redone, threaded):
    """The recorder packs chunks of tetrahedra, on threads or not; a chunk that overflows
    its stretch is done again alone (slack 0.3: some chunks do, some not). The rows stay
    those of one sequential pass of the kernel, and sum to the streaming kernel's grays."""
    from ctseg import _overlap_rows, _threads
    from ctseg._tet_clip import _record
    from ctseg.tetra_gray import VoxelOverlaps

    shape = (6, 7, 9)
    pts, tets = random_mesh(shape, 60, 5)
    volume = np.random.default_rng(1).normal(size=shape)
    ref = VoxelOverlaps(pts, tets, shape)
    P = np.ascontiguousarray(pts[tets])
    start = np.zeros(len(P) + 1, np.int64)
    voxel, overlap = np.empty(10 ** 6, np.int32), np.empty(10 ** 6)
    assert _record(P, *shape, 0, start, voxel, overlap) == len(P)
    expected = np.full(len(P), slack * 30.0)
    monkeypatch.setattr(_overlap_rows, "_CHUNK_TETS", chunk)
    monkeypatch.setattr(_threads, "enabled", threaded)
    calls = []
    growing = _overlap_rows._record_growing
    monkeypatch.setattr(_overlap_rows, "_record_growing", lambda *a: calls.append(1) or growing(*a))
    got_start, got_voxel, got_overlap = _overlap_rows.overlap_rows(P, shape, expected)
    q = start[-1]
    for a, b in ((got_start, start), (got_voxel, voxel[:q]), (got_overlap, overlap[:q]),
                 (ref.start, start), (ref.voxel, voxel[:q])):
        np.testing.assert_array_equal(a, b)
    assert np.array_equal(ref.tetra_mean(volume), tetra_gray(volume, pts, tets))
    assert bool(calls) == redone


def test_near_degenerate_tetrahedra_near_the_planes_share_out_their_volume():
    """Vertices within 1e-15 of the voxel planes and near-flat slivers: the rounding of
    the clipped polygons may leave them slightly non-convex; each tetrahedron's overlaps
    still sum to its volume and each lies in a voxel it reaches."""
    rng = np.random.default_rng(12)
    shape = (5, 5, 5)
    for _ in range(300):
        tet = np.round(rng.uniform(0.2, 3.8, (4, 3)) * 2) / 2 + rng.normal(0, 1e-15, (4, 3))
        if rng.uniform() < 0.5:  # a sliver: the fourth vertex near the plane of the others
            w = rng.dirichlet(np.ones(3))
            tet[3] = w @ tet[:3] + rng.normal(0, 1e-3, 3)
        tet = np.clip(tet, 0, 4)
        vol = abs(tetra_volumes(tet, [[0, 1, 2, 3]])[0])
        if vol < 1e-12:
            continue
        t, v, a = voxel_overlaps(tet, [[0, 1, 2, 3]], shape)
        assert np.all(a > 0)
        assert np.isclose(a.sum(), vol, rtol=1e-9, atol=1e-15), (tet, a.sum(), vol)
        k, j, i = np.unravel_index(v, shape)
        lo, hi = np.floor(tet.min(0) + 0.5), np.ceil(tet.max(0) - 0.5)
        assert np.all((i >= lo[0]) & (i <= hi[0]) & (j >= lo[1]) & (j <= hi[1])
                      & (k >= lo[2]) & (k <= hi[2]))
