"""The 3D mode's material levels checked against the tetrahedra (ctseg/levels3d.py): on a
small true 3D phantom the flat voxels hold partial volume and merge materials; the
tetrahedra's grays recover them."""
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

import ctseg.levels3d
import ctseg.levels
from ctseg.levels3d import checked_levels, denser_levels, homogeneous_levels, hidden_levels, tetra_levels
from ctseg.metrics import evaluate_tetra
from ctseg.params import SegmentParams
from ctseg.phantoms import make_volume
from ctseg.phantoms3d import make_part_3d
from ctseg.pipeline3d import segment_volume_3d


def _modes(rng, means, sd, counts):
    return np.concatenate([rng.normal(m, sd, n) for m, n in zip(means, counts)])


def test_tetra_levels_find_separated_modes():
    rng = np.random.default_rng(0)
    gray = _modes(rng, (20, 45, 85, 240), 1.5, (4000, 300, 500, 100))
    levels, sigma = tetra_levels(gray, np.ones(len(gray)))
    assert np.allclose(levels, (20, 45, 85, 240), atol=1.0)
    assert sigma == pytest.approx(1.5, rel=0.2)


def test_flat_levels_kept_when_the_spreads_agree_or_materials_are_given():
    rng = np.random.default_rng(1)
    gray = _modes(rng, (20, 45, 85), 1.5, (4000, 300, 500))
    vol = np.ones(len(gray))
    flat = np.array([20.0, 85.0])
    kept, rep = checked_levels(flat, 2.5, gray, vol)  # flat spread < 2 x the tetrahedra's
    assert rep["method"] == "flat_voxels" and np.array_equal(kept, flat)
    swapped, rep = checked_levels(flat, 9.0, gray, vol)
    assert rep["method"] == "tetrahedra" and len(swapped) == 3
    given, rep = checked_levels(flat, 9.0, gray, vol, SegmentParams().replace(n_materials=2))
    assert rep["method"] == "flat_voxels" and np.array_equal(given, flat)


def test_small_phantom_gets_its_four_materials(monkeypatch):
    ph = make_part_3d(64, seed=0)
    seg = segment_volume_3d(ph.image)
    acc = evaluate_tetra(seg, ph.truth)
    rep = seg.diagnostics["levels"]
    assert rep["method"] == "tetrahedra" and seg.n_materials == 4
    assert rep["flat_sigma_255"] > 2 * rep["tetra_sigma_255"]
    # measured 0.989 / 0.579 / 0.869 / 0.935
    assert np.all(np.array(acc["dice"]) >= [0.97, 0.45, 0.80, 0.88]), acc["dice"]
    # without the check the flat voxels' levels merge polymer and aluminium into the air
    # (the homogeneous tetrahedra's levels, on their own, would add them back)
    monkeypatch.setattr(ctseg.levels3d, "FLAT_TO_ELEMENT_SPREAD", np.inf)
    monkeypatch.setattr(ctseg.levels3d, "HOMOGENEOUS_SPREAD", 0.0)
    before = segment_volume_3d(ph.image)
    assert before.n_materials < 4 and before.diagnostics["levels"]["method"] == "flat_voxels"


def test_simulated_ct_volume_keeps_the_flat_levels():
    ph = make_volume(16, 48, seed=3)
    seg = segment_volume_3d(ph.image)
    rep = seg.diagnostics["levels"]
    assert rep["method"] == "flat_voxels"
    # the flat voxels miss the steel (1.1% of the voxels); the tail rule adds it from its
    # dense regions, so the tetrahedra's check has nothing to add
    assert len(rep["flat_levels_255"]) == 3 and rep["flat_levels_255"][-1] > 200
    assert rep["denser_added_255"] == [] and rep["homogeneous_added_255"] == []
    assert seg.diagnostics["material_levels_255"] == rep["flat_levels_255"]


def _coated(rng):
    """Tetrahedron grays and spreads of air, a blurred air/aluminium edge (all grays in
    between, spreading as the contrast), a thin polymer between them, aluminium."""
    gray = np.concatenate([rng.normal(20, 1, 3000), rng.uniform(20, 80, 3000),
                           rng.normal(45, 1, 60), rng.normal(80, 1, 1500)])
    spread = np.concatenate([rng.uniform(4, 7, 3000), rng.uniform(8, 25, 3000),
                             rng.uniform(4, 7, 1560)])
    return gray, np.ones(len(gray)), spread


def test_homogeneous_tetrahedra_add_a_level_the_histograms_hide():
    rng = np.random.default_rng(4)
    gray, vol, spread = _coated(rng)
    flat = np.array([20.0, 80.0])
    # all tetrahedra together: the polymer drowns in the edge's continuum
    assert len(tetra_levels(gray, vol)[0]) < 3
    assert np.array_equal(checked_levels(flat, 2.5, gray, vol)[0], flat)
    levels, rep = checked_levels(flat, 2.5, gray, vol, None, spread, 5.0)
    assert np.allclose(levels, (20, 45, 80), atol=1.5) and len(rep["homogeneous_added_255"]) == 1
    # the edge's tetrahedra spreading as the noise: no longer told apart, nothing added
    levels, rep = checked_levels(flat, 2.5, gray, vol, None, np.full(len(gray), 5.0), 5.0)
    assert np.array_equal(levels, flat) and rep["homogeneous_added_255"] == []


def test_homogeneous_modes_next_to_a_level_add_nothing():
    rng = np.random.default_rng(5)
    gray = _modes(rng, (20, 26, 80), 1.0, (3000, 400, 1500))  # 26: within 20's separation
    found, sigma = homogeneous_levels(gray, np.ones(len(gray)), np.full(len(gray), 4.0), 5.0)
    assert len(hidden_levels(found, sigma, [20.0, 80.0])) == 0
    # a homogeneous mode far from both is added; one near 80 is not, nor one beyond 20
    gray = _modes(rng, (5, 20, 50, 84, 80), 1.0, (300, 3000, 400, 200, 1500))
    found, sigma = homogeneous_levels(gray, np.ones(len(gray)), np.full(len(gray), 4.0), 5.0)
    assert np.allclose(hidden_levels(found, sigma, [20.0, 80.0]), [50.0], atol=1.0)


def test_a_thin_polymer_layer_gets_its_level(monkeypatch):
    """96^3 seed 0: a polymer layer and bushing 3.5 voxels thick, 3 noise sd above air,
    leave no mode among the flat voxels or the tetrahedra; the homogeneous ones show it."""
    ph = make_part_3d(96, seed=0)
    seg = segment_volume_3d(ph.image)
    acc = evaluate_tetra(seg, ph.truth)
    rep = seg.diagnostics["levels"]
    assert seg.n_materials == 4 and len(rep["homogeneous_added_255"]) == 1
    # measured 0.993 / 0.764 / 0.970 / 0.965
    assert np.all(np.array(acc["dice"]) >= [0.97, 0.6, 0.93, 0.93]), acc["dice"]
    monkeypatch.setattr(ctseg.levels3d, "HOMOGENEOUS_SPREAD", 0.0)  # no tetrahedron counts
    before = segment_volume_3d(ph.image)
    assert before.n_materials == 3 and before.diagnostics["levels"]["homogeneous_added_255"] == []


def test_given_material_count_gives_way_to_a_hidden_level():
    rng = np.random.default_rng(6)
    gray, vol, spread = _coated(rng)
    three, four = (SegmentParams().replace(n_materials=k) for k in (3, 4))
    # the count's third level forced out of a bump at 200, which no tetrahedron is near
    levels, rep = checked_levels(np.array([20.0, 80.0, 200.0, 250.0]), 2.5, gray, vol, four, spread, 5.0)
    assert rep["method"] == "homogeneous_tetrahedra" and np.allclose(levels, (20, 45, 80, 250), atol=1.5)
    # the polymer already among the levels: nothing hidden, kept as they are
    flat = np.array([21.0, 44.0, 79.0])
    levels, rep = checked_levels(flat, 2.5, gray, vol, three, spread, 5.0)
    assert rep["method"] == "flat_voxels" and np.array_equal(levels, flat)
    # the outermost levels stay however little they hold (a clipped end, say)
    levels, rep = checked_levels(np.array([20.0, 80.0, 250.0]), 2.5, gray, vol, three, spread, 5.0)
    assert rep["method"] == "flat_voxels" and np.allclose(levels, (20, 80, 250))
    # without the spreads: the count's levels
    levels, rep = checked_levels(np.array([20.0, 80.0, 200.0]), 2.5, gray, vol, three)
    assert rep["method"] == "flat_voxels" and np.allclose(levels, (20, 80, 200))


def test_a_handful_of_homogeneous_tetrahedra_is_no_level():
    rng = np.random.default_rng(7)
    gray, vol, spread = _coated(rng)
    keep = np.ones(len(gray), bool)
    keep[6000 + 10:6060] = False  # 10 polymer tetrahedra left: 0.13% of the volume
    found, _ = homogeneous_levels(gray[keep], vol[keep], spread[keep], 5.0)
    assert len(found) == 2
    found, _ = homogeneous_levels(gray, vol, spread, 5.0)  # 60 of them: 0.8%
    assert len(found) == 3


def test_denser_levels_only_above_the_highest_and_beyond_the_separation():
    p = SegmentParams()
    sep = max(p.merge_floor_255, p.merge_k * 1.0) + p.merge_rel * 200.0
    assert denser_levels([20.0, 90.0, 200.0], 1.0, [20.0, 90.0]).tolist() == [200.0]
    # within the separation of the highest level: its own blur tail, nothing added
    assert denser_levels([20.0, 180.0 + 0.9 * sep], 1.0, [20.0, 180.0]).size == 0
    # below the lowest level: never (a dark artefact band would make one)
    assert denser_levels([2.0, 90.0], 1.0, [40.0, 90.0]).size == 0


def test_denser_levels_are_judged_in_the_smaller_of_the_two_spreads():
    # thin struts mixing into the tetrahedra widen their spread (6) while the flat voxels
    # show the noise (1): a mode 40 above the highest level is beyond 1's separation only
    rng = np.random.default_rng(4)
    gray = np.concatenate([rng.normal(20.0, 6.0, 2000), rng.normal(130.0, 2.0, 60)])
    p = SegmentParams()
    _, t_sigma = tetra_levels(gray, np.ones(len(gray)))
    assert 130.0 < 90.0 + p.merge_k * t_sigma + p.merge_rel * 130.0  # the tetrahedra's spread misses it
    levels, rep = checked_levels(np.array([20.0, 90.0]), 1.0, gray, np.ones(len(gray)))
    assert len(rep["denser_added_255"]) == 1 and abs(rep["denser_added_255"][0] - 130.0) < 3.0
    assert len(levels) == 3


def _rod_in_cylinder(n=48):
    """A solid aluminium cylinder holding a steel rod of radius 3 voxels (0.5% of the
    voxels): too few flat voxels for a level of the rod's own."""
    z, y, x = np.indices((n, n, n))
    truth = (((y - n / 2) ** 2 + (x - n / 2 + 2) ** 2 < 11 ** 2) & (z > 6) & (z < n - 6)).astype(int)
    truth[((y - n / 2) ** 2 + (x - n / 2 - 2) ** 2 < 9) & (z > 9) & (z < n - 10)] = 2
    gray = gaussian_filter(np.array([1000.0, 9000.0, 30000.0])[truth], 0.8)
    return gray + np.random.default_rng(1).normal(0, 400, truth.shape), truth


def test_a_small_dense_insert_gets_a_level_from_its_tetrahedra(monkeypatch):
    """The rod's voxels beyond the aluminium are found by the tail rule; with that rule
    off (an insert too small for it) the tetrahedra's grays still find it, and with both
    off it is merged."""
    vol, truth = _rod_in_cylinder()
    assert (truth == 2).mean() < 0.01
    seg = segment_volume_3d(vol)
    assert seg.n_materials == 3 and min(evaluate_tetra(seg, truth)["dice"]) > 0.85
    monkeypatch.setattr(ctseg.levels, "tail_levels", lambda *a, **k: [])
    seg = segment_volume_3d(vol)
    assert seg.n_materials == 3
    assert seg.diagnostics["levels"]["denser_added_255"]
    dice = evaluate_tetra(seg, truth)["dice"]
    assert min(dice) > 0.85
    monkeypatch.setattr(ctseg.levels3d, "denser_levels", lambda *a, **k: np.zeros(0))
    assert segment_volume_3d(vol).n_materials == 2
