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
