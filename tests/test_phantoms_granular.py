"""The granular and porous phantoms: known truth, deterministic, and in fact hard."""
import numpy as np
import pytest

import ctseg
from ctseg.metrics import evaluate
from ctseg.phantoms import make_phantom
from ctseg.phantoms_granular import (KINDS, LEVELS, NAMES, flat_fraction, granular_labels,
                                     image_levels, make_granular)

# share of each label in the supersampled truth, (low, high), at 200 x 200
FRACTIONS = {
    "sand": ((0.15, 0.35), (0.55, 0.80), (0.03, 0.15)),
    "casting": ((0.20, 0.45), (0.50, 0.80), (0.005, 0.05)),
    "sintered": ((0.08, 0.25), (0.75, 0.92)),
}


@pytest.fixture(scope="module", params=KINDS)
def phantom(request):
    return request.param, make_granular(request.param, 200, seed=0)


def test_truth_fractions(phantom):
    kind, p = phantom
    assert p.image.shape == p.truth.shape == (200, 200)
    assert p.truth_hr.shape == (200 * p.supersample, 200 * p.supersample)
    assert p.names == NAMES[kind]
    for k, (lo, hi) in enumerate(FRACTIONS[kind]):
        share = float(np.mean(p.truth_hr == k))
        assert lo <= share <= hi, (kind, k, share)
        assert abs(float(np.mean(p.truth == k)) - share) < 0.03  # the majority keeps the share
    assert int(p.truth_hr.max()) == len(NAMES[kind]) - 1


def test_truth_is_the_majority_of_the_subpixels(phantom):
    _, p = phantom
    s = p.supersample
    counts = np.stack([(p.truth_hr == k).reshape(200, s, 200, s).sum(axis=(1, 3))
                       for k in range(len(p.names))])
    assert np.all(counts[p.truth, np.arange(200)[:, None], np.arange(200)] == counts.max(axis=0))


def test_deterministic_per_seed():
    a, b = make_granular("sand", 96, seed=5), make_granular("sand", 96, seed=5)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.truth_hr, b.truth_hr)
    c = make_granular("sand", 96, seed=6)
    assert not np.array_equal(a.truth_hr, c.truth_hr)
    # the kinds draw from different streams
    assert not np.array_equal(granular_labels("sintered", (64, 64), 5)[0] > 0,
                              granular_labels("sand", (64, 64), 5)[0] > 0)


def test_the_slices_are_hard(phantom):
    """Hardly any flat region (a machined part is 0.9 flat), and a broad histogram with a
    partial-volume plateau between the levels, not only noise round them."""
    kind, p = phantom
    assert flat_fraction(p.image) < 0.6, kind
    lv = np.asarray(LEVELS[kind])
    img = p.image.astype(float)
    near = np.min(np.abs(img[..., None] - lv), axis=-1) < 2.5 * 0.03  # within 2.5 noise sd
    assert np.mean(~near) > 0.15, kind


def test_a_machined_part_is_flat_by_the_same_measure():
    assert flat_fraction(make_phantom(128, seed=0).image) > 0.85


def test_grain_scale_sets_the_boundary_length():
    fine = granular_labels("sintered", (96, 96), 1, supersample=2, grain_scale=1.0)[0]
    coarse = granular_labels("sintered", (96, 96), 1, supersample=2, grain_scale=2.0)[0]
    edges = lambda t: int((t[1:] != t[:-1]).sum() + (t[:, 1:] != t[:, :-1]).sum())  # noqa: E731
    assert edges(fine) > 1.5 * edges(coarse)


def test_clip8_is_8_bit_and_clips_the_pores():
    p = make_granular("sand", 128, seed=2, clip8=True)
    assert p.image.dtype == np.uint8
    assert np.mean(p.image == 0) > 0.002
    lv = image_levels("sand", clip8=True)
    assert lv[0] == 5.0 and lv[-1] == 230.0
    pores = p.truth == 0
    assert float(np.median(p.image[pores])) < 0.5 * (lv[0] + lv[1])  # pores stay dark
    assert float(np.median(p.image[p.truth == 2])) > 0.5 * (lv[1] + lv[2])


def test_rectangular_slices_and_bad_input():
    p = make_granular("casting", (94, 103), seed=3)
    assert p.image.shape == (94, 103) and p.truth_hr.shape == (94 * 4, 103 * 4)
    with pytest.raises(ValueError):
        make_granular("gravel", 64, seed=0)
    with pytest.raises(ValueError):
        make_granular("sand", 8, seed=0)


def test_evaluate_takes_the_phantom():
    p = make_granular("casting", 200, seed=0)
    seg = ctseg.segment_image(p.image, gray_levels=image_levels("casting"))
    ev = evaluate(seg, p.truth, p.truth_hr, p.supersample)
    assert len(ev["dice"]) == 3 and len(ev["dice_subpixel"]) == 3
    assert ev["dice"][1] > 0.9  # the metal
