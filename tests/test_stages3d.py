"""3D stages 1-3 (SPEC 9.1-9.3): density volume, initial sites on voxels, voxel CVT."""
import itertools

import numpy as np
import pytest
from scipy.spatial import cKDTree

from ctseg import density_map
from ctseg._assign3d import _assign_3d
from ctseg._cvt3d import _local_drift_3d, _nearest_many_3d, _reassign_3d, _site_grid_3d
from ctseg.cvt3d import CORNER, EDGE, FACE, FREE, _not_coincident, coarse_sites_3d, lloyd_cvt_3d
from ctseg.density import density_volume
from ctseg.errors import InputError, ParameterError
from ctseg.phantoms import make_volume
from ctseg.sites import (INIT_METHODS, density_random_sites_3d, initial_sites_3d,
                         random_sites_3d, ward_agglomerate, ward_block_sides_3d, ward_sites_3d)
from ctseg.tetrahedra import delaunay_tetrahedra, tetra_volumes

from oracles import ward_cost


def voxel_centres(shape, sp):
    kk, jj, ii = np.indices(shape)
    return np.column_stack([ii.ravel() * sp[0], jj.ravel() * sp[1], kk.ravel() * sp[2]])


def box_of(shape, sp):
    return (np.array(shape[::-1]) - 1) * np.asarray(sp, float)


def sphere(sp, extent=24.0, radius=7.0):
    """A ball of physical radius `radius` (partial-volume edge) in a cube of side `extent`."""
    n = [int(round(extent / s)) + 1 for s in sp]
    z, y, x = np.meshgrid(*(np.arange(m) * s for m, s in zip(n[::-1], sp[::-1])), indexing="ij")
    d = np.sqrt((x - extent / 2) ** 2 + (y - extent / 2) ** 2 + (z - extent / 2) ** 2)
    return np.clip(radius - d + 0.5, 0.0, 1.0) * 100.0


# ---- 1. density ------------------------------------------------------------------------

def test_density_volume_is_the_2d_map_on_a_z_constant_volume():
    img = make_volume(4, 40, seed=1).image[2].astype(float)
    rho = density_volume(np.repeat(img[None], 5, axis=0))
    np.testing.assert_allclose(rho, np.repeat(density_map(img)[None], 5, axis=0), atol=1e-12)


def test_density_volume_spacing_belongs_to_its_axis():
    """Transposing the volume and its spacing transposes the density (sigma, gradient and
    ridge window follow each axis's spacing); a uniform change of unit changes nothing."""
    vol = make_volume(12, 24, seed=2).image.astype(float)
    sp = (0.5, 0.7, 1.5)
    rho = density_volume(vol, sp)
    swapped = density_volume(vol.transpose(2, 1, 0), sp[::-1])
    np.testing.assert_allclose(swapped, rho.transpose(2, 1, 0), atol=1e-12)
    np.testing.assert_allclose(density_volume(vol, [3 * s for s in sp]), rho, atol=1e-12)
    # anisotropy matters: the same samples at another spacing give another density
    assert np.abs(density_volume(vol, (1, 1, 1)) - rho).max() > 0.05


def test_density_volume_constant_and_range():
    assert np.all(density_volume(np.full((3, 4, 5), 7.0)) == 0.02)
    rho = density_volume(sphere((1.0, 1.0, 1.0), 16, 5), density_floor=0.1)
    assert rho.min() >= 0.1 and rho.max() <= 1.1 and rho.max() > 0.9


@pytest.mark.parametrize("bad, match", [
    (np.zeros((4, 5)), "3D"), (np.zeros((1, 4, 5)), "at least 2"), (np.zeros((2, 3, 4), object), "real numbers"),
    (np.full((2, 3, 4), np.nan), "NaN"), (np.zeros((2, 3, 4), complex), "real numbers")])
def test_density_volume_bad_volume(bad, match):
    with pytest.raises(InputError, match=match):
        density_volume(bad)


@pytest.mark.parametrize("spacing", [(1, 1), (1, 0, 1), (1, -1, 1), (1, np.nan, 1), "abc"])
def test_density_volume_bad_spacing(spacing):
    with pytest.raises(ParameterError, match="spacing"):
        density_volume(np.zeros((2, 3, 4)), spacing)


# ---- 2. initial sites ------------------------------------------------------------------

def naive_ward_3d(weights, points, edges, k):
    """O(n^3) reference: merge the cheapest adjacent cluster pair until k remain."""
    clusters = [{i} for i in range(len(weights))]
    adj = {frozenset(e) for e in map(tuple, edges)}

    def stats(c):
        idx = sorted(c)
        return weights[idx].sum(), (weights[idx, None] * points[idx]).sum(0) / weights[idx].sum()

    while len(clusters) > k:
        best = None
        for a, b in itertools.combinations(range(len(clusters)), 2):
            if any(frozenset((i, j)) in adj for i in clusters[a] for j in clusters[b]):
                cost = ward_cost(*stats(clusters[a]), *stats(clusters[b]))
                if best is None or cost < best[0]:
                    best = (cost, a, b)
        clusters[best[1]] |= clusters.pop(best[2])
    return sorted(tuple(sorted(c)) for c in clusters)


def test_ward_agglomerate_3d_matches_naive():
    shape, sp = (3, 3, 4), (0.5, 1.0, 2.0)
    rng = np.random.default_rng(0)
    w = rng.uniform(0.1, 2.0, 36)
    ids = np.arange(36).reshape(shape)
    edges = np.concatenate([np.column_stack([a.ravel(), b.ravel()]) for a, b in (
        (ids[:, :, :-1], ids[:, :, 1:]), (ids[:, :-1], ids[:, 1:]), (ids[:-1], ids[1:]))])
    pts = voxel_centres(shape, sp)
    for k in (1, 6, 15):
        labels, _, cc = ward_agglomerate(w, pts, edges, k)
        assert sorted(tuple(np.flatnonzero(labels == c)) for c in range(k)) == \
            naive_ward_3d(w, pts, edges, k)
        for c in range(k):
            m = labels == c
            np.testing.assert_allclose(cc[c], (w[m, None] * pts[m]).sum(0) / w[m].sum())


def test_ward_sites_3d_inside_distinct_and_exact_on_voxels():
    rho = np.random.default_rng(1).uniform(0.1, 1, (6, 9, 11))
    sp = (0.5, 0.5, 1.5)
    s = ward_sites_3d(rho, 40, sp)
    hi = box_of(rho.shape, sp)
    assert s.shape == (40, 3) and np.all(s >= 0) and np.all(s <= hi)
    assert len(np.unique(s, axis=0)) == 40
    # exact Ward with as many clusters as voxels: every voxel centre, physical
    full = ward_sites_3d(rho, rho.size, sp, ward_block_px=1)
    ref = voxel_centres(rho.shape, sp)
    np.testing.assert_allclose(full[np.lexsort(np.round(full, 9).T)], ref[np.lexsort(ref.T)],
                               atol=1e-12)


def test_block_sides_follow_spacing():
    assert ward_block_sides_3d((30, 90, 90), (0.1, 0.1, 0.3), 100, 3) == (1, 3, 3)
    assert ward_block_sides_3d((64, 64, 64), (1, 1, 1), 1000, "auto") == (2, 2, 2)
    # auto: about 16 blocks or more per site
    sides = ward_block_sides_3d((48, 96, 96), (0.1, 0.1, 0.2), 500, None)
    assert np.prod([-(-n // b) for n, b in zip((48, 96, 96), sides)]) >= 16 * 500
    with pytest.raises(ParameterError, match="ward_block_px"):
        ward_block_sides_3d((4, 4, 4), (1, 1, 1), 10, 0)


def test_block_premerge_energy_close_to_exact_ward():
    """Exact voxel Ward is the reference: the block pre-merge's final CVT energy, x n^(2/3)
    (the added box sites make the counts differ), is within 2% on average."""
    rel = []
    for seed in range(6):
        rho = density_volume(make_volume(16, 24, seed=seed).image)
        exact = lloyd_cvt_3d(rho, ward_sites_3d(rho, 60, ward_block_px=1))
        fast = lloyd_cvt_3d(rho, ward_sites_3d(rho, 60))
        e = [r.energy[-1] * len(r.sites) ** (2 / 3) for r in (exact, fast)]
        rel.append(e[1] / e[0] - 1)
    assert ward_block_sides_3d(rho.shape, (1, 1, 1), 60) == (2, 2, 2)  # a real pre-merge
    assert np.mean(rel) < 0.02 and max(rel) < 0.05, rel


def test_random_inits_3d():
    rho = np.full((10, 12, 14), 0.01)
    rho[:, :, :4] = 1.0
    sp = (0.5, 1.0, 2.0)
    for fn in (lambda s: random_sites_3d(rho.shape, 60, sp, seed=s),
               lambda s: density_random_sites_3d(rho, 60, sp, seed=s)):
        a, b, c = fn(4), fn(4), fn(5)
        assert np.array_equal(a, b) and not np.array_equal(a, c)
        assert len(np.unique(a, axis=0)) == 60
        assert np.all(a / sp == np.round(a / sp)) and np.all(a <= box_of(rho.shape, sp))
    assert np.mean(density_random_sites_3d(rho, 200, sp)[:, 0] < 4 * 0.5) > 0.8


def test_initial_sites_3d_dispatch_and_errors():
    rho = np.random.default_rng(3).uniform(0.1, 1, (5, 6, 7))
    assert np.array_equal(initial_sites_3d(rho, 12), ward_sites_3d(rho, 12))
    for init in INIT_METHODS:
        assert initial_sites_3d(rho, 12, (1, 2, 3), init=init, seed=2).shape == (12, 3)
    with pytest.raises(ParameterError, match="init"):
        initial_sites_3d(rho, 12, init="grid")
    for n in (7, 0, 211):
        with pytest.raises(ParameterError, match="n_sites"):
            ward_sites_3d(rho, n)
    with pytest.raises(InputError, match="density"):
        ward_sites_3d(-rho, 12)


# ---- 3. voxel CVT ----------------------------------------------------------------------

CASES = {  # name: (volume, spacing, n_sites, init)
    "ward": (lambda: make_volume(16, 32, seed=0).image, (1.0, 1.0, 1.0), 150, "ward"),
    "aniso": (lambda: make_volume(16, 32, seed=1).image, (0.1, 0.1, 0.3), 200, "density_random"),
    "random": (lambda: make_volume(20, 20, seed=2).image[:, :, :15], (1.0, 2.0, 0.5), 80, "random"),
    "sphere": (lambda: sphere((0.5, 0.5, 1.5)), (0.5, 0.5, 1.5), 150, "ward"),
}


@pytest.fixture(scope="module")
def runs():
    out = {}
    for name, (make, sp, n, init) in CASES.items():
        rho = density_volume(make(), sp)
        out[name] = (rho, sp, lloyd_cvt_3d(rho, initial_sites_3d(rho, n, sp, init=init, seed=1), sp))
    return out


@pytest.mark.parametrize("name", list(CASES))
def test_energy_never_increases_and_is_f(runs, name):
    rho, sp, r = runs[name]
    e = np.array(r.energy)
    assert len(e) == r.n_iter + 1 and e[-1] < e[0]
    assert np.all(np.diff(e) <= 1e-9 * e[0])
    d = voxel_centres(rho.shape, sp) - r.sites[r.labels.ravel()]
    assert np.isclose(e[-1], np.prod(sp) * np.sum(rho.ravel() * np.sum(d * d, axis=1)))


def test_energy_tolerance_stops_where_the_energy_flattens():
    """energy_rtol_3d stops Lloyd at the first iteration that lowers the energy by less
    than that share; 0 runs on to tol_px / max_iter, through the same iterates."""
    make, sp, n, init = CASES["ward"]
    rho = density_volume(make(), sp)
    start = initial_sites_3d(rho, n, sp, init=init, seed=1)
    full = lloyd_cvt_3d(rho, start, sp, energy_rtol_3d=0.0, max_iter=80)
    rtol = 1e-3
    early = lloyd_cvt_3d(rho, start, sp, energy_rtol_3d=rtol, max_iter=80)
    e = np.array(full.energy)
    drops = (e[:-1] - e[1:]) / e[:-1]
    first = int(np.argmax(drops < rtol)) + 1
    assert drops.min() < rtol and early.n_iter == first < full.n_iter
    np.testing.assert_allclose(early.energy, e[:first + 1], rtol=1e-12)


@pytest.mark.parametrize("name", ["ward", "aniso", "random"])
def test_coarse_pass_keeps_the_box_and_lowers_the_energy(name):
    """coarse_sites_3d: distinct sites inside the voxel box, the 8 corners exactly on it,
    the coarse run's face and edge sites exactly on their faces and edges (so the voxel
    Lloyd keeps them as face, edge and corner sites), a lower voxel CVT energy than the start,
    deterministic; a side of fewer than 4 voxels (under 2 blocks) gives the sites back."""
    make, sp, n, init = CASES[name]
    rho = density_volume(make(), sp)
    start = initial_sites_3d(rho, n, sp, init=init, seed=1)
    sites, it = coarse_sites_3d(rho, start, sp)
    hi = box_of(rho.shape, sp)
    assert it > 0 and len(sites) >= n and len(np.unique(sites, axis=0)) == len(sites)
    assert np.all(sites >= 0) and np.all(sites <= hi)
    corners = np.array(list(itertools.product(*[(0.0, h) for h in hi])))
    assert all(np.any(np.all(sites == c, axis=1)) for c in corners)
    on_box = np.any((sites == 0) | (sites == hi), axis=1)
    fine = lloyd_cvt_3d(rho, sites, sp, max_iter=1)
    assert np.all(fine.site_class[:len(sites)][on_box] != FREE)  # kept their classes
    before = lloyd_cvt_3d(rho, start, sp, max_iter=1).energy[0]
    assert fine.energy[0] < before
    again, _ = coarse_sites_3d(rho, start, sp)
    assert np.array_equal(again, sites)
    thin = rho[:3]
    inside = start[start[:, 2] <= 2 * sp[2]]
    same, it0 = coarse_sites_3d(thin, inside, sp)
    assert it0 == 0 and np.array_equal(same, inside)


@pytest.mark.parametrize("name", ["aniso", "random"])
def test_overrelaxed_step_is_w_times_lloyds(name):
    """A free site moves w times Lloyd's step, or Lloyd's step where that would leave the
    box; the energy still never increases, up to w near 2."""
    make, sp, n, init = CASES[name]
    rho = density_volume(make(), sp)
    start = initial_sites_3d(rho, n, sp, init=init, seed=1)
    one = {w: lloyd_cvt_3d(rho, start, sp, max_iter=1, overrelaxation_3d=w) for w in (1.0, 1.9)}
    free = np.flatnonzero(one[1.0].site_class[:n] == 0)
    assert len(one[1.9].sites) == len(one[1.0].sites) and len(free) > 0.5 * n
    lloyd = one[1.0].sites[free] - start[free]
    over = one[1.9].sites[free] - start[free]
    hi = (np.array(rho.shape[::-1]) - 1) * np.array(sp)
    inside = np.all((start[free] + 1.9 * lloyd >= 0) & (start[free] + 1.9 * lloyd <= hi), axis=1)
    assert inside.sum() > 0.5 * len(free)
    np.testing.assert_allclose(over[inside], 1.9 * lloyd[inside], atol=1e-9)
    np.testing.assert_allclose(over[~inside], lloyd[~inside], atol=1e-9)
    for w in (1.0, 1.5, 1.95):
        e = np.array(lloyd_cvt_3d(rho, start, sp, max_iter=40, energy_rtol_3d=0.0,
                                  overrelaxation_3d=w).energy)
        assert np.all(np.diff(e) <= 1e-9 * e[0]) and e[-1] < e[0]


@pytest.mark.parametrize("name", list(CASES))
def test_regions_are_nearest_sites(runs, name):
    rho, sp, r = runs[name]
    pts = voxel_centres(rho.shape, sp)
    d, _ = cKDTree(r.sites).query(pts)
    np.testing.assert_allclose(np.linalg.norm(pts - r.sites[r.labels.ravel()], axis=1), d,
                               atol=1e-12)
    # the incremental updates end where a fresh search does, exact ties included
    assert np.array_equal(r.labels.ravel(), _nearest_many_3d(pts, r.sites))


@pytest.mark.parametrize("name", list(CASES))
def test_corners_faces_edges(runs, name):
    rho, sp, r = runs[name]
    hi = box_of(rho.shape, sp)
    s, cls, feat = r.sites, r.site_class, r.site_feature
    corners = np.array([[bx * hi[0], by * hi[1], bz * hi[2]]
                        for bz, by, bx in itertools.product((0, 1), repeat=3)])
    assert np.sum(cls == CORNER) == 8
    assert np.array_equal(s[cls == CORNER][np.argsort(feat[cls == CORNER])], corners)
    at_lo, at_hi = np.isclose(s, 0, atol=1e-12, rtol=0), np.isclose(s, hi, atol=1e-12, rtol=0)
    on_bound = at_lo | at_hi
    for f in range(6):  # face 2 axis + side: exactly on its plane, strictly inside the face
        axis, side = divmod(f, 2)
        mine = s[(cls == FACE) & (feat == f)]
        assert len(mine) > 0
        assert np.all(mine[:, axis] == side * hi[axis])
        others = [a for a in range(3) if a != axis]
        assert np.all((mine[:, others] > 0) & (mine[:, others] < hi[others]))
    for e in range(12):  # edge 4 axis + 2 side_b + side_c, b < c the fixed axes
        axis, sides = divmod(e, 4)
        fixed = [a for a in range(3) if a != axis]
        mine = s[(cls == EDGE) & (feat == e)]
        assert len(mine) > 0
        for b, side in zip(fixed, divmod(sides, 2)):
            assert np.all(mine[:, b] == side * hi[b])
        assert np.all((mine[:, axis] > 0) & (mine[:, axis] < hi[axis]))
    # the classes agree with the geometry: free sites are inside the box, face sites on
    # one bound, edge sites on two
    assert np.all(on_bound.sum(1)[cls == FACE] == 1) and np.all(on_bound.sum(1)[cls == EDGE] == 2)
    assert np.all(on_bound.sum(1)[cls == FREE] <= 1)


@pytest.mark.parametrize("name", list(CASES))
def test_delaunay_covers_the_box(runs, name):
    rho, sp, r = runs[name]
    hi = box_of(rho.shape, sp)
    mesh = delaunay_tetrahedra(r.sites, hi)  # raises if the tetrahedra miss part of the box
    assert abs(tetra_volumes(mesh.points, mesh.tetrahedra).sum() - np.prod(hi)) <= 1e-9 * np.prod(hi)


def test_anisotropic_spacing_gives_physically_even_sites(runs):
    """The same physical ball at 0.5 x 0.5 x 1.5 and at 0.5 x 0.5 x 0.5: nearest-neighbour
    steps as long along z as along x and y, and as long as in the isotropic case (a CVT in
    index units would make them three times longer along z)."""

    def steps(rho, sp, r):
        free = r.site_class == FREE
        d, k = cKDTree(r.sites).query(r.sites[free], k=2)
        return np.abs(r.sites[k[:, 1]] - r.sites[free]).mean(axis=0), d[:, 1].mean()

    iso_sp = (0.5, 0.5, 0.5)
    rho = density_volume(sphere(iso_sp), iso_sp)
    iso = steps(rho, iso_sp, lloyd_cvt_3d(rho, ward_sites_3d(rho, 150, iso_sp), iso_sp))
    aniso = steps(*runs["sphere"])
    for axis_steps, _ in (iso, aniso):
        assert 0.75 < axis_steps[2] / axis_steps[:2].mean() < 1.33
    assert abs(aniso[1] / iso[1] - 1) < 0.15


def test_deterministic():
    rho = density_volume(make_volume(10, 20, seed=4).image, (1, 1, 2))
    a, b = (lloyd_cvt_3d(rho, density_random_sites_3d(rho, 50, (1, 1, 2), seed=7), (1, 1, 2))
            for _ in range(2))
    assert np.array_equal(a.sites, b.sites) and np.array_equal(a.labels, b.labels)
    assert a.energy == b.energy


@pytest.mark.parametrize("layout", ["uniform", "integer"])
def test_nearest_site_kernel_matches_brute_force(layout):
    rng = np.random.default_rng(0)
    if layout == "uniform":
        sites, pts = rng.uniform(0, 20, (80, 3)), rng.uniform(0, 20, (2000, 3))
    else:  # voxel-centre sites and points: many exact ties
        sites = np.unique(rng.choice(11, (60, 3)).astype(float), axis=0)
        pts = rng.choice(11, (2000, 3)).astype(float)
    d = np.sqrt(((pts[:, None] - sites[None]) ** 2).sum(-1))
    assert np.array_equal(_nearest_many_3d(pts, sites), np.argmin(d, axis=1))


@pytest.mark.parametrize("layout", ["uniform", "clustered", "ties", "one", "two", "three"])
def test_full_assignment_matches_brute_force(layout):
    """The block-by-block search of every voxel's three nearest sites against all the
    distances sorted by (distance, index): nearest and second exactly (ties to the lower
    index), u, l2 and l3 bounds within float32 rounding. Clustered sites leave blocks far
    from any site; anisotropic spacing makes the blocks unequal along the axes."""
    shape, sp = (13, 17, 21), np.array([1.0, 0.6, 1.7])
    hi = box_of(shape, sp)
    rng = np.random.default_rng(5)
    n = {"one": 1, "two": 2, "three": 3}.get(layout, 120)
    sites = rng.uniform(0, 1, (n, 3)) * hi
    if layout == "clustered":
        sites = np.clip(hi * 0.2 + rng.normal(0, 1.0, (n, 3)), 0, hi)
    if layout == "ties":  # half-voxel positions: many voxels equidistant from two sites
        sites = np.clip(np.round(sites / (0.5 * sp)) * (0.5 * sp), 0, hi)
    sites = np.unique(sites, axis=0)
    labels, second, u, l2, l3 = arrays = kernel_state(int(np.prod(shape)))
    _assign_3d(*shape, *sp, sites, *arrays)
    c = voxel_centres(shape, sp)
    sq = ((c[:, None, :] - sites[None]) ** 2).sum(-1)  # squared, as the kernel compares them
    order = np.lexsort((np.broadcast_to(np.arange(len(sites)), sq.shape), sq), axis=1)
    d = np.sqrt(sq)
    assert np.array_equal(labels, order[:, 0])
    # sorted distances, inf where there are fewer than three sites
    ds = np.hstack([np.take_along_axis(d, order, axis=1), np.full((len(c), 2), np.inf)])
    d2, d3 = ds[:, 1], ds[:, 2]
    if len(sites) > 1:
        assert np.array_equal(second, order[:, 1])
    for bound, exact, up in ((u, ds[:, 0], True), (l2, d2, False), (l3, d3, False)):
        b = bound.astype(np.float64)
        assert np.all(b >= exact) if up else np.all(b <= exact)
        fin = np.isfinite(exact)
        assert np.array_equal(np.isfinite(b), fin)
        assert np.allclose(b[fin], exact[fin], rtol=1e-6, atol=1e-6)


def test_cvt_rejects_bad_input():
    rho = np.ones((4, 5, 6))
    good = ward_sites_3d(rho, 10)
    with pytest.raises(InputError, match="density"):
        lloyd_cvt_3d(np.ones((4, 5)), good)
    with pytest.raises(InputError, match="inside the box"):
        lloyd_cvt_3d(rho, good + [0, 0, 10])
    with pytest.raises(InputError, match="coincide"):
        lloyd_cvt_3d(rho, np.vstack([good, good[:1]]))
    with pytest.raises(InputError, match=r"\(n, 3\)"):
        lloyd_cvt_3d(rho, good[:, :2])
    with pytest.raises(ParameterError, match="n_sites"):
        lloyd_cvt_3d(rho, good[:7])
    with pytest.raises(ParameterError, match="spacing"):
        lloyd_cvt_3d(rho, good, spacing=(1, 1, 0))
    with pytest.raises(ParameterError, match="tol_px"):
        lloyd_cvt_3d(rho, good, tol_px=0)


def test_progress_and_max_iter():
    rho = density_volume(sphere((1.0, 1.0, 1.0), 12, 4))
    calls = []
    r = lloyd_cvt_3d(rho, random_sites_3d(rho.shape, 30, seed=0), max_iter=3,
                     progress=lambda i, n: calls.append((i, n)))
    assert r.n_iter == 3 and not r.converged and calls == [(1, 3), (2, 3), (3, 3)]


def test_coincident_sites_removed_by_class():
    sites = np.array([[0, 0, 0], [1e-9, 0, 0], [5, 5, 5], [5, 5, 5 + 1e-8], [2, 0, 3],
                      [2, 1e-9, 3]], float)
    cls = np.array([CORNER, FREE, FREE, FREE, FACE, EDGE])
    assert _not_coincident(sites, cls, 1e-6).tolist() == [True, False, True, False, False, True]


def test_border_sites_added_per_region_and_feature():
    """Two free sites in a uniform cube: each face and edge region of a start site gets a
    site of its own there (faces y and z are shared by both regions: two sites each);
    the edges, held only by corner regions, get one each."""
    corners = np.array([[x, y, z] for z in (0, 5) for y in (0, 5) for x in (0, 5)], float)
    start = np.vstack([corners, [[1.5, 2.5, 2.5], [3.5, 2.5, 2.5]]])
    r = lloyd_cvt_3d(np.ones((6, 6, 6)), start, max_iter=1)
    assert np.bincount(r.site_feature[r.site_class == FACE], minlength=6).tolist() == [1, 1, 2, 2, 2, 2]
    assert np.bincount(r.site_feature[r.site_class == EDGE], minlength=12).tolist() == [1] * 12
    assert np.array_equal(r.sites[:8], corners) and np.all(r.site_class[8:10] == FREE)
    assert np.sum(r.site_class == FREE) == 2 and len(r.sites) == 8 + 2 + 10 + 12


def kernel_state(size):
    """The kernels' per-voxel arrays, of the types lloyd_cvt_3d gives them."""
    return ([np.empty(size, np.int32), np.empty(size, np.int32)]
            + [np.empty(size, np.float32) for _ in range(3)])


@pytest.mark.parametrize("reach", [1, 3])
def test_local_drift_is_the_largest_drift_in_the_cell_box(reach):
    """The per-cell drift bound of the incremental assignment: for every grid cell, the
    largest drift of the sites that started within ``reach`` cells (Chebyshev), against
    scipy's maximum filter over the cells' own largest drifts."""
    from scipy.ndimage import maximum_filter

    rng = np.random.default_rng(reach)
    for n, ext in ((7, (3.0, 40.0, 9.0)), (400, (30.0, 20.0, 25.0)), (2500, (10.0, 60.0, 60.0))):
        sites = rng.uniform(0, 1, (n, 3)) * ext
        drift = rng.exponential(0.2, n) * (rng.uniform(size=n) < 0.6)
        h, gx, gy, gz, _, _, _ = _site_grid_3d(sites, *ext)
        cell = np.minimum((sites / h).astype(int), [gx - 1, gy - 1, gz - 1])
        top = np.zeros((gz, gy, gx))
        np.maximum.at(top, (cell[:, 2], cell[:, 1], cell[:, 0]), drift)
        want = maximum_filter(top, size=2 * reach + 1, mode="constant", cval=0.0)
        got = _local_drift_3d(sites, drift, h, gx, gy, gz, reach).reshape(gz, gy, gx)
        assert np.array_equal(got, want)


@pytest.mark.parametrize("ties", [False, True])
def test_incremental_assignment_matches_a_fresh_one(ties):
    """The bounds kernel against a full search, over chains of moves: drifts, pauses, a few
    sites jumping across the box (the far-site margin), and half-voxel positions (ties)."""
    shape, sp = (9, 12, 14), np.array([1.0, 0.5, 2.0])
    hi, half = box_of(shape, sp), 0.5 * sp
    size = int(np.prod(shape))
    rng = np.random.default_rng(1)

    def snap(p):
        return np.clip(np.round(p / half) * half if ties else p, 0, hi)

    sites = np.unique(snap(rng.uniform(0, 1, (40, 3)) * hi), axis=0)
    arrays = kernel_state(size)
    _assign_3d(*shape, *sp, sites, *arrays)
    fresh = [np.empty_like(a) for a in arrays]
    for step in range(12):
        new = sites + rng.normal(0, 0.3, sites.shape) * (step % 3 != 2)
        new[rng.choice(len(sites), 3, replace=False)] = rng.uniform(0, 1, (3, 3)) * hi
        new = snap(new)
        if len(np.unique(new, axis=0)) < len(new):
            continue
        _reassign_3d(*shape, *sp, sites, new, np.linalg.norm(new - sites, axis=1), *arrays)
        sites = np.ascontiguousarray(new)
        _assign_3d(*shape, *sp, sites, *fresh)
        assert np.array_equal(arrays[0], fresh[0]), step


def test_incremental_assignment_gives_an_exact_tie_to_the_lower_index():
    """Site 0 moves to tie with site 1 at voxel x = 1: the voxel goes to site 0, as a search
    would give it (a bound equal to the distance is a failed bound)."""
    shape, sp = (2, 2, 4), (1.0, 1.0, 1.0)
    old = np.array([[3.0, 0, 0], [0, 0, 0], [3, 1, 1]])
    new = np.array([[2.0, 0, 0], [0, 0, 0], [3, 1, 1]])
    arrays = kernel_state(16)
    _assign_3d(*shape, *sp, old, *arrays)
    assert arrays[0][1] == 1
    _reassign_3d(*shape, *sp, old, new, np.linalg.norm(new - old, axis=1), *arrays)
    assert arrays[0][1] == 0 and np.array_equal(arrays[0], _nearest_many_3d(voxel_centres(shape, sp), new))


def test_float32_bounds_are_rounded_outwards():
    """The kernels store u, l2, l3 as float32, rounded outwards: still bounds of the
    float64 distances they stand for (u above the nearest, l2 below the second)."""
    shape, sp = (7, 9, 11), np.array([0.7, 1.3, 1.0])
    sites = np.random.default_rng(3).uniform(0, 1, (30, 3)) * box_of(shape, sp)
    arrays = kernel_state(int(np.prod(shape)))
    _assign_3d(*shape, *sp, sites, *arrays)
    labels, second, u, l2, l3 = arrays
    c = voxel_centres(shape, sp)
    d1 = np.linalg.norm(c - sites[labels], axis=1)
    d2 = np.linalg.norm(c - sites[second], axis=1)
    assert np.all(u.astype(np.float64) >= d1) and np.all(l2.astype(np.float64) <= d2)
    assert np.all(l3 >= l2)
