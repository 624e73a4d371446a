"""Metal streak correction (ctseg.beam_hardening): known artifacts recovered, real ones reduced."""
import numpy as np
import pytest
from scipy import ndimage

import ctseg.beam_hardening as bh
from ctseg.beam_hardening import correct_metal_streaks, fit_streak_weight, metal_streak_basis
from ctseg.errors import InputError, ParameterError
from ctseg.phantoms import make_phantom
from ctseg.levels import flat_pixels


def part(shape=(96, 96)):
    """Air, an aluminium disc (1.0) and two steel pins (5.0): truth image and metal mask."""
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    img = np.zeros(shape)
    img[(yy - 48) ** 2 + (xx - 48) ** 2 <= 40 ** 2] = 1.0
    metal = ((yy - 48) ** 2 + (xx - 30) ** 2 <= 11 ** 2) | ((yy - 48) ** 2 + (xx - 68) ** 2 <= 8 ** 2)
    img[metal] = 5.0
    return img, metal


def test_fit_equals_least_squares_with_class_means():
    # independent reference: lstsq on [basis, one indicator column per class]
    rng = np.random.default_rng(0)
    img = rng.normal(size=(20, 30))
    basis = rng.normal(size=(20, 30))
    classes = rng.integers(0, 3, size=(20, 30))
    mask = rng.random((20, 30)) < 0.7
    w, explained = fit_streak_weight(img, basis, classes, mask)
    cols = [basis[mask]] + [(classes[mask] == k).astype(float) for k in range(3)]
    coef = np.linalg.lstsq(np.column_stack(cols), img[mask], rcond=None)[0]
    assert w == pytest.approx(-coef[0], rel=1e-10)
    resid0 = sum(((img[mask & (classes == k)] - img[mask & (classes == k)].mean()) ** 2).sum()
                 for k in range(3))
    resid1 = ((img[mask] - np.column_stack(cols) @ coef) ** 2).sum()
    assert explained == pytest.approx(1 - resid1 / resid0, rel=1e-9)


def test_known_streak_artifact_is_removed():
    truth, metal = part()
    basis = metal_streak_basis(metal)
    away = ~ndimage.binary_dilation(metal, iterations=3)
    w = 0.3 / np.abs(basis[away]).max()  # streaks up to 30% of the aluminium level
    rng = np.random.default_rng(1)
    seen = truth - w * basis + rng.normal(0, 0.02, truth.shape)  # dark streaks + noise
    out = correct_metal_streaks(seen, [0.0, 1.0, 5.0])
    assert out.weight == pytest.approx(w, rel=0.03)
    assert out.explained > 0.5
    err_before = np.abs(seen - truth)[away].mean()
    err_after = np.abs(out.image - truth)[away].mean()
    assert err_after < 0.7 * err_before
    assert np.abs(out.image - truth)[away].max() < 0.15


def test_nothing_to_correct_leaves_the_image_alone():
    truth, metal = part()
    basis = metal_streak_basis(metal)
    # bright streaks are not beam hardening: a negative weight is refused
    out = correct_metal_streaks(truth + 0.004 * basis, [0.0, 1.0, 5.0])
    assert out.weight == 0.0 and "not positive" in out.reason
    np.testing.assert_array_equal(out.image, truth + 0.004 * basis)
    one = correct_metal_streaks(truth, [1.0])
    assert one.weight == 0.0 and "fewer than two" in one.reason
    np.testing.assert_array_equal(one.image, truth)
    low = correct_metal_streaks(truth, [0.0, 1.0, 50.0])  # no pixel reads as the top level
    assert low.weight == 0.0 and low.reason == "no metal"
    # noise only: whatever weight fits it explains next to nothing and is not applied
    rng = np.random.default_rng(3)
    noisy = truth + rng.normal(0, 0.05, truth.shape)
    calm = correct_metal_streaks(noisy, [0.0, 1.0, 5.0])
    assert calm.weight == 0.0 and calm.explained < 0.05
    np.testing.assert_array_equal(calm.image, noisy)


def test_coarse_basis_follows_the_full_size_one(monkeypatch):
    _, metal = part((150, 150))
    full = metal_streak_basis(metal)
    monkeypatch.setattr(bh, "BASIS_MAX_PX", 75)  # 2x coarser, as on a 512 px slice
    coarse = metal_streak_basis(metal)
    assert coarse.shape == full.shape
    away = ~ndimage.binary_dilation(metal, iterations=6)
    # the weight is fitted, so the shape matters, not the scale
    assert np.corrcoef(coarse[away], full[away])[0, 1] > 0.9


def test_bad_arguments_name_the_problem():
    truth, _ = part((20, 20))
    with pytest.raises(ParameterError, match="levels"):
        correct_metal_streaks(truth, [0.0, np.nan])
    with pytest.raises(ParameterError, match="flat"):
        correct_metal_streaks(truth, [0.0, 1.0], flat=np.ones((3, 3), bool))
    with pytest.raises(InputError, match="NaN"):
        correct_metal_streaks(np.full((5, 5), np.nan), [0.0, 1.0])
    with pytest.raises(ParameterError, match="metal"):
        metal_streak_basis(np.ones(5))


def test_simulated_beam_hardening_is_reduced():
    # polychromatic simulation: the correction must bring non-metal pixels closer to
    # their material's level (measured on the truth, which the correction never sees)
    p = make_phantom(128, seed=0)
    img = p.image.astype(float)
    truth = p.truth
    levels = [np.median(img[truth == k]) for k in range(4)]
    flat = flat_pixels(img)  # as segment_image fits it: away from edges
    out = correct_metal_streaks(img, levels, flat=flat)
    assert out.weight > 0 and out.explained > 0.1
    keep = np.zeros(truth.shape, bool)
    for k in range(3):
        keep |= ndimage.binary_erosion(truth == k, iterations=2)
    keep &= ~ndimage.binary_dilation(truth == 3, iterations=3)

    def spread(im):
        return sum(((im[keep & (truth == k)] - im[keep & (truth == k)].mean()) ** 2).sum()
                   for k in range(3))
    assert spread(out.image) < 0.8 * spread(img)
    again = correct_metal_streaks(img, levels, flat=flat)
    np.testing.assert_array_equal(again.image, out.image)
