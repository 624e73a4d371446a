"""The 3D mode's material levels checked against the tetrahedra (ctseg/levels3d.py): on a
small true 3D phantom the flat voxels hold partial volume and merge materials; the
tetrahedra's grays recover them."""
import numpy as np
import pytest

import ctseg.levels3d
from ctseg.levels3d import checked_levels, tetra_levels
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
    monkeypatch.setattr(ctseg.levels3d, "FLAT_TO_ELEMENT_SPREAD", np.inf)
    before = segment_volume_3d(ph.image)
    assert before.n_materials < 4 and before.diagnostics["levels"]["method"] == "flat_voxels"


def test_simulated_ct_volume_keeps_the_flat_levels():
    ph = make_volume(16, 48, seed=3)
    seg = segment_volume_3d(ph.image)
    assert seg.diagnostics["levels"]["method"] == "flat_voxels"
    assert seg.diagnostics["material_levels_255"] == seg.diagnostics["levels"]["flat_levels_255"]
