"""Sub-pixel boundary placement (SPEC 10): vertices between two materials at the ISO-50
crossing, never inverting or squashing a triangle; junction and border vertices fixed."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.ndimage import gaussian_filter

import ctseg
from ctseg.errors import InputError, ParameterError
from ctseg.subpixel import MIN_AREA_RATIO, place_boundary_vertices, subpixel_mesh


def _signed(points, tri):
    p = points[tri]
    return 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))


def _half_plane(shape, normal, offset, lo=20.0, hi=180.0, ss=8):
    """Exact-ish pixel averages (ss x ss sub-samples) of a half-plane n.x > offset."""
    rows, cols = shape
    sub = (np.arange(ss) + 0.5) / ss - 0.5
    ys = (np.arange(rows)[:, None] + sub[None, :]).ravel()
    xs = (np.arange(cols)[:, None] + sub[None, :]).ravel()
    inside = (normal[0] * xs[None, :] + normal[1] * ys[:, None]) > offset
    frac = inside.reshape(rows, ss, cols, ss).mean(axis=(1, 3))
    return lo + (hi - lo) * frac


def _labelled_mesh(image, threshold, n_sites=300, seed=0):
    mesh = ctseg.delaunay_mesh(ctseg.random_sites(image.shape, n_sites, seed=seed))
    gray = ctseg.triangle_gray(image, mesh.points, mesh.triangles)
    return mesh, gray, (gray > threshold).astype(np.int64)


def test_vertices_land_on_a_tilted_edge():
    """Ground truth: a straight edge at a known sub-pixel position; the boundary vertices
    move onto it (ISO-50 of a linear partial-volume profile is the edge itself)."""
    n = np.array([np.cos(0.3), np.sin(0.3)])
    img = _half_plane((48, 48), n, 24.37)
    mesh, gray, mat = _labelled_mesh(img, 100.0, n_sites=400)
    moved, n_moved = place_boundary_vertices(mesh.points, mesh.triangles, mat, img, [20.0, 180.0])
    both = np.zeros(len(mesh.points), bool)
    for k in (0, 1):
        v = np.zeros(len(mesh.points), bool)
        v[mesh.triangles[mat == k].ravel()] = True
        both = both & v if k else v
    border = (np.isclose(mesh.points, 0) | np.isclose(mesh.points, 47)).any(axis=1)
    inner = both & ~border
    before = np.abs(mesh.points[inner] @ n - 24.37)
    after = np.abs(moved[inner] @ n - 24.37)
    went = np.any(moved[inner] != mesh.points[inner], axis=1)
    assert went.sum() == n_moved >= 10
    assert np.all(went[before < 0.4])  # near vertices always find the crossing
    assert np.max(after[went]) < 0.15 and np.median(after[went]) < 0.1, after[went]
    assert np.median(before[went]) > 0.25
    assert np.array_equal(moved[~inner], mesh.points[~inner])


def test_junction_and_border_vertices_stay():
    img = np.zeros((40, 40))
    img[:, 20:] = 100.0
    img[20:, :20] = 200.0
    mesh, gray, _ = _labelled_mesh(img, 0.0, n_sites=250, seed=3)
    mat = np.digitize(gray, [50.0, 150.0])
    moved, _ = place_boundary_vertices(mesh.points, mesh.triangles, mat, img, [0.0, 100.0, 200.0])
    n_mat = np.zeros(len(mesh.points), int)
    for k in range(3):
        v = np.zeros(len(mesh.points), bool)
        v[mesh.triangles[mat == k].ravel()] = True
        n_mat += v
    border = (np.isclose(mesh.points, 0) | np.isclose(mesh.points, 39)).any(axis=1)
    fixed = (n_mat != 2) | border
    assert fixed.any() and (n_mat == 3).any()
    assert np.array_equal(moved[fixed], mesh.points[fixed])
    assert not np.array_equal(moved, mesh.points)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), n_sites=st.integers(12, 400), shift=st.floats(0.05, 0.95),
       smooth=st.floats(0.0, 2.0), blur=st.floats(0.0, 3.0), k=st.integers(2, 4))
def test_no_triangle_inverted_or_squashed(seed, n_sites, shift, smooth, blur, k):
    """Any image, any mesh, any labels: every triangle keeps MIN_AREA_RATIO of its area,
    positively oriented; vertices with one or three or more materials do not move."""
    rng = np.random.default_rng(seed)
    shape = tuple(rng.integers(6, 40, 2))
    img = gaussian_filter(rng.normal(0, 1, shape), 1.5) * 100 + rng.normal(0, 5, shape)
    img = gaussian_filter(img, blur) if blur else img
    mesh = ctseg.delaunay_mesh(ctseg.random_sites(shape, min(n_sites, shape[0] * shape[1]), seed=seed))
    gray = ctseg.triangle_gray(img, mesh.points, mesh.triangles)
    mat = np.digitize(gray, np.quantile(gray, np.linspace(0, 1, k + 1)[1:-1]))
    levels = np.array([np.median(gray[mat == j]) if (mat == j).any() else np.nan for j in range(k)])
    moved, n_moved = place_boundary_vertices(mesh.points, mesh.triangles, mat, img, levels,
                                             max_shift_fraction=shift, smooth_px=smooth)
    a0, a1 = _signed(mesh.points, mesh.triangles), _signed(moved, mesh.triangles)
    assert np.all(a1 >= MIN_AREA_RATIO * a0 - 1e-12) and np.all(a1 > 0)
    counts = np.zeros(len(mesh.points), int)
    for j in range(k):
        v = np.zeros(len(mesh.points), bool)
        v[mesh.triangles[mat == j].ravel()] = True
        counts += v
    assert np.array_equal(moved[counts != 2], mesh.points[counts != 2])
    assert n_moved == int(np.any(moved != mesh.points, axis=1).sum())


def test_bad_input_is_refused():
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    tri = np.array([[0, 1, 2]])
    img = np.zeros((2, 2))
    with pytest.raises(InputError, match="material"):
        place_boundary_vertices(pts, tri, [0, 1], img, [0.0, 1.0])
    with pytest.raises(InputError, match="index levels"):
        place_boundary_vertices(pts, tri, [3], img, [0.0, 1.0])
    with pytest.raises(ParameterError, match="max_shift_fraction"):
        place_boundary_vertices(pts, tri, [0], img, [0.0, 1.0], max_shift_fraction=1.0)
    with pytest.raises(InputError, match="points"):
        place_boundary_vertices(pts[:, :1], tri, [0], img, [0.0, 1.0])


def test_pipeline_moves_vertices_and_keeps_labels():
    from ctseg.phantoms import make_phantom
    from ctseg.metrics import evaluate

    p = make_phantom(256, seed=0)
    off = ctseg.segment_image(p.image, subpixel_boundary=False)
    on = ctseg.segment_image(p.image)
    assert np.array_equal(on.triangles, off.triangles) and np.array_equal(on.material, off.material)
    moved = np.any(on.points != off.points, axis=1)
    assert on.diagnostics["subpixel_moved"] == moved.sum() > 0
    assert set(np.flatnonzero(moved)) <= set(np.unique(off.boundary_edges).tolist())
    # the gray is measured again on the moved mesh
    np.testing.assert_allclose(on.gray, ctseg.triangle_gray(on.corrected_image if on.corrected_image
                                                            is not None else p.image,
                                                            on.points, on.triangles), rtol=1e-12)
    e_on = evaluate(on, p.truth, p.truth_hr, p.supersample)
    e_off = evaluate(off, p.truth, p.truth_hr, p.supersample)
    assert e_on["boundary_px"]["mean"] < e_off["boundary_px"]["mean"]
    assert e_on["min_dice_subpixel"] >= e_off["min_dice_subpixel"] - 0.002


def test_subpixel_mesh_measures_levels_away_from_the_boundary():
    n = np.array([1.0, 0.0])
    img = _half_plane((32, 32), n, 15.6)
    mesh, gray, mat = _labelled_mesh(img, 100.0, n_sites=200)
    out = subpixel_mesh(img, mesh.points, mesh.triangles, gray, mat, renumber=False)
    assert out.n_moved > 0 and np.array_equal(out.material, mat) and out.material_gray is None
    np.testing.assert_allclose(out.gray, ctseg.triangle_gray(img, out.points, mesh.triangles))


# ---------------------------------------------------------------------------- tetrahedra
def _half_space_3d(shape, normal, offset, spacing, lo=20.0, hi=180.0, ss=4):
    """Exact-ish voxel averages (ss^3 sub-samples) of the half-space n.x > offset, x the
    physical point (i sx, j sy, k sz)."""
    sub = (np.arange(ss) + 0.5) / ss - 0.5
    axes = [((np.arange(n)[:, None] + sub[None, :]) * s).ravel()
            for n, s in zip(shape, np.asarray(spacing, float)[::-1])]  # z, y, x
    z, y, x = np.meshgrid(*axes, indexing="ij")
    inside = normal[0] * x + normal[1] * y + normal[2] * z > offset
    frac = inside.reshape(shape[0], ss, shape[1], ss, shape[2], ss).mean(axis=(1, 3, 5))
    return lo + (hi - lo) * frac


def _tetra_mesh(shape, spacing, n_sites, seed):
    from ctseg.sites import random_sites_3d
    from ctseg.stages3d import tetrahedra_3d

    box = (np.array(shape[::-1], float) - 1.0) * spacing
    corners = np.array([[x, y, z] for x in (0, box[0]) for y in (0, box[1]) for z in (0, box[2])])
    sites = np.unique(np.vstack([corners, random_sites_3d(shape, n_sites, spacing, seed=seed)]), axis=0)
    return tetrahedra_3d(sites, shape, None, spacing)[0]


def _materials_per_vertex(elements, mat, n_points):
    counts = np.zeros(n_points, int)
    for j in np.unique(mat):
        v = np.zeros(n_points, bool)
        v[elements[mat == j].ravel()] = True
        counts += v
    return counts


def test_vertices_land_on_a_tilted_plane_in_3d():
    """Ground truth in 3D with anisotropic voxels: a tilted plane at a known position; the
    vertices between its two sides move onto it, box vertices stay."""
    from ctseg.tetra_gray import tetra_gray

    sp = np.array([0.6, 0.8, 1.1])
    shape = (16, 22, 26)
    n = np.array([0.8, 0.36, 0.48])
    n /= np.linalg.norm(n)
    box = (np.array(shape[::-1]) - 1.0) * sp
    offset = float(n @ box / 2 + 0.137)
    img = _half_space_3d(shape, n, offset, sp)
    mesh = _tetra_mesh(shape, sp, 900, seed=2)
    mat = (tetra_gray(img, mesh.points, mesh.tetrahedra, sp) > 100.0).astype(np.int64)
    moved, n_moved = place_boundary_vertices(mesh.points, mesh.tetrahedra, mat, img, [20.0, 180.0],
                                             spacing=sp, min_dihedral_deg=5.0)
    counts = _materials_per_vertex(mesh.tetrahedra, mat, len(mesh.points))
    border = (np.isclose(mesh.points, 0) | np.isclose(mesh.points, box)).any(axis=1)
    inner = (counts == 2) & ~border
    went = np.any(moved != mesh.points, axis=1)
    assert went.sum() == n_moved >= 20 and not went[~inner].any()
    before = np.abs(mesh.points[went] @ n - offset) / sp.min()
    after = np.abs(moved[went] @ n - offset) / sp.min()
    # moves a tetrahedron's quality cut short (halved) stop part way
    assert np.median(before) > 0.3 and np.median(after) < 0.1, after
    assert np.mean(after) < 0.4 * np.mean(before) and np.mean(after < before) > 0.9
    near = inner & (np.abs(mesh.points @ n - offset) < 0.4 * sp.min())
    assert went[near].mean() > 0.8


def test_3d_step_check_leaves_features_too_thin_to_reach_their_level():
    """A plate 2 voxels thick, blurred until its gray peaks at about 70% of the contrast:
    its ISO-50 lies inside it, so without the step check its vertices move in (the plate
    thins); with it (the 3D mode's EDGE_PX, EDGE_SHARE) none moves. A thick slab of the
    same material, same blur: its vertices move with and without."""
    from ctseg.subpixel import EDGE_PX
    from ctseg.tetra_gray import tetra_gray

    sp = np.ones(3)
    shape = (14, 16, 40)
    for x0, x1, expect_moves in ((18.3, 20.3, False), (14.3, 26.3, True)):
        img = gaussian_filter(_half_space_3d(shape, np.array([1.0, 0, 0]), x0, sp, 0.0, 100.0)
                              - _half_space_3d(shape, np.array([1.0, 0, 0]), x1, sp, 0.0, 100.0), 1.0)
        assert (55.0 < img.max() < 85.0) == (not expect_moves)
        mesh = _tetra_mesh(shape, sp, 700, seed=5)
        mat = (tetra_gray(img, mesh.points, mesh.tetrahedra) > 25.0).astype(np.int64)
        _, free = place_boundary_vertices(mesh.points, mesh.tetrahedra, mat, img, [0.0, 100.0])
        _, checked = place_boundary_vertices(mesh.points, mesh.tetrahedra, mat, img, [0.0, 100.0],
                                             edge_px=EDGE_PX)
        assert free > 5
        assert (checked > 0.5 * free) if expect_moves else checked == 0, (free, checked)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n_sites=st.integers(10, 160), shift=st.floats(0.05, 0.95),
       smooth=st.floats(0.0, 2.0), k=st.integers(2, 4), min_angle=st.sampled_from([0.0, 5.0, 12.0]))
def test_no_tetrahedron_inverted_squashed_or_made_a_sliver(seed, n_sites, shift, smooth, k, min_angle):
    """Any volume, any tetrahedra, any labels: every tetrahedron keeps MIN_AREA_RATIO of its
    volume, positively oriented, and a smallest dihedral angle of at least
    min(its own, min_dihedral_deg); vertices with one or three or more materials and box
    vertices do not move."""
    from ctseg.tetra_gray import tetra_gray
    from ctseg.tetrahedra import dihedral_angles, tetra_volumes

    rng = np.random.default_rng(seed)
    shape = tuple(int(v) for v in rng.integers(4, 14, 3))
    sp = rng.uniform(0.5, 1.5, 3)
    img = gaussian_filter(rng.normal(0, 1, shape), 1.5) * 100 + rng.normal(0, 5, shape)
    mesh = _tetra_mesh(shape, sp, min(n_sites, int(np.prod(shape)) - 8), seed)
    gray = tetra_gray(img, mesh.points, mesh.tetrahedra, sp)
    mat = np.digitize(gray, np.quantile(gray, np.linspace(0, 1, k + 1)[1:-1]))
    levels = np.array([np.median(gray[mat == j]) if (mat == j).any() else np.nan for j in range(k)])
    moved, n_moved = place_boundary_vertices(mesh.points, mesh.tetrahedra, mat, img, levels,
                                             max_shift_fraction=shift, smooth_px=smooth,
                                             spacing=sp, min_dihedral_deg=min_angle)
    v0, v1 = tetra_volumes(mesh.points, mesh.tetrahedra), tetra_volumes(moved, mesh.tetrahedra)
    assert np.all(v1 >= MIN_AREA_RATIO * v0 - 1e-12) and np.all(v1 > 0)
    a0 = dihedral_angles(mesh.points, mesh.tetrahedra).min(axis=1)
    a1 = dihedral_angles(moved, mesh.tetrahedra).min(axis=1)
    went = np.any(moved != mesh.points, axis=1)
    around = np.isin(np.arange(len(mesh.tetrahedra)),
                     np.flatnonzero(np.isin(mesh.tetrahedra, np.flatnonzero(went)).any(axis=1)))
    assert np.all(a1[around] >= np.minimum(a0[around], min_angle) - 1e-9)
    box = (np.array(shape[::-1]) - 1.0) * sp
    border = (np.isclose(mesh.points, 0) | np.isclose(mesh.points, box)).any(axis=1)
    counts = _materials_per_vertex(mesh.tetrahedra, mat, len(mesh.points))
    assert not went[(counts != 2) | border].any()
    assert n_moved == int(went.sum())


def test_volume_pipeline_moves_vertices_onto_a_sphere_and_keeps_labels():
    """3D mode: the same tetrahedra and materials with and without the placement; only
    interface vertices move, towards the analytic sphere; the surfaces stay closed and
    enclose their tetrahedra's volume; the gray is measured again."""
    from ctseg.phantoms3d import make_sphere_3d
    from ctseg.tetra_gray import tetra_gray

    ph = make_sphere_3d(28, radius=8.3, noise_sd=0.03)
    off = ctseg.segment_volume(ph.image, mode="3d", subpixel_boundary=False)
    on = ctseg.segment_volume(ph.image, mode="3d")
    assert np.array_equal(on.tetrahedra, off.tetrahedra) and np.array_equal(on.material, off.material)
    went = np.any(on.points != off.points, axis=1)
    assert on.diagnostics["subpixel_moved"] == went.sum() > 20
    assert set(np.flatnonzero(went)) <= set(np.unique(off.interfaces).tolist())
    centre, radius = np.array(ph.features["centre"]), ph.features["radius"]
    dist = lambda p: np.abs(np.linalg.norm(p - centre, axis=1) - radius)
    iface = np.unique(on.interfaces)
    # the moved vertices land on the sphere; the coarse-to-fine CVT already puts the
    # interface vertices near it (0.17 voxel), so all of them gain less (0.13). With 10
    # voxel Lloyd iterations the moved ones go 0.150 -> 0.052 voxel, and 0.197 -> 0.104 on
    # the oldest supported versions (numpy 1.24), whose mesh differs
    assert dist(on.points[went]).mean() < min(0.6 * dist(off.points[went]).mean(), 0.15)
    assert dist(on.points[iface]).mean() < dist(off.points[iface]).mean()
    assert on.diagnostics["element_quality"]["min_dihedral_deg"] >= 5.0 - 1e-9
    for s in on.surfaces:
        assert abs(s.enclosed_volume - s.element_volume) < 1e-9 * s.element_volume
    np.testing.assert_allclose(on.gray, tetra_gray(ph.image.astype(float), on.points, on.tetrahedra),
                               rtol=1e-9)
