import numpy as np
import pytest

from ctseg import delaunay_mesh, triangle_gray
from ctseg.errors import InputError
from ctseg.raster import pixel_overlaps
from ctseg.triangulation import triangle_areas


def clip_polygon(poly, inside, intersect):
    out = []
    for k in range(len(poly)):
        cur, nxt = poly[k], poly[(k + 1) % len(poly)]
        if inside(cur):
            out.append(cur)
            if not inside(nxt):
                out.append(intersect(cur, nxt))
        elif inside(nxt):
            out.append(intersect(cur, nxt))
    return out


def overlap_reference(tri, x0, x1, y0, y1):
    """Slow, obvious Sutherland-Hodgman clip of one triangle by one rectangle."""
    poly = [tuple(p) for p in tri]

    def cut_x(c):
        return lambda a, b: (c, a[1] + (c - a[0]) * (b[1] - a[1]) / (b[0] - a[0]))

    def cut_y(c):
        return lambda a, b: (a[0] + (c - a[1]) * (b[0] - a[0]) / (b[1] - a[1]), c)

    for inside, inter in [(lambda p: p[0] >= x0, cut_x(x0)), (lambda p: p[0] <= x1, cut_x(x1)),
                          (lambda p: p[1] >= y0, cut_y(y0)), (lambda p: p[1] <= y1, cut_y(y1))]:
        if not poly:
            return 0.0
        poly = clip_polygon(poly, inside, inter)
    if len(poly) < 3:
        return 0.0
    x = np.array([p[0] for p in poly])
    y = np.array([p[1] for p in poly])
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


@pytest.fixture(scope="module")
def small_mesh():
    rng = np.random.default_rng(3)
    rows, cols = 9, 11
    pts = np.vstack([[[0, 0], [cols - 1, 0], [0, rows - 1], [cols - 1, rows - 1]],
                     rng.uniform([0.3, 0.3], [cols - 1.3, rows - 1.3], (25, 2)),
                     [[rng.uniform(1, cols - 2), 0], [0, rng.uniform(1, rows - 2)]]])
    return (rows, cols), delaunay_mesh(pts)


def test_overlaps_match_polygon_clipping_reference(small_mesh):
    (rows, cols), m = small_mesh
    t, p, a = pixel_overlaps(m.points, m.triangles, (rows, cols))
    got = {(int(ti), int(pi)): ai for ti, pi, ai in zip(t, p, a)}
    for ti, tri in enumerate(m.points[m.triangles]):
        for r in range(rows):
            for c in range(cols):
                ref = overlap_reference(tri, max(c - 0.5, 0), min(c + 0.5, cols - 1),
                                        max(r - 0.5, 0), min(r + 0.5, rows - 1))
                assert abs(got.get((ti, r * cols + c), 0.0) - ref) < 1e-9


def test_every_pixel_shared_out_once(small_mesh):
    (rows, cols), m = small_mesh
    t, p, a = pixel_overlaps(m.points, m.triangles, (rows, cols))
    per_pixel = np.bincount(p, a, rows * cols).reshape(rows, cols)
    wx = np.full(cols, 1.0)
    wx[[0, -1]] = 0.5
    wy = np.full(rows, 1.0)
    wy[[0, -1]] = 0.5
    np.testing.assert_allclose(per_pixel, wy[:, None] * wx[None, :], atol=1e-12)
    np.testing.assert_allclose(np.bincount(t, a, len(m.triangles)), triangle_areas(m.points, m.triangles))


def test_area_times_gray_is_the_image_integral(small_mesh):
    (rows, cols), m = small_mesh
    img = np.random.default_rng(0).uniform(-50, 300, (rows, cols))
    g = triangle_gray(img, m.points, m.triangles)
    wx = np.full(cols, 1.0)
    wx[[0, -1]] = 0.5
    wy = np.full(rows, 1.0)
    wy[[0, -1]] = 0.5
    integral = np.sum(img * wy[:, None] * wx[None, :])
    assert np.isclose(np.sum(g * triangle_areas(m.points, m.triangles)), integral)


def test_triangle_smaller_than_a_pixel_gets_its_pixel_value():
    pts = np.array([[0, 0], [4, 0], [0, 4], [4, 4], [2.1, 2.1], [2.3, 2.05], [2.2, 2.3]], float)
    m = delaunay_mesh(pts)
    img = np.arange(25, dtype=float).reshape(5, 5)
    g = triangle_gray(img, m.points, m.triangles)
    small = np.flatnonzero(np.all(np.isin(m.triangles, [4, 5, 6]), axis=1))
    assert len(small) == 1 and np.isclose(g[small[0]], img[2, 2])


def test_constant_image_gives_constant_gray(small_mesh):
    (rows, cols), m = small_mesh
    np.testing.assert_allclose(triangle_gray(np.full((rows, cols), 7.5), m.points, m.triangles), 7.5)


def test_points_outside_image_rejected(small_mesh):
    (rows, cols), m = small_mesh
    with pytest.raises(InputError):
        triangle_gray(np.zeros((rows - 1, cols)), m.points, m.triangles)


def test_pixel_mean_of_triangles_is_the_transpose_of_triangle_gray():
    # sum over pixels of image x (triangle values rasterised, times coverage) equals sum over
    # triangles of value x area x mean image gray: <I, R v> = <R^T I, v>
    from ctseg import delaunay_mesh
    from ctseg.triangle_gray import pixel_mean_of_triangles
    from ctseg.triangulation import triangle_areas
    rng = np.random.default_rng(4)
    rows, cols = 20, 30
    pts = np.vstack([[[0, 0], [cols - 1, 0], [0, rows - 1], [cols - 1, rows - 1]],
                     rng.uniform([0.5, 0.5], [cols - 1.5, rows - 1.5], (40, 2))])
    mesh = delaunay_mesh(pts)
    values = rng.uniform(0, 9, len(mesh.triangles))
    image = rng.uniform(0, 5, (rows, cols))
    mean, covered = pixel_mean_of_triangles(values, mesh.points, mesh.triangles, (rows, cols))
    lhs = np.sum(image * mean * covered)
    rhs = np.sum(values * triangle_areas(mesh.points, mesh.triangles)
                 * triangle_gray(image, mesh.points, mesh.triangles))
    assert np.isclose(lhs, rhs, rtol=1e-12)
    expect = np.ones((rows, cols))
    expect[[0, -1], :] = 0.5
    expect[:, [0, -1]] = 0.5
    expect[[0, 0, -1, -1], [0, -1, 0, -1]] = 0.25
    np.testing.assert_allclose(covered, expect, atol=1e-12)


def test_threaded_and_serial_sums_give_the_same_bits(monkeypatch):
    """The threaded kernels (one process) add in the serial order (slice workers): per
    triangle and per pixel, the same bits; and both equal the sums over the overlap list."""
    from ctseg import _threads
    from ctseg.triangle_gray import pixel_mean_of_triangles

    rng = np.random.default_rng(7)
    rows, cols = 61, 83  # bands of rows do not divide it evenly
    pts = np.vstack([[[0, 0], [cols - 1, 0], [0, rows - 1], [cols - 1, rows - 1]],
                     rng.uniform([0, 0], [cols - 1, rows - 1], (300, 2))])
    m = delaunay_mesh(pts)
    image = rng.normal(100.0, 30.0, (rows, cols))
    values = rng.normal(0.0, 1.0, len(m.triangles))
    runs = []
    for threaded in (True, False):
        monkeypatch.setattr(_threads, "enabled", threaded)
        runs.append((triangle_gray(image, m.points, m.triangles),
                     *pixel_mean_of_triangles(values, m.points, m.triangles, (rows, cols))))
    for a, b in zip(*runs):
        assert np.array_equal(a, b)
    t, p, a = pixel_overlaps(m.points, m.triangles, (rows, cols))
    gray = np.bincount(t, a * image.ravel()[p], len(m.triangles)) / np.bincount(t, a)
    np.testing.assert_allclose(runs[0][0], gray, rtol=1e-12)
    covered = np.bincount(p, a, rows * cols)
    np.testing.assert_allclose(runs[0][2].ravel(), covered, atol=1e-12)
    np.testing.assert_allclose(runs[0][1].ravel(), np.bincount(p, a * values[t], rows * cols) / covered,
                               atol=1e-12)
