import numpy as np
import pytest
from scipy import ndimage

from ctseg import delaunay_mesh, triangle_gray
from ctseg.blur import blur_corrected_gray, estimate_blur, level_image, region_levels
from ctseg.errors import InputError, ParameterError


def random_mesh(rows, cols, n, seed=0):
    rng = np.random.default_rng(seed)
    pts = np.vstack([[[0, 0], [cols - 1, 0], [0, rows - 1], [cols - 1, rows - 1]],
                     rng.uniform([0.5, 0.5], [cols - 1.5, rows - 1.5], (n, 2))])
    return delaunay_mesh(pts)


def disc_levels(mesh, cx, cy, r, inside=100.0, outside=10.0):
    c = mesh.points[mesh.triangles].mean(axis=1)
    return np.where(np.hypot(c[:, 0] - cx, c[:, 1] - cy) < r, inside, outside)


def test_level_image_matches_supersampled_reference():
    # each pixel: the mean level over 24 x 24 sample points of its square (inside the mesh's
    # rectangle, as the overlaps are clipped to it), found by a point-in-triangle search
    rows, cols = 9, 11
    mesh = random_mesh(rows, cols, 25)
    level = np.random.default_rng(1).uniform(0, 50, len(mesh.triangles))
    got = level_image(mesh.points, mesh.triangles, level, (rows, cols))
    P = mesh.points[mesh.triangles]  # (m, 3, 2)

    def containing_triangle(x, y):  # brute force: barycentric signs against every triangle
        a, b, c = P[:, 0], P[:, 1], P[:, 2]
        cross = lambda u, v, px, py: ((v[:, 0] - u[:, 0])[None] * (py[:, None] - u[:, 1][None])
                                      - (v[:, 1] - u[:, 1])[None] * (px[:, None] - u[:, 0][None]))
        inside = ((cross(a, b, x, y) >= -1e-12) & (cross(b, c, x, y) >= -1e-12)
                  & (cross(c, a, x, y) >= -1e-12))
        assert inside.any(axis=1).all()
        return inside.argmax(axis=1)

    k = 24
    off = (np.arange(k) + 0.5) / k - 0.5
    ref = np.zeros((rows, cols))
    for r in range(rows):
        for c in range(cols):
            xs, ys = np.meshgrid(c + off, r + off)
            xs, ys = xs.ravel(), ys.ravel()
            keep = (xs >= 0) & (xs <= cols - 1) & (ys >= 0) & (ys <= rows - 1)
            ref[r, c] = level[containing_triangle(xs[keep], ys[keep])].mean()
    np.testing.assert_allclose(got, ref, atol=1.5)  # sampling error of a 24 x 24 grid
    assert np.abs(got - ref).mean() < 0.2


@pytest.mark.parametrize("sigma", [0.6, 1.0, 1.5, 2.7])
def test_estimate_blur_recovers_a_known_blur(sigma):
    # shapes drawn 8x finer, blurred, averaged onto pixels, noise added: the fit finds sigma
    # (2.7: the upward scan of the grid must go on to its last widths)
    s, n = 8, 80
    yy, xx = (np.mgrid[0:n * s, 0:n * s] + 0.5) / s - 0.5
    fine = np.where(np.hypot(xx - 30.3, yy - 41.7) < 17.2, 200.0, 20.0)
    fine[(np.abs(xx - 62.1) < 6.4) & (np.abs(yy - 20.6) < 11.3)] = 80.0
    down = lambda a: a.reshape(n, s, n, s).mean(axis=(1, 3))
    image = down(ndimage.gaussian_filter(fine, sigma * s))
    image += np.random.default_rng(0).normal(0, 2.0, image.shape)
    est = estimate_blur(image, down(fine))
    assert abs(est - sigma) < 0.1


@pytest.mark.parametrize("sigma", [0.5, 1.3, 2.7])
def test_blur_on_chosen_slices_is_the_full_blur_there(sigma):
    from ctseg.blur import _blurred_slices, _fit_slices
    vol = np.random.default_rng(1).normal(0, 1, (140, 9, 11))
    slices = _fit_slices(len(vol))
    assert len(slices) == 70 and slices[0] == 1 and np.all(np.diff(slices) == 2)
    want = ndimage.gaussian_filter(vol, sigma, mode="nearest")[slices]
    np.testing.assert_allclose(_blurred_slices(vol, sigma, slices), want, rtol=0, atol=1e-12)


def test_volume_blur_fitted_on_some_slices_as_on_all(monkeypatch):
    """A 132-slice volume is compared on every other slice: the fitted blur is that of
    all the slices, and the true one."""
    import ctseg.blur as blur
    n, sigma = (132, 40, 40), 1.2
    z, y, x = np.indices(n, dtype=float)
    level = np.where((x - 19.3) ** 2 + (y - 20.6) ** 2 < 11.4 ** 2, 180.0, 30.0)
    level[np.abs(z - 70.2 + 0.3 * x) < 6.1] = 90.0  # a tilted plate: edges across the slices
    vol = ndimage.gaussian_filter(level, sigma, mode="nearest")
    vol += np.random.default_rng(2).normal(0, 3.0, n)
    some = estimate_blur(vol, level)
    monkeypatch.setattr(blur, "_FIT_SLICES", 10 ** 6)
    every = estimate_blur(vol, level)
    assert abs(some - every) < 0.02 and abs(every - sigma) < 0.05


def test_volume_blur_fitted_on_every_slice_where_the_sampled_ones_miss_the_edges(monkeypatch):
    """An interface across z between two sampled slices: their band is empty, so every
    slice is fitted (not a mean over no voxel)."""
    import ctseg.blur as blur
    monkeypatch.setattr(blur, "_FIT_SLICES", 8)  # 140 slices: every 17th, from slice 8
    monkeypatch.setattr(blur, "_FIT_MIN_VOXELS", 1)
    level = np.full((140, 30, 30), 20.0)
    level[67:] = 120.0  # band: slices 64-69, none of them sampled
    assert not np.isin(np.arange(64, 70), blur._fit_slices(140)).any()
    vol = ndimage.gaussian_filter(level, 1.5, mode="nearest")
    vol += np.random.default_rng(3).normal(0, 2.0, vol.shape)
    assert abs(estimate_blur(vol, level) - 1.5) < 0.05


def test_estimate_blur_edge_cases():
    flat = np.full((10, 10), 5.0)
    assert estimate_blur(flat + np.random.default_rng(0).normal(0, 1, flat.shape), flat) == 0.0
    with pytest.raises(ParameterError, match="levels_image"):
        estimate_blur(flat, np.zeros((10, 11)))
    with pytest.raises(InputError):
        estimate_blur(flat, np.full((10, 10), np.nan))


def test_correction_gives_back_the_levels_of_an_exactly_blurred_labelling():
    # if the image is G_sigma * L for the labelling's own level image, every corrected
    # triangle gray is its level, with the given sigma and with the fitted one
    rows, cols = 40, 44
    mesh = random_mesh(rows, cols, 220, seed=3)
    level = disc_levels(mesh, 20.5, 18.0, 9.0)
    image = ndimage.gaussian_filter(level_image(mesh.points, mesh.triangles, level, (rows, cols)),
                                    1.1, mode="nearest")
    gray = triangle_gray(image, mesh.points, mesh.triangles)
    assert np.abs(gray - level).max() > 20  # the blur moved the edge triangles a lot
    fixed, s = blur_corrected_gray(gray, mesh.points, mesh.triangles, level, image, sigma=1.1)
    assert s == 1.1
    np.testing.assert_allclose(fixed, level, atol=1e-9)
    fitted, s = blur_corrected_gray(gray, mesh.points, mesh.triangles, level, image)
    assert abs(s - 1.1) < 0.02
    np.testing.assert_allclose(fitted, level, atol=1.0)


def test_bad_level_length():
    mesh = random_mesh(10, 10, 5)
    with pytest.raises(ParameterError, match="level"):
        level_image(mesh.points, mesh.triangles, np.zeros(len(mesh.triangles) + 1), (10, 10))
    with pytest.raises(ParameterError, match="gray"):
        blur_corrected_gray(np.zeros(2), mesh.points, mesh.triangles,
                            np.zeros(len(mesh.triangles)), np.zeros((10, 10)))


def test_region_levels_are_weighted_medians_of_connected_runs():
    # on a chain of triangles, regions are the runs of equal material; reference: sort each
    # run and take the first value whose cumulative area reaches half the run's
    rng = np.random.default_rng(0)
    m = 300
    material = rng.integers(0, 3, m)
    gray = rng.normal(0, 10, m) + 50 * material
    area = rng.uniform(0.5, 3.0, m)
    chain = np.column_stack([np.arange(m - 1), np.arange(1, m)])
    got = region_levels(material, gray, area, chain)
    ref = np.empty(m)
    i = 0
    while i < m:
        j = i
        while j + 1 < m and material[j + 1] == material[i]:
            j += 1
        run = slice(i, j + 1)
        order = np.argsort(gray[run])
        cum = np.cumsum(area[run][order])
        ref[run] = gray[run][order][np.searchsorted(cum, 0.5 * cum[-1])]
        i = j + 1
    np.testing.assert_array_equal(got, ref)
    # the same material apart (no shared edge) is two regions with their own medians
    two = region_levels([0, 0, 0, 0], [1.0, 2.0, 10.0, 20.0], [1, 1, 1, 1], [[0, 1], [2, 3]])
    np.testing.assert_array_equal(two, [1.0, 1.0, 10.0, 10.0])


@pytest.mark.parametrize("side,sigma", [(30.0, 1.0), (12.0, 0.8), (8.0, 1.5)])
def test_self_weight_against_blurring_the_triangle_alone(side, sigma):
    # exact: the triangle's own coverage image, blurred, averaged over the triangle
    n = int(side) + 16
    pts = np.array([[0, 0], [n - 1, 0], [0, n - 1], [n - 1, n - 1],
                    [8.3, 9.1], [8.3 + side, 9.1], [8.3 + side / 2, 9.1 + side * 0.866]])
    mesh = delaunay_mesh(pts)
    inner = np.flatnonzero(np.all(mesh.triangles >= 4, axis=1))
    assert len(inner) == 1
    own = np.zeros(len(mesh.triangles))
    own[inner] = 1.0
    cover = level_image(mesh.points, mesh.triangles, own, (n, n))
    exact = triangle_gray(ndimage.gaussian_filter(cover, sigma, mode="constant"), mesh.points,
                          mesh.triangles)[inner[0]]
    from ctseg.blur import self_weight
    approx = self_weight(mesh.points, mesh.triangles, sigma)[inner[0]]
    # where it is used (above the 0.8 floor: sides many sigma long) within 0.03; on a small
    # triangle the corners, which lose less than straight edges, make it an underestimate
    if exact > 0.75:
        assert abs(approx - exact) < 0.03, (approx, exact)
    else:
        assert exact - 0.1 < approx < exact, (approx, exact)


def test_amplified_correction_explains_a_thin_gap():
    # a 4 px air gap (level 0) between two bright blocks (200) that a first pass labelled
    # bright: the blur left the gap at a quarter of the contrast; the correction amplified by
    # the self-weight floor (1 / 0.8) brings it near 0, the plain one leaves it where it is
    rows, cols = 30, 40
    pts = np.array([[x, y] for x in (0, 8, 18, 22, 32, 39) for y in (0, 7.5, 15, 22.5, 29)], float)
    mesh = delaunay_mesh(pts)
    cx = mesh.points[mesh.triangles].mean(axis=1)[:, 0]
    truth = np.where((cx > 18) & (cx < 22), 0.0, 200.0)
    image = ndimage.gaussian_filter(level_image(mesh.points, mesh.triangles, truth, (rows, cols)),
                                    1.0, mode="nearest")
    gray = triangle_gray(image, mesh.points, mesh.triangles)
    first = np.full(len(gray), 200.0)  # the gap missed
    gap = truth == 0
    plain, _ = blur_corrected_gray(gray, mesh.points, mesh.triangles, first, image, sigma=1.0,
                                   blur_min_self_weight=1.0)
    fixed, _ = blur_corrected_gray(gray, mesh.points, mesh.triangles, first, image, sigma=1.0)
    assert np.all(gray[gap] > 40)  # the blur lifted the gap
    np.testing.assert_allclose(plain[gap], gray[gap], atol=1e-6)  # nothing predicted there
    np.testing.assert_allclose(fixed[gap], 200.0 + (gray[gap] - 200.0) / 0.8, atol=1e-6)
    assert np.all(np.abs(fixed[gap]) < 15)


@pytest.mark.parametrize("shape", [(1, 30, 40), (5, 9, 11), (16, 20, 24)])
def test_level_changes_are_the_max_minus_min_filter_rule(shape):
    # the compiled neighbourhood test against the filters it replaces (the slow reference)
    from ctseg import _level_changes

    rng = np.random.default_rng(len(shape) + shape[0])
    lev = np.where(rng.uniform(size=shape) < 0.93, 1.0, rng.integers(0, 3, shape).astype(float))
    lev[lev == 0] = -0.0  # a signed zero is no change
    lev[:, :2, :2] = 0.0
    expected = (ndimage.maximum_filter(lev, 3, mode="nearest")
                - ndimage.minimum_filter(lev, 3, mode="nearest")) > 0
    assert 0 < expected.sum() < expected.size
    for kernel in (_level_changes.level_changes, _level_changes.level_changes_parallel):
        out = np.empty(shape, bool)
        kernel(lev, out)
        assert np.array_equal(out, expected)


def test_self_weight_3d_is_the_rule_on_face_areas_and_volume():
    # slow reference: each face's area from the outward faces, the volume from its formula
    from ctseg.blur import self_weight_3d
    from ctseg.tetrahedra import delaunay_tetrahedra, tetra_faces, tetra_volumes

    rng = np.random.default_rng(3)
    corners = np.array([[x, y, z] for x in (0, 9) for y in (0, 9) for z in (0, 9)], float)
    mesh = delaunay_tetrahedra(np.vstack([corners, rng.uniform(0, 9, (80, 3))]), (9, 9, 9))
    sigma = 0.8
    got = self_weight_3d(mesh.points, mesh.tetrahedra, sigma)
    expected = []
    for tet in mesh.tetrahedra:
        faces = tetra_faces(tet[None])
        area = sum(0.5 * np.linalg.norm(np.cross(mesh.points[f[1]] - mesh.points[f[0]],
                                                 mesh.points[f[2]] - mesh.points[f[0]]))
                   for f in faces)
        vol = abs(tetra_volumes(mesh.points, tet[None])[0])
        expected.append(1.0 - area * sigma / (np.sqrt(2.0 * np.pi) * vol))
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)
    # a scaled copy: area over volume falls as 1 / scale
    np.testing.assert_allclose(1.0 - self_weight_3d(2.0 * mesh.points, mesh.tetrahedra, sigma),
                               0.5 * (1.0 - got), rtol=1e-9)
