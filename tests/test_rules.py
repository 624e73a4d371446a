"""Every term of the graph cut and every rule of the recursive cut and of the partial-volume
labelling pinned by a test that fails when it is removed or altered (issue 15 item 6).

Each test builds a small input on which the term or rule changes the outcome, and asserts
the outcome with it. The comment above each test names the source mutation it was checked
against (the mutation was applied, the test failed, the source was restored).
"""
import itertools

import numpy as np

from ctseg.graphcut import graphcut_capacities, graphcut_split
from ctseg.partial_volume import label_partial_volume_leaves, partial_volume_elements
from ctseg.recursive_cut import (interior_triangles, order_by_gray, segment_triangles,
                                 step_noise)

LAM, BETA, EPS = 70.0, 0.286, 1.0  # SPEC 6 defaults, written out (not read from ctseg)


def chain(gray, area=10.0):
    """A 1D chain of elements: gray, area, adjacent pairs, barycentres on the x axis."""
    g = np.asarray(gray, float)
    n = len(g)
    area = np.broadcast_to(np.asarray(area, float), (n,)).copy()
    pairs = np.column_stack([np.arange(n - 1), np.arange(1, n)])
    cent = np.column_stack([np.arange(n, dtype=float), np.zeros(n)])
    return g, area, pairs, cent


def segment_chain(gray, area=10.0, **kw):
    g, a, p, c = chain(gray, area)
    return segment_triangles(g, a, p, c, **kw)


# ---------------------------------------------------------------------------------------
# SPEC 6: the graph cut's terms


def spec6_energies(f, edges, cent, lam=LAM, beta=BETA, eps=EPS, theta=None, data_term=True):
    """Every labelling of ``f`` that respects the seed sets, with its SPEC 6 energy, written
    from SPEC 6's text (independent of ctseg.graphcut)."""
    f = np.asarray(f, float)
    edges = np.asarray(edges)
    s0, s1 = int(np.argmin(f)), int(np.argmax(f))
    if theta is None:
        theta = 0.1 * (f[s1] - f[s0])
    d0, d1 = np.abs(f - f[s0]), np.abs(f - f[s1])
    v0 = d0 <= theta
    v1 = (d1 <= theta) & ~v0
    labs = np.array(list(itertools.product([0, 1], repeat=len(f))))
    labs = labs[np.all(labs[:, v0] == 0, axis=1) & np.all(labs[:, v1] == 1, axis=1)]
    energy = np.zeros(len(labs))
    if data_term:
        for t in np.flatnonzero(~(v0 | v1)):
            cap_s0 = 1 - d0[t] / (d0[t] + d1[t])  # cut when t is on the sink side (label 1)
            cap_s1 = 1 - d1[t] / (d0[t] + d1[t])  # cut when t is on the source side (label 0)
            energy += np.where(labs[:, t] == 1, cap_s0, cap_s1)
    dist = np.hypot(*(cent[edges[:, 0]] - cent[edges[:, 1]]).T)
    w = lam * (1 / (np.abs(f[edges[:, 0]] - f[edges[:, 1]]) + eps) + beta * dist / (dist + dist.mean()))
    energy += ((labs[:, edges[:, 0]] != labs[:, edges[:, 1]]) * w).sum(axis=1)
    return labs, energy


# Five triangles of a hand-built mesh; vertices
#   0 (0,0)  1 (4,0)  2 (4,4)  3 (0,4)  4 (8,0)  5 (8,4)  6 (-4,2)
# T0 = (0,1,2), T1 = (0,2,3), T2 = (1,4,2), T3 = (4,5,2), T4 = (0,3,6); adjacent pairs
# T0-T1 (edge 0-2), T0-T2 (edge 1-2), T2-T3 (edge 2-4), T1-T4 (edge 0-3).
TRI_POINTS = np.array([[0, 0], [4, 0], [4, 4], [0, 4], [8, 0], [8, 4], [-4, 2]], float)
TRI = np.array([[0, 1, 2], [0, 2, 3], [1, 4, 2], [4, 5, 2], [0, 3, 6]])
TRI_EDGES = np.array([[0, 1], [0, 2], [2, 3], [1, 4]])
TRI_GRAY = np.array([70.0, 10.0, 180.0, 250.0, 30.0])
# barycentres by hand: T0 (8/3, 4/3), T1 (4/3, 8/3), T2 (16/3, 4/3), T3 (20/3, 8/3), T4 (-4/3, 2)
TRI_CENT = np.array([[8, 4], [4, 8], [16, 4], [20, 8], [-4, 6]], float) / 3.0
# barycentre distances of the pairs, by hand: 4 sqrt2/3, 8/3, 4 sqrt2/3, sqrt68/3
TRI_DIST = np.array([4 * np.sqrt(2), 8, 4 * np.sqrt(2), np.sqrt(68)]) / 3.0
TRI_SHARED_LEN = np.array([4 * np.sqrt(2), 4.0, 4 * np.sqrt(2), 4.0])
TRI_DGRAY = np.array([60.0, 110.0, 70.0, 20.0])


def test_hand_built_mesh_matches_its_constants():
    """The literal barycentres and distances above are those of the mesh (guards the data)."""
    np.testing.assert_allclose(TRI_POINTS[TRI].mean(axis=1), TRI_CENT)
    np.testing.assert_allclose(np.hypot(*(TRI_CENT[TRI_EDGES[:, 0]] - TRI_CENT[TRI_EDGES[:, 1]]).T),
                               TRI_DIST)


# Mutations caught: cap(t, s0) from d1 instead of d0 (`src = ... 1.0 - d1 / tot`, the
# data term gone); cap(t, s1) from d0; both swapped; t-links of free triangles set to 0;
# seed sets not widened by theta (`in0 = d0 <= 0`); theta auto 20% instead of 10% of the
# range; n-link without its gray term, without its distance term, or with 2 x eps; the
# edge-length option ignored (`w = w * 1.0`).
def test_capacities_on_a_hand_built_mesh_follow_spec6():
    caps = graphcut_capacities(TRI_GRAY, TRI_EDGES, TRI_CENT)
    assert caps.seeds == (1, 3)  # darkest T1 (10), brightest T3 (250)
    # theta = 10% of 240 = 24: V0 = {T1, T4 (d0 = 20)}, V1 = {T3}, Vf = {T0, T2}
    inf = caps.inf_cap
    np.testing.assert_array_equal(caps.source_cap[[1, 4, 3]], [inf, inf, 0.0])
    np.testing.assert_array_equal(caps.sink_cap[[1, 4, 3]], [0.0, 0.0, inf])
    # T0 = 70: d0 = 60, d1 = 180 -> cap(t,s0) = 1 - 60/240 = 0.75, cap(t,s1) = 1 - 180/240
    # T2 = 180: d0 = 170, d1 = 70 -> 1 - 170/240 and 1 - 70/240 (asymmetric: the data term)
    np.testing.assert_allclose(caps.source_cap[[0, 2]], [0.75, 70.0 / 240.0], rtol=1e-12)
    np.testing.assert_allclose(caps.sink_cap[[0, 2]], [0.25, 170.0 / 240.0], rtol=1e-12)
    dbar = TRI_DIST.mean()
    n_link = LAM * (1.0 / (TRI_DGRAY + EPS) + BETA * TRI_DIST / (TRI_DIST + dbar))
    np.testing.assert_allclose(caps.edge_cap, n_link, rtol=1e-12)
    # the documented option: n-links times the shared edge length
    caps_len = graphcut_capacities(TRI_GRAY, TRI_EDGES, TRI_CENT, edge_length=TRI_SHARED_LEN)
    np.testing.assert_allclose(caps_len.edge_cap, n_link * TRI_SHARED_LEN, rtol=1e-12)
    # theta auto is 10% of the range: T4 at 36 (d0 = 26 > 24) is free, at 30 it is in V0
    caps36 = graphcut_capacities(np.r_[TRI_GRAY[:4], 36.0], TRI_EDGES, TRI_CENT)
    np.testing.assert_allclose([caps36.source_cap[4], caps36.sink_cap[4]],
                               [1 - 26.0 / 240.0, 1 - 214.0 / 240.0], rtol=1e-12)
    # an explicit theta of 65 puts T0 (d0 = 60) in V0 and leaves T2 (d1 = 70) free
    caps65 = graphcut_capacities(TRI_GRAY, TRI_EDGES, TRI_CENT, theta_255=65.0)
    assert caps65.source_cap[0] == caps65.inf_cap and caps65.sink_cap[0] == 0.0
    np.testing.assert_allclose([caps65.source_cap[2], caps65.sink_cap[2]],
                               [70.0 / 240.0, 170.0 / 240.0], rtol=1e-12)


# Mutations caught: cap(t, s0) from d1 instead of d0 (data term gone: column 2 goes dark);
# the two t-links of free triangles swapped (data term inverted).
def test_data_term_changes_the_cut_at_default_parameters():
    # a 3 x 4 grid, dark left, bright right, a noisy middle; default lambda, beta, theta
    rows, cols = 3, 4
    idx = np.arange(rows * cols).reshape(rows, cols)
    edges = np.r_[np.c_[idx[:, :-1].ravel(), idx[:, 1:].ravel()],
                  np.c_[idx[:-1].ravel(), idx[1:].ravel()]]
    yy, xx = np.mgrid[0:rows, 0:cols]
    cent = np.c_[xx.ravel(), yy.ravel()].astype(float)
    f = np.array([10, 112, 149, 241,
                  8, 60, 162, 250,
                  8, 75, 180, 246], float)
    labs, energy = spec6_energies(f, edges, cent)
    best = labs[np.argmin(energy)]
    assert np.sort(energy)[1] - energy.min() > 0.2  # a unique minimum, by a margin
    expected = np.tile([0, 0, 1, 1], 3)
    assert best.tolist() == expected.tolist()
    # without the data term the minimum is elsewhere: the term decides column 2
    labs_nd, energy_nd = spec6_energies(f, edges, cent, data_term=False)
    assert labs_nd[np.argmin(energy_nd)].tolist() == np.tile([0, 0, 0, 1], 3).tolist()
    labels, flow = graphcut_split(f, edges, cent)
    assert labels.tolist() == expected.tolist()
    assert np.isclose(flow, energy.min(), rtol=1e-9)


# Mutations caught: cap(t, s0) from d1 instead of d0; the t-links swapped.
def test_data_term_decides_a_free_triangle_between_equal_neighbour_links():
    # 0 - 25 - 139 - 255: theta 25.5 puts 25 in V0; 139 has nearly equal n-links to both
    # sides (gray steps 114 and 116) and is nearer s1 (d1 = 116 < d0 = 139): the data term
    # sends it to the sink side; by n-links alone it would join the source side
    f = [0.0, 25.0, 139.0, 255.0]
    edges, cent = [[0, 1], [1, 2], [2, 3]], [[0, 0], [1, 0], [2, 0], [3, 0]]
    labels, _ = graphcut_split(f, edges, cent)
    assert labels.tolist() == [0, 0, 1, 1]
    labs_nd, energy_nd = spec6_energies(np.array(f), np.array(edges), np.array(cent, float),
                                        data_term=False)
    assert labs_nd[np.argmin(energy_nd)].tolist() == [0, 0, 0, 1]


# Mutations caught: cap(t, s0) from d1 instead of d0; the distance term of the n-links
# removed; eps changed; theta's sets removed (every brute-force minimum checked).
def test_min_cut_minimises_the_spec6_energy_with_a_small_lambda():
    # lambda = 5: the data term weighs as much as the n-links
    rng = np.random.default_rng(4)
    for _ in range(3):
        f = np.clip(np.tile([10.0, 100.0, 160.0, 245.0], 3)
                    + rng.normal(0, 40, 12) * np.tile([0.1, 1, 1, 0.1], 3), 0, 255)
        idx = np.arange(12).reshape(3, 4)
        edges = np.r_[np.c_[idx[:, :-1].ravel(), idx[:, 1:].ravel()],
                      np.c_[idx[:-1].ravel(), idx[1:].ravel()]]
        cent = rng.uniform(0, 4, (12, 2))
        labs, energy = spec6_energies(f, edges, cent, lam=5.0)
        labels, flow = graphcut_split(f, edges, cent, lam=5.0)
        assert np.isclose(flow, energy.min(), rtol=1e-9)
        if np.sort(energy)[1] - energy.min() > 1e-6:
            assert labels.tolist() == labs[np.argmin(energy)].tolist()


# ---------------------------------------------------------------------------------------
# SPEC 7: the recursive cut (ctseg.recursive_cut)


# Mutation caught: `(mass >= min_pocket)` -> `(mass > 0)` in the split test (a pocket
# below min_pocket_area then starts a cut and becomes a material of its own).
def test_a_pocket_below_min_pocket_area_does_not_start_a_cut():
    g = [20] * 5 + [200] + [20] * 5
    a = [10] * 5 + [1] + [10] * 5  # the bright pocket: 1 px^2 < min_pocket_area = 4
    seg = segment_chain(g, a, levels=[20, 200])
    assert seg.graphcut_calls == 0
    assert seg.material.tolist() == [0] * 11 and seg.mode_gray.tolist() == [20.0]
    # with a pocket of 4 px^2 the cut runs and the pocket is a material
    seg4 = segment_chain(g, [10] * 5 + [4] + [10] * 5, levels=[20, 200])
    assert seg4.graphcut_calls >= 1 and seg4.material.tolist() == [0] * 5 + [1] + [0] * 5


# Mutation caught: `len(comp) < max(2, min_triangles)` -> `len(comp) < 2`.
def test_min_triangles_stops_the_split():
    g = [20] * 7 + [200] * 5
    assert segment_chain(g, levels=[20, 200]).material.tolist() == [0] * 7 + [1] * 5
    seg = segment_chain(g, levels=[20, 200], min_triangles=13)
    assert seg.graphcut_calls == 0 and seg.material.tolist() == [0] * 12


# Mutation caught: `or depth >= max_depth` removed from the stop test.
def test_max_depth_stops_the_split():
    g = [20] * 4 + [110] * 4 + [200] * 4
    seg = segment_chain(g, levels=[20, 110, 200], max_depth=1)
    # one cut: dark against bright; the middle goes with one side and is not split off
    assert seg.graphcut_calls == 1 and seg.max_depth_reached == 1
    assert len(seg.mode_gray) == 2
    assert len(segment_chain(g, levels=[20, 110, 200]).mode_gray) == 3
    assert segment_chain(g, levels=[20, 110, 200], max_depth=0).graphcut_calls == 0


# Mutation caught: `if imass.max() >= min_pocket:` -> `if False:` (leaves no longer take
# the material holding most of their interior area; the whole leaf then goes by its mean
# gray, 149, to the bright level).
def test_a_leaf_takes_the_material_of_most_of_its_interior_area():
    g = [20] * 5 + [200] * 7
    a = [10] * 5 + [8] + [20] * 6
    interior = np.array([True] * 6 + [False] * 6)  # interior: 50 px^2 dark, 8 px^2 bright
    seg = segment_chain(g, a, levels=[20, 200], max_depth=0, interior=interior)
    assert seg.mode_gray.tolist() == [20.0] and np.all(seg.material == 0)


# Mutation caught: `elif len(present) == 1 and area[comp].sum() >= min_layer_area:` ->
# `elif False:` (the thin-layer rule off: the leaf, without interior area, goes by its
# mean gray 162 to level 200).
def test_a_thin_layer_without_interior_is_the_material_of_its_core():
    g = [110] * 6 + [175] * 4 + [110]
    a = [10] * 6 + [60] * 4 + [1]
    interior = np.array([False] * 10 + [True])  # 1 px^2 of interior: below min_pocket_area
    kw = dict(levels=[20, 110, 200], min_material_area=10, interior=interior)
    assert segment_chain(g, a, **kw).mode_gray.tolist() == [110.0]
    # the documented switch that turns the rule off
    assert segment_chain(g, a, thin_layers=False, **kw).mode_gray.tolist() == [200.0]


# Mutation caught: `seeds=(in_comp[s0], in_comp[s1])` -> `seeds=None` (the paper's
# darkest/brightest elements: the first cut then cuts off the bright speck alone).
def test_seeds_are_core_elements_not_the_extreme_speck():
    g = [20] * 3 + [255] + [20] * 3 + [120] * 6
    a = [10] * 3 + [1] + [10] * 3 + [10] * 6
    seg = segment_chain(g, a, levels=[20, 120], max_depth=1)
    assert seg.graphcut_calls == 1
    assert seg.material.tolist() == [0] * 7 + [1] * 6


# Mutation caught: connected pieces replaced by the two sides of the cut
# (`n_pieces, piece = connected_pieces(...)` -> `n_pieces, piece = 2, labels.astype(np.int64)`):
# the speck of gray 35 inside the bright region, pulled to the dark side by the seed set
# of eq. 8, is then absorbed into the dark leaf instead of being judged alone.
def test_each_side_of_a_cut_recurses_as_its_connected_pieces():
    g = [20] * 5 + [200] * 3 + [35] + [200] * 3
    a = [10] * 8 + [2] + [10] * 3
    interior = np.array([True] * 8 + [False] + [True] * 3)
    seg = segment_chain(g, a, levels=[20, 35, 200], interior=interior)
    assert seg.material.tolist() == [0] * 5 + [2] * 3 + [1] + [2] * 3


# Mutations caught: the step threshold's rule `max(4.0 * s, 2.0)` -> `max(3.0 * s, 2.0)`
# or `4.0 * s`; step_noise using every pair (`if sel.sum() >= 10:` -> never).
def test_step_threshold_is_four_step_noise_of_large_element_pairs_at_least_2():
    rng = np.random.default_rng(1)
    big = 20 + rng.normal(0, 2.0, 30)
    small = 20 + rng.normal(0, 30.0, 12)  # small elements along a boundary: large steps
    g = np.r_[big, small]
    a = np.r_[np.full(30, 10.0), np.full(12, 1.0)]
    gg, aa, pairs, cent = chain(g, a)
    # independent: 1.4826 MAD of the steps between pairs of elements >= the median area
    keep = (aa[pairs[:, 0]] >= np.median(aa)) & (aa[pairs[:, 1]] >= np.median(aa))
    d = np.diff(big)
    assert keep.sum() == 29 and np.allclose(gg[pairs[keep, 0]] - gg[pairs[keep, 1]], -d)
    s = 1.4826 * np.median(np.abs(d - np.median(d)))
    assert np.isclose(step_noise(gg, pairs, aa), s)
    seg = segment_triangles(gg, aa, pairs, cent, levels=[20.0])
    assert np.isclose(seg.step_noise, s) and np.isclose(seg.step_threshold, 4 * s)
    assert 4 * s > 2.0
    # noise-free: the floor of 2
    assert segment_chain([20.0] * 6 + [200.0] * 6, levels=[20, 200]).step_threshold == 2.0


# Mutation caught: `return step <= step_threshold + rel * f` -> `return step <= step_threshold`.
def test_interior_step_allows_a_gray_proportional_part():
    g, _, pairs, _ = chain([200, 210, 200, 20, 30, 20])
    assert interior_triangles(g, pairs, 5.0).tolist() == [False] * 6
    # 10 <= 5 + 0.1 * 200: the bright elements are interior, the dark ones are not
    assert interior_triangles(g, pairs, 5.0, rel=0.1).tolist() == [True, True, False, False, False, False]


# Mutation caught: the level separation without its gray-proportional term
# (`separation = lambda level: base + merge_rel * level` -> `lambda level: base`).
def test_level_separation_grows_with_gray():
    rng = np.random.default_rng(0)
    g = np.r_[200 + rng.normal(0, 0.5, 60), 215 + rng.normal(0, 0.5, 60)]
    # 15 gray apart: more than max(2, 5 sigma) but less than that + 0.2 x 200 = one material
    assert len(segment_chain(g).mode_gray) == 1
    assert len(segment_chain(g, merge_rel=0.0).mode_gray) == 2


# Mutations caught: the min_material_area default `max(16.0, 1e-3 * area.sum())` with 16
# -> 1, or with 1e-3 -> 1e-4.
def test_min_material_area_default():
    # a bright pocket of 4 elements (its 2 inner ones interior): 12 px^2 < 16
    g = [20.0] * 15 + [200.0] * 4 + [20.0] * 15
    a = [10.0] * 15 + [6.0] * 4 + [10.0] * 15
    assert len(segment_chain(g, a).mode_gray) == 1
    assert len(segment_chain(g, a, min_material_area=10.0).mode_gray) == 2
    # large images: 0.1% of the area; the pocket's 2 x 60 px^2 < 0.1% of 150 000
    a2 = [5000.0] * 15 + [60.0] * 4 + [5000.0] * 15
    assert len(segment_chain(g, a2).mode_gray) == 1
    assert len(segment_chain(g, a2, min_material_area=100.0).mode_gray) == 2


# Mutation caught: `order = np.argsort(mean, kind="stable")` -> `order = np.arange(k)`.
def test_materials_are_numbered_by_ascending_gray():
    mat, mean, old = order_by_gray(np.array([0, 0, 1, 1, 2]), np.array([200.0, 200, 20, 20, 90]),
                                   np.ones(5))
    assert mat.tolist() == [2, 2, 0, 0, 1] and mean.tolist() == [20, 90, 200]
    assert old.tolist() == [1, 2, 0]


# Mutations caught (ctseg/labelling.py): fixed levels numbered by level index
# (`material = np.searchsorted(levels, seg.mode_gray)[seg.material]` -> `material = seg.material`);
# also the element sweep not called in segment_triangles
# (`material = partial_volume_elements(...)` -> `material = material`).
def test_fixed_levels_number_materials_by_level():
    from ctseg import delaunay_mesh, triangle_gray
    from ctseg.labelling import label_mesh
    img = np.zeros((24, 24))
    img[:, 12:] = 100.0
    ys, xs = np.mgrid[0:24:4, 0:24:4]
    mesh = delaunay_mesh(np.column_stack([xs.ravel(), ys.ravel()]).astype(float))
    lab = label_mesh(img, mesh, triangle_gray(img, mesh.points, mesh.triangles),
                     levels_255=[0.0, 128.0, 255.0])
    assert set(lab.material.tolist()) == {0, 2}  # the middle level holds nothing


# Mutation caught (the call, not the function): `interior_triangles(f, adjacency,
# step_threshold, 0.5 * merge_rel)` -> `(..., 0.0)` in segment_triangles.
def test_bright_noisy_elements_are_interior_through_the_gray_proportional_step():
    # one leaf (max_depth 0): dark 50 px^2 interior; bright 185/200 alternating (steps of
    # 15 > the step threshold 2, but <= 2 + 0.1 x gray): 60 px^2 interior, so bright wins
    g = [20] * 5 + [185, 200] * 3
    a = [10] * 5 + [12] * 6
    kw = dict(levels=[20, 200], max_depth=0, step_threshold_255=2.0)
    assert segment_chain(g, a, **kw).mode_gray.tolist() == [200.0]
    assert segment_chain(g, a, merge_rel=0.0, **kw).mode_gray.tolist() == [20.0]


# Mutation caught: `if not interior.any():` -> `if False:` (no interior element: every
# element counts as interior, and the leaf takes the material of most of its area rather
# than the level nearest its mean gray, 96).
def test_without_interior_elements_every_element_counts_as_interior():
    g, a = [20] * 5 + [160] * 6, 10.0
    for interior in (np.zeros(11, bool), np.ones(11, bool)):
        seg = segment_chain(g, a, levels=[20, 200], max_depth=0, interior=interior)
        assert seg.mode_gray.tolist() == [200.0]


def grid(rows, cols):
    idx = np.arange(rows * cols).reshape(rows, cols)
    edges = np.r_[np.c_[idx[:, :-1].ravel(), idx[:, 1:].ravel()],
                  np.c_[idx[:-1].ravel(), idx[1:].ravel()]]
    yy, xx = np.mgrid[0:rows, 0:cols]
    return edges, np.c_[xx.ravel(), yy.ravel()].astype(float)


# Mutation caught: the call of label_fragmented_layers removed from _recursive_split
# (the function itself is pinned by test_materials.py).
def test_a_thin_layer_chopped_by_the_cuts_is_one_material():
    # columns dark | layer | bright, 6 rows; the layer (no interior, 4 px^2 per element)
    # alternates 90 / 132, both in the core of level 110. With lambda 1 and beta 0 the data
    # term sends the 90s to the dark side and the 132s to the bright side: six one-element
    # leaves (4 < min_material_area = 5), each between dark and bright; together 24 px^2
    # >= 4 x 5, all in the 110 core: a layer of 110. Alone each would join dark or bright.
    rows = 6
    edges, cent = grid(rows, 3)
    g = np.array([[20.0, 90.0 if r % 2 == 0 else 132.0, 200.0] for r in range(rows)]).ravel()
    a = np.tile([10.0, 4.0, 10.0], rows)
    interior = np.tile([True, False, True], rows)
    seg = segment_triangles(g, a, edges, cent, levels=[20, 110, 200], interior=interior,
                            min_material_area=5.0, lam=1.0, beta=0.0)
    layer = seg.mode_gray[seg.material].reshape(rows, 3)[:, 1]
    assert len(np.unique(seg.leaf.reshape(rows, 3)[:, 1])) == rows  # chopped into 6 leaves
    assert layer.tolist() == [110.0] * rows


# Mutation caught: a layer needs a run of two or more leaves (`if pending.sum() < 2:` ->
# `if pending.sum() < 1:` in label_fragmented_layers): a single leaf stopped by max_depth
# with 52 of its 101 px^2 in the 110 core and 49 in the 200 core is not a layer; it goes by
# its mean gray (191) to 200.
def test_a_single_unlabelled_leaf_is_not_a_fragmented_layer():
    g = [132] * 4 + [255] * 7
    a = [17, 17, 17, 1] + [7] * 7
    interior = np.zeros(11, bool)
    interior[3] = True  # 1 px^2 of interior: below min_pocket_area
    seg = segment_chain(g, a, levels=[20, 110, 200], interior=interior, min_material_area=10.0,
                        max_depth=0)
    assert seg.mode_gray.tolist() == [200.0]


# Mutation caught: label_partial_volume_leaves called without its min_area
# (`min_layer_area / 4.0)` -> `np.inf)` in _recursive_split).
def test_a_leaf_of_min_material_area_in_a_core_between_its_neighbours_is_that_material():
    # dark | two elements of gray 100 (8 px^2 >= min_material_area 5, no interior) | bright
    g = [20] * 3 + [100] * 2 + [200] * 3
    a = [10] * 3 + [4] * 2 + [10] * 3
    interior = np.array([1, 1, 1, 0, 0, 1, 1, 1], bool)
    kw = dict(levels=[20, 110, 200], interior=interior, min_material_area=5.0)
    seg = segment_chain(g, a, **kw)
    assert seg.mode_gray[seg.material].tolist() == [20.0] * 3 + [110.0] * 2 + [200.0] * 3
    # without the thin-layer rules (thin_layers=False) it is a mixed band and joins dark
    seg = segment_chain(g, a, thin_layers=False, **kw)
    assert seg.mode_gray[seg.material].tolist() == [20.0] * 5 + [200.0] * 3


# ---------------------------------------------------------------------------------------
# SPEC 7: the partial-volume rules (ctseg.partial_volume)

LEVELS3 = np.array([20.0, 110.0, 200.0])


def pv_leaves(leaf_gray, leaf_area, leaf_material, pairs, min_area=np.inf):
    """label_partial_volume_leaves on one element per leaf."""
    lm = np.array(leaf_material)
    n = len(lm)
    label_partial_volume_leaves(np.asarray(leaf_gray, float), np.asarray(leaf_area, float),
                                np.arange(n), lm, np.array(pairs), LEVELS3, min_area)
    return lm.tolist()


# Mutation caught: between its neighbours' levels a leaf joins the closest neighbouring
# material (`leaf_material[k] = ng[int(np.argmin(np.abs(lv - lg[k])))]` ->
# `leaf_material[k] = closest`, the closest level overall: here 110).
def test_pv_leaf_between_neighbours_joins_the_closest_neighbour():
    # dark (solid) - mixed leaf of gray 100 - bright (solid)
    assert pv_leaves([20, 100, 200], [50, 2, 50], [0, -1, 2], [(0, 1), (1, 2)]) == [0, 0, 2]


# Mutation caught: `if la[k] >= min_area and in_core_of(lg[k], closest):` -> `if False:`
# (a leaf too large for a mixed band, in the core of the level in between, is that level).
def test_large_pv_leaf_in_a_core_between_neighbours_is_that_material():
    assert pv_leaves([20, 100, 200], [50, 40, 50], [0, -1, 2], [(0, 1), (1, 2)],
                     min_area=30.0) == [0, 1, 2]
    # out of the core (lg 80: 30 from 110, core half-width 22.5): the closest neighbour
    assert pv_leaves([20, 80, 200], [50, 40, 50], [0, -1, 2], [(0, 1), (1, 2)],
                     min_area=30.0) == [0, 0, 2]


# Mutation caught: a leaf not between its neighbours' levels joins the closest level
# overall (`leaf_material[k] = int(np.argmin(np.abs(means - lg[k])))` in the else branch
# -> the closest neighbouring material, `ng[int(np.argmin(np.abs(lv - lg[k])))]`).
def test_pv_leaf_outside_its_neighbours_joins_the_closest_level():
    # a pore of gray 30 inside bright: dark, although no neighbour is dark
    assert pv_leaves([200, 30, 200], [50, 2, 50], [2, -1, 2], [(0, 1), (1, 2)]) == [2, 0, 2]


# Mutation caught: neighbours labelled by their interior first
# (`use = nb[solid[nb]] if solid[nb].any() else nb[leaf_material[nb] >= 0]` ->
# `use = nb[leaf_material[nb] >= 0]`).
def test_pv_leaf_looks_at_solid_neighbours_first():
    # 0 dark solid - 1 (gray 100, small) - 2 (gray 190, larger, labelled first) - 3 bright solid
    # leaf 1 sees only the solid dark leaf: not between -> closest level 110; with leaf 2's
    # (gray-alike) label counted it would lie between dark and bright and join dark
    assert pv_leaves([20, 100, 190, 200], [50, 2, 5, 50], [0, -1, -1, 2],
                     [(0, 1), (1, 2), (2, 3)]) == [0, 1, 2, 2]


# Mutation caught: larger leaves first (`np.argsort(-la[pending], kind="stable")` ->
# `np.argsort(la[pending], kind="stable")`).
def test_pv_leaves_are_labelled_largest_first():
    # 0 bright solid; 1 (190) next to it; 2 (gray 100, largest) next to 1 and 3; 3 (gray 30)
    # next to 1 and 2. Largest first: 1 -> bright, 3 -> dark (via 1), then 2 sees dark and
    # bright and joins dark. Smallest first, 2 would see bright only and go to 110.
    pairs = [(0, 1), (1, 2), (2, 3), (1, 3)]
    assert pv_leaves([200, 190, 100, 30], [50, 5, 9, 2], [2, -1, -1, -1], pairs) == [2, 2, 0, 0]


# Mutation caught: the fallback for leaves without any labelled neighbour removed
# (`leaf_material[pending] = [...]` -> `pass`): they would stay -1.
def test_isolated_pv_leaves_take_the_closest_level():
    assert pv_leaves([100, 190], [5, 5], [-1, -1], np.zeros((0, 2), int)) == [1, 2]


def pv_elements(gray, material, interior, levels=LEVELS3):
    g, _, pairs, _ = chain(gray)
    return partial_volume_elements(g, np.array(material), np.array(interior, bool), pairs,
                                   np.asarray(levels, float)).tolist()


# Mutation caught: the element rule disabled (`if lo == hi or not (lo <= f[t] <= hi):` ->
# `if True:`).
def test_mixed_element_takes_the_closer_of_the_materials_it_touches():
    # dark interior - element of gray 150 labelled dark - bright interior
    assert pv_elements([20, 150, 200], [0, 0, 2], [1, 0, 1]) == [0, 2, 2]


# Mutation caught: interior elements swept too (`boundary = np.flatnonzero(~interior)` ->
# `boundary = np.arange(len(f))`).
def test_interior_elements_keep_their_material():
    assert pv_elements([20, 150, 200], [0, 0, 2], [1, 1, 1]) == [0, 0, 2]


# Mutation caught: the gray must lie between the levels around
# (`not (lo <= f[t] <= hi)` -> `not (lo <= hi)`).
def test_mixed_element_outside_the_levels_around_is_left():
    # gray 250 labelled dark next to mid: outside [20, 110], stays dark
    assert pv_elements([20, 250, 110], [0, 0, 1], [1, 0, 1]) == [0, 0, 1]


# Mutation caught: one sweep instead of two (`for _ in range(2):` -> `for _ in range(1):`).
def test_mixed_elements_get_a_second_sweep():
    # 1 (120) only sees dark until 2 (180) has turned bright in the first sweep
    assert pv_elements([20, 120, 180, 200], [0, 0, 0, 1], [1, 0, 0, 1],
                       levels=[20.0, 200.0]) == [0, 1, 1, 1]


# Mutation caught: ties to the higher material (`(d == db and k < best)` -> `(d == db and k > best)`).
def test_mixed_element_ties_go_to_the_lower_material():
    # gray 110, 90 from both levels, labelled bright: goes to dark
    assert pv_elements([20, 110, 200], [0, 1, 1], [1, 0, 1], levels=[20.0, 200.0]) == [0, 0, 1]
