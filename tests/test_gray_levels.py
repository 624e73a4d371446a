"""Material gray levels given by the user (``gray_levels``, CLI ``--levels``), and
``n_materials`` honoured, on synthetic images and on every real slice of ../shared/realdata."""
import glob
import json
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ctseg
from ctseg.metrics import dice_per_label
from ctseg.raster import label_image
from ctseg.cli import main
from ctseg.errors import ParameterError
from ctseg.params import AUTO, SPECS, SegmentParams

REALDATA = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "realdata")
REAL_SLICES = sorted(glob.glob(os.path.join(REALDATA, "*_z*.npy")))
SPEC = SPECS["gray_levels"]


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1e12, 1e12, allow_nan=False), min_size=1, max_size=8, unique=True))
def test_text_form_reads_back_exactly(values):
    levels = tuple(sorted(values))
    if any(b <= a for a, b in zip(levels, levels[1:])):
        return
    assert SPEC.parse(SPEC.to_text(levels)) == levels
    assert SPEC.check(list(levels)) == levels and SPEC.check(np.array(levels)) == levels


def test_bad_levels_are_refused_with_the_reason():
    for bad, why in [("40, 30", "strictly ascending"), ("40, 40", "strictly ascending"),
                     ("", "valid:"), ("1, x", "valid:"), ([1.0, float("inf")], "valid:"),
                     ([True, 2], "valid:"), ({"a": 1}, "valid:")]:
        with pytest.raises(ParameterError, match=f"gray_levels: .*{why}"):
            SegmentParams().replace(gray_levels=bad)
    with pytest.raises(ParameterError, match="2 levels given .* n_materials=3"):
        SegmentParams().replace(gray_levels=(1, 2), n_materials=3)
    assert SegmentParams().replace(gray_levels=(1, 2, 3), n_materials=3).n_materials == 3
    assert SegmentParams().replace(gray_levels="auto").gray_levels == AUTO


def _three_regions(seed=0):
    """Left 40, middle 44, right 200 (noise sd 2): 40 and 44 are closer than the automatic
    separation rule (5 sd + 0.2 x gray on the 0-255 scale) keeps apart."""
    rng = np.random.default_rng(seed)
    img = np.full((96, 96), 40.0)
    img[:, 32:64] = 44.0
    img[:, 64:] = 200.0
    truth = np.repeat(np.array([0, 1, 2]), 32)[None, :].repeat(96, 0)
    return img + rng.normal(0, 2.0, img.shape), truth


def test_given_levels_separate_what_the_automatic_rule_merges():
    img, truth = _three_regions()
    auto = ctseg.segment_image(img, n_sites=600)
    assert auto.n_materials == 2  # the premise: the rule merges 40 and 44
    seg = ctseg.segment_image(img, n_sites=600, gray_levels=(40, 44, 200))
    assert seg.diagnostics["levels"]["method"] == "given"
    assert np.allclose(seg.material_gray, [40, 44, 200])
    lab = label_image(seg.points, seg.triangles, seg.material, img.shape)
    dice = dice_per_label(lab, truth, 3)
    assert min(dice) > 0.95, dice


def test_material_k_is_the_kth_level_even_when_one_is_absent():
    img, truth = _three_regions()
    img = np.where(truth == 1, img - 4.0, img)  # the middle joins the left: 40 and 200 only
    seg = ctseg.segment_image(img, n_sites=400, gray_levels=(40, 120, 200))
    assert np.allclose(seg.material_gray, [40, 120, 200])
    assert set(np.unique(seg.material)) == {0, 2}


def test_levels_outside_the_data_are_refused():
    img, _ = _three_regions()
    with pytest.raises(ParameterError, match=r"gray_levels: 4000 lies outside .*input's units"):
        ctseg.segment_image(img, gray_levels=(40, 4000))
    vol = np.stack([img] * 4)
    for mode in ("slices", "3d"):
        with pytest.raises(ParameterError, match="gray_levels: -5 lies outside"):
            ctseg.segment_volume(vol, mode=mode, gray_levels=(-5, 40))


def test_a_level_missing_from_some_slices_is_not_refused():
    """Slices mode checks the levels against the volume, not slice by slice."""
    img, truth = _three_regions()
    vol = np.stack([img[::2, ::2]] * 4)
    vol[:2] = np.where(vol[:2] > 100, 40.0, vol[:2])  # no bright material in slices 0-1
    seg = ctseg.segment_volume(vol, mode="slices", n_sites=150, gray_levels=(40, 44, 200))
    assert np.allclose(seg.material_gray, [40, 44, 200])
    assert 2 not in seg.slices[0].material and 2 in seg.slices[3].material


def test_volumes_take_the_given_levels_in_both_modes():
    img, truth = _three_regions()
    vol = np.stack([img[::2, ::2]] * 8)
    for mode in ("slices", "3d"):
        seg = ctseg.segment_volume(vol, mode=mode, n_sites=300 if mode == "3d" else 150,
                                   gray_levels=(40, 44, 200))
        # slices: the levels themselves; 3D: each material's mean gray
        assert np.allclose(seg.material_gray, [40, 44, 200], atol=0 if mode == "slices" else 2), mode
        material = seg.material if mode == "3d" else np.concatenate([s.material for s in seg.slices])
        assert set(np.unique(material)) == {0, 1, 2}, mode


@pytest.mark.skipif(not REAL_SLICES, reason="../shared/realdata is absent")
@pytest.mark.parametrize("path", REAL_SLICES, ids=os.path.basename)
def test_materials_and_levels_work_on_every_real_slice(path, tmp_path):
    """--materials K gives K materials on every real slice; --levels with those materials'
    grays (within the data's range) gives as many, at exactly those levels."""
    data = np.load(path)
    for k in (2, 3):
        report = tmp_path / f"k{k}.json"
        assert main(["mesh", path, "-o", str(tmp_path / f"k{k}.vtp"), "--materials", str(k),
                     "--report", str(report)]) == 0
        diag = json.loads(report.read_text())
        assert diag["n_materials"] == k, (k, diag["material_gray"], diag["levels"])
    levels = np.unique(np.clip(np.round(diag["material_gray"], 1), data.min(), data.max()))
    text = ", ".join(f"{v:g}" for v in levels)
    report = tmp_path / "given.json"
    assert main(["mesh", path, "-o", str(tmp_path / "given.vtp"), "--levels", text,
                 "--report", str(report)]) == 0
    diag = json.loads(report.read_text())
    assert diag["levels"]["method"] == "given"
    assert np.allclose(diag["material_gray"], levels, rtol=1e-9)
    assert diag["n_materials"] == len(levels)
