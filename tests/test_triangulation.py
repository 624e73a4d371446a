import numpy as np
import pytest

from ctseg import delaunay_mesh, density_map, lloyd_cvt, ward_sites
from ctseg.errors import InputError
from ctseg.triangulation import edge_adjacency, triangle_areas

from conftest import disc_image


@pytest.fixture(scope="module")
def mesh():
    img, _ = disc_image(50, noise=3.0)
    rho = density_map(img)
    r = lloyd_cvt(rho, ward_sites(rho, 90))
    return img.shape, delaunay_mesh(r.sites)


def test_covers_rectangle_without_degenerate_triangles(mesh):
    (rows, cols), m = mesh
    a = triangle_areas(m.points, m.triangles)
    assert np.all(a > 1e-6)  # counter-clockwise, none degenerate
    assert np.isclose(a.sum(), (rows - 1) * (cols - 1))
    # every vertex is used, and the outer boundary is exactly the rectangle's perimeter
    assert len(np.unique(m.triangles)) == len(m.points)
    _, _, boundary = edge_adjacency(m.triangles)
    p0, p1 = m.points[boundary[:, 0]], m.points[boundary[:, 1]]
    on_border = lambda p: (p[:, 0] == 0) | (p[:, 0] == cols - 1) | (p[:, 1] == 0) | (p[:, 1] == rows - 1)
    assert np.all(on_border(p0) & on_border(p1))
    assert np.isclose(np.hypot(*(p1 - p0).T).sum(), 2 * (rows - 1 + cols - 1))


def test_adjacency_matches_brute_force(mesh):
    _, m = mesh
    t = m.triangles
    ref = set()
    sets = [set(x) for x in t.tolist()]
    for i in range(len(t)):
        for j in range(i + 1, len(t)):
            if len(sets[i] & sets[j]) == 2:
                ref.add((i, j))
    assert set(map(tuple, m.adjacency.tolist())) == ref
    for (i, j), e in zip(m.adjacency, m.shared_edges):
        assert set(e) == sets[i] & sets[j]


def test_bad_sites():
    with pytest.raises(InputError):
        delaunay_mesh(np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]))
    with pytest.raises(InputError):
        delaunay_mesh(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, 1.0]]))
