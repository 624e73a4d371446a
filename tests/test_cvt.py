import numpy as np
import pytest

from ctseg import density_map, lloyd_cvt, ward_sites
from ctseg.errors import InputError, ParameterError

from conftest import disc_image
from oracles import cvt_energy, nearest_site


def brute_nearest_dist(points, sites):
    d = np.sqrt(((points[:, None, :] - sites[None, :, :]) ** 2).sum(-1))
    return d.min(axis=1)


@pytest.mark.parametrize("layout", ["uniform", "clustered", "integer"])
def test_nearest_site_matches_brute_force(layout):
    rng = np.random.default_rng(0)
    pts = rng.uniform(-5, 55, (3000, 2))
    if layout == "uniform":
        sites = rng.uniform(0, 50, (60, 2))
    elif layout == "clustered":  # dense near a line, sparse elsewhere (as CVT sites are)
        sites = np.vstack([np.column_stack([rng.uniform(0, 50, 200), 25 + rng.normal(0, 0.3, 200)]),
                           rng.uniform(0, 50, (10, 2))])
    else:  # pixel-centre sites and points: many exact ties
        sites = rng.choice(51, (40, 2)).astype(float)
        sites = np.unique(sites, axis=0)
        pts = rng.choice(51, (3000, 2)).astype(float)
    lab = nearest_site(pts, sites)
    d_all = np.sqrt(((pts[:, None, :] - sites[None, :, :]) ** 2).sum(-1))
    np.testing.assert_allclose(d_all[np.arange(len(pts)), lab], d_all.min(axis=1), atol=1e-12)
    # ties go to the lower index: the first site at the minimum distance
    assert np.array_equal(lab, np.argmin(d_all, axis=1))


@pytest.fixture(scope="module")
def cvt_run():
    img, _ = disc_image(60, noise=5.0)
    rho = density_map(img)
    return rho, lloyd_cvt(rho, ward_sites(rho, 80), max_iter=300)


def test_final_regions_are_nearest_site(cvt_run):
    rho, r = cvt_run
    rows, cols = rho.shape
    yy, xx = np.mgrid[0:rows, 0:cols]
    px = np.column_stack([xx.ravel(), yy.ravel()]).astype(float)
    d = np.hypot(*(px - r.sites[r.labels.ravel()]).T)
    np.testing.assert_allclose(d, brute_nearest_dist(px, r.sites), atol=1e-9)


def test_energy_never_increases(cvt_run):
    rho, r = cvt_run
    e = np.array(r.energy)
    assert len(e) == r.n_iter + 1
    assert np.all(np.diff(e) <= 1e-9 * e[0])
    assert e[-1] < e[0]
    assert np.isclose(e[-1], cvt_energy(rho, r.sites, r.labels))


def test_corners_fixed_and_border_sites_on_border(cvt_run):
    rho, r = cvt_run
    rows, cols = rho.shape
    for corner in [(0, 0), (cols - 1, 0), (0, rows - 1), (cols - 1, rows - 1)]:
        assert np.any(np.all(r.sites == corner, axis=1))
    # the border lines are served mostly by border sites (rule 2; sites are added there,
    # and a free site whose region reaches the border later is the exception)
    lab = r.labels
    s = r.sites
    on_line = (s[:, 0] == 0) | (s[:, 0] == cols - 1) | (s[:, 1] == 0) | (s[:, 1] == rows - 1)
    for line in (lab[0], lab[-1], lab[:, 0], lab[:, -1]):
        assert on_line[line].mean() > 0.7
    border_regions = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    # and no interior region's site sits on the border
    inner = np.setdiff1d(np.arange(len(r.sites)), border_regions)
    si = r.sites[inner]
    assert np.all((si[:, 0] > 0) & (si[:, 0] < cols - 1) & (si[:, 1] > 0) & (si[:, 1] < rows - 1))


def test_converges_and_reports(cvt_run):
    _, r = cvt_run
    assert r.converged and r.n_iter < 300


def test_bad_inputs():
    rho = np.ones((10, 10))
    with pytest.raises(ParameterError):
        lloyd_cvt(rho, np.array([[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]))
    with pytest.raises(InputError):
        lloyd_cvt(rho, np.array([[1.0, 1.0], [2.0, 2.0], [3.0, 3.0], [20.0, 1.0]]))
    sites = np.random.default_rng(0).uniform(0, 9, (6, 2))
    for kw, word in (({"tol_px": 0}, "tol_px"), ({"max_iter": 0}, "max_iter"),
                     ({"max_iter": 2.5}, "max_iter")):
        with pytest.raises(ParameterError, match=word):
            lloyd_cvt(rho, sites, **kw)


def test_no_site_left_a_hair_from_another():
    # found by hypothesis: a free site whose region is one run of bottom-border pixels
    # ended 4e-16 px from a border site, and Qhull dropped it from the triangulation
    row = [100., 150., 150., 100., 150., 150., 150., 0., 50., 100., 50., 50., 100., 150.]
    img = np.array([row] * 4)
    from ctseg import segment_image
    from ctseg.sites import initial_sites
    rho = density_map(img)
    r = lloyd_cvt(rho, initial_sites(rho, 24, init="ward"))
    d = np.hypot(*(r.sites[:, None, :] - r.sites[None, :, :]).transpose(2, 0, 1))
    assert d[np.triu_indices(len(r.sites), 1)].min() > 1e-3
    px = np.column_stack([c.ravel() for c in np.mgrid[0:4, 0:14][::-1]]).astype(float)
    assert np.array_equal(r.labels.ravel(), nearest_site(px, r.sites))
    seg = segment_image(img, n_sites=24)  # every site a vertex of the mesh
    assert len(np.unique(seg.triangles)) == len(seg.points)



def test_no_site_left_a_hair_inside_a_border_line():
    # found by hypothesis: a free site whose region is the one pixel (13, 1) of a 4 x 14
    # noise image ended at x = w * 13 / w = 12.999999999999998, and with the border sites
    # (13, 0) and (13, 2) made a flat Delaunay triangle: segment_image raised InputError
    from ctseg import segment_image
    from ctseg.sites import initial_sites
    from ctseg.triangulation import triangle_areas

    img = np.random.default_rng(14).normal(size=(4, 14))
    rho = density_map(img)
    r = lloyd_cvt(rho, initial_sites(rho, 33, init="ward"))
    for axis, value in ((0, 0.0), (0, 13.0), (1, 0.0), (1, 3.0)):
        gap = np.abs(r.sites[:, axis] - value)
        assert not np.any((gap > 0) & (gap < 1e-3))  # on the line or clear of it
    px = np.column_stack([c.ravel() for c in np.mgrid[0:4, 0:14][::-1]]).astype(float)
    assert np.array_equal(r.labels.ravel(), nearest_site(px, r.sites))
    seg = segment_image(img, n_sites=33)
    a = triangle_areas(seg.points, seg.triangles)
    assert np.all(a > 1e-6) and np.isclose(a.sum(), 3 * 13)
    assert len(np.unique(seg.triangles)) == len(seg.points)

def test_threaded_and_serial_kernels_give_the_same_tessellation(monkeypatch):
    """Slice workers run the serial kernels (ctseg._threads.enabled off), a single process
    the threaded ones: the same regions, sites and energies, bit for bit, as each pixel's
    update is its own."""
    from ctseg import _threads

    img, _ = disc_image(70, 3.0)
    rho = density_map(img)
    sites0 = ward_sites(rho, 90)
    runs = []
    for threaded in (True, False):
        monkeypatch.setattr(_threads, "enabled", threaded)
        runs.append(lloyd_cvt(rho, sites0, max_iter=40))
    a, b = runs
    assert np.array_equal(a.labels, b.labels) and np.array_equal(a.sites, b.sites)
    assert a.energy == b.energy and a.n_iter == b.n_iter
