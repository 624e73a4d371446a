"""Metal streak correction (ctseg.beam_hardening): known artifacts recovered, real ones reduced."""
import numpy as np
import pytest
from scipy import ndimage

import ctseg.streak_basis as streak_basis
from ctseg.beam_hardening import (HALO_SIGMAS_PX, correct_metal_streaks, fit_streak_weight,
                                   fit_streak_weights, halo_basis, metal_streak_basis,
                                   streak_bases)
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
    out = correct_metal_streaks(seen, [0.0, 1.0, 5.0], streak_model="square")
    assert out.weight == pytest.approx(w, rel=0.03)
    assert out.explained > 0.5
    err_before = np.abs(seen - truth)[away].mean()
    err_after = np.abs(out.image - truth)[away].mean()
    assert err_after < 0.7 * err_before
    assert np.abs(out.image - truth)[away].max() < 0.15
    # a pure L^2 artifact: the polynomial model gains too little over the square one and
    # gives way to it; with no gain asked it is kept and corrects as well
    poly = correct_metal_streaks(seen, [0.0, 1.0, 5.0], streak_model="polynomial")
    assert poly.weights == out.weights and len(poly.weights) == 1
    np.testing.assert_array_equal(poly.image, out.image)
    forced = correct_metal_streaks(seen, [0.0, 1.0, 5.0], streak_model="polynomial",
                                   streak_min_gain=0.0)
    assert len(forced.weights) == 3 and forced.explained >= out.explained - 1e-9
    assert np.abs(forced.image - truth)[away].mean() < 0.7 * err_before
    assert np.abs(forced.image - truth)[away].max() < 0.15


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
    monkeypatch.setattr(streak_basis, "BASIS_MAX_PX", 75)  # 2x coarser, as on a 512 px slice
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


def test_several_bases_fit_equals_least_squares_with_class_means():
    rng = np.random.default_rng(5)
    img = rng.normal(size=(20, 30))
    bases = [rng.normal(size=(20, 30)) for _ in range(3)]
    classes = rng.integers(0, 3, size=(20, 30))
    mask = rng.random((20, 30)) < 0.7
    w, explained = fit_streak_weights(img, bases, classes, mask)
    cols = [b[mask] for b in bases] + [(classes[mask] == k).astype(float) for k in range(3)]
    coef = np.linalg.lstsq(np.column_stack(cols), img[mask], rcond=None)[0]
    np.testing.assert_allclose(w, -coef[:3], rtol=1e-8)
    one = fit_streak_weight(img, bases[0], classes, mask)
    np.testing.assert_allclose(fit_streak_weights(img, bases[:1], classes, mask)[0], [one[0]],
                               rtol=1e-10)
    assert 0.0 <= explained <= 1.0


def plate_with_inserts(n=128):
    """A plate (1.0) with four metal discs (5.0) in a row along it, tilted: truth, metal."""
    yy, xx = np.mgrid[0:n, 0:n]
    a = 0.2
    u = (xx - n / 2) * np.cos(a) + (yy - n / 2) * np.sin(a)
    v = -(xx - n / 2) * np.sin(a) + (yy - n / 2) * np.cos(a)
    img = np.zeros((n, n))
    img[(np.abs(u) <= 0.36 * n) & (np.abs(v) <= 0.2 * n)] = 1.0
    metal = np.zeros((n, n), bool)
    for x0 in np.linspace(-0.25, 0.25, 4) * n:
        metal |= (u - x0) ** 2 + v ** 2 <= (0.045 * n) ** 2
    img[metal] = 5.0
    return img, metal


def test_bands_between_several_inserts_are_removed():
    # the dark bands along a row of inserts in a plate: rays through metal *and* a long
    # stretch of plate harden more than L^2 says (a cross term L * P), and the long metal
    # paths less (L^3); the square model leaves the bands, the polynomial one removes most
    truth, metal = plate_with_inserts()
    plate = (truth > 0) & ~metal
    sq, cube, cross = streak_bases(metal, plate, model="polynomial")
    away = ~ndimage.binary_dilation(metal, iterations=3)
    art = 0.5 * sq / np.abs(sq[away]).max() + 0.5 * cross / np.abs(cross[away]).max() \
        - 0.1 * cube / np.abs(cube[away]).max()
    rng = np.random.default_rng(2)
    noise = rng.normal(0, 0.02, truth.shape)
    seen = truth - art + noise  # bands down to about half the plate's level
    fit = ndimage.binary_erosion(plate, iterations=2) & away
    err_before = np.abs(seen - noise - truth)[fit].mean()
    fixed = correct_metal_streaks(seen, [0.0, 1.0, 5.0], streak_model="polynomial")
    old = correct_metal_streaks(seen, [0.0, 1.0, 5.0], streak_model="square")
    assert fixed.weight > 0 and len(fixed.weights) == 3
    err_new = np.abs(fixed.image - noise - truth)[fit].mean()
    err_old = np.abs(old.image - noise - truth)[fit].mean()
    assert err_new < 0.35 * err_before
    assert err_new < 0.5 * err_old
    assert fixed.explained > old.explained + 0.3


def test_simulated_multi_insert_plate_is_flattened_more_by_the_polynomial_model():
    # ctseg.phantoms' polychromatic simulation (its own ray-driven projector) of a plate
    # with a row of steel inserts: the polynomial model flattens the plate more
    from ctseg.phantoms import simulate_ct
    n, s = 128, 2
    truth, metal = plate_with_inserts(n * s)
    lab = np.where(metal, 2, (truth > 0).astype(int)).astype(np.uint8)
    img = simulate_ct(lab, s, materials=("air", "aluminium", "steel"), pixel_mm=0.6, seed=3)
    img = img.astype(float)
    lab_px = lab[::s, ::s]
    levels = [np.median(img[lab_px == k]) for k in range(3)]
    flat = flat_pixels(img)
    keep = ndimage.binary_erosion(lab_px == 1, iterations=2)
    keep &= ~ndimage.binary_dilation(lab_px == 2, iterations=3)

    def spread(im):
        return float(((im[keep] - im[keep].mean()) ** 2).sum())
    old = correct_metal_streaks(img, levels, flat=flat, streak_model="square")
    new = correct_metal_streaks(img, levels, flat=flat, streak_model="polynomial")
    assert new.weight > 0 and new.explained > old.explained
    assert spread(new.image) < 0.8 * spread(old.image) < 0.8 * spread(img)


def test_glow_around_the_metal_is_removed_by_the_halo_model():
    # streaks plus a bright glow (the metal blurred by a Gaussian of 11.3 px, up to 40% of
    # the plate's level), as scatter and glare leave around a clipped steel fastener: the
    # path-length terms cannot make it, the halo model finds its width and removes it
    truth, metal = plate_with_inserts()
    plate = (truth > 0) & ~metal
    sq = streak_bases(metal, plate, model="square")[0]
    away = ~ndimage.binary_dilation(metal, iterations=3)
    glow = halo_basis(metal, HALO_SIGMAS_PX[1])
    rng = np.random.default_rng(4)
    noise = rng.normal(0, 0.02, truth.shape)
    clean = truth - 0.5 * sq / np.abs(sq[away]).max() + noise
    seen = clean + 0.4 * glow / glow[away].max()
    fit = ndimage.binary_erosion(plate, iterations=2) & away
    poly = correct_metal_streaks(seen, [0.0, 1.0, 5.0], streak_model="polynomial")
    halo = correct_metal_streaks(seen, [0.0, 1.0, 5.0], streak_model="halo")
    assert poly.halo_px == 0.0 and halo.halo_px in HALO_SIGMAS_PX[:3]
    assert len(halo.weights) == 4 and halo.weights[-1] < 0  # the glow taken off
    err_poly = np.abs(poly.image - noise - truth)[fit].mean()
    err_halo = np.abs(halo.image - noise - truth)[fit].mean()
    assert err_halo < 0.5 * err_poly
    # without a glow its term gains too little and the polynomial model's image stays
    plain_poly = correct_metal_streaks(clean, [0.0, 1.0, 5.0], streak_model="polynomial")
    plain_halo = correct_metal_streaks(clean, [0.0, 1.0, 5.0], streak_model="halo")
    assert plain_halo.halo_px == 0.0
    np.testing.assert_array_equal(plain_halo.image, plain_poly.image)


def test_halo_basis_is_the_blurred_mask():
    # independent reference: the full-resolution Gaussian of the mask
    m = np.zeros((80, 90), bool)
    m[30:44, 20:70] = True
    for s in (4.0, 11.0, 20.0):
        ref = ndimage.gaussian_filter(m.astype(float), s, mode="constant")
        full = halo_basis(m, s)
        assert np.abs(full - ref).max() < 0.03
        at = np.arange(0, m.size, 7)
        np.testing.assert_array_equal(halo_basis(m, s, at=at), full.ravel()[at])
    with pytest.raises(ParameterError, match="sigma_px"):
        halo_basis(m, 0.0)


def test_bad_streak_model_is_refused():
    truth, metal = part((20, 20))
    with pytest.raises(ParameterError, match="streak_model"):
        correct_metal_streaks(truth, [0.0, 1.0, 5.0], streak_model="cubic")
    with pytest.raises(ParameterError, match="model"):
        streak_bases(metal, model="cubic")
    with pytest.raises(ParameterError, match="other"):
        streak_bases(metal, model="polynomial")


def test_volume_probes_every_fourth_metal_slice_of_each_run():
    from ctseg.beam_hardening import STREAK_PROBE_STEP, correct_streaks_volume

    vol = np.zeros((14, 16, 16))
    for k in (1, 4, 5, 6, 8, 9, 10, 11, 12, 13):  # runs of 1, 3 and 6 slices through metal
        vol[k, 6:10, 6:10] = 100.0
    assert STREAK_PROBE_STEP == 4
    out, weights, probed, _ = correct_streaks_volume(vol, gray_scale=(0.0, 2.55), levels_255=[0.0, 255.0])
    assert probed == 4  # slices 1, 4, 8 and 12
    assert weights == [0.0] * 14 and np.array_equal(out, vol)


def test_volume_streaks_corrected_on_every_metal_slice_as_slice_by_slice():
    from ctseg.beam_hardening import correct_streaks, correct_streaks_volume, metal_slices
    from ctseg.levels import volume_levels
    from ctseg.params import resolve
    from ctseg.phantoms import make_volume
    from ctseg.phantoms3d import make_part_3d

    p = resolve(None)
    for vol, streaky in ((make_volume(6, 96, seed=1, simulate=True).image, True),
                         (make_part_3d(32, seed=1).image, False)):
        vol = np.asarray(vol, float)
        scale, levels, _, _ = volume_levels(vol, p, 0)
        out, weights, probed, halo_px = correct_streaks_volume(vol, p, gray_scale=scale, levels_255=levels)
        ref = [correct_streaks(vol[k], p, gray_scale=scale, levels_255=levels) for k in range(len(vol))]
        n_metal = int(metal_slices(vol, levels / scale[1] + scale[0], p.streak_sigma_px).sum())
        assert probed < n_metal
        assert (max(weights) > 0) == streaky
        # streaks: every slice as alone; none: the slices not probed had none either
        np.testing.assert_array_equal(weights, [f.weight for f in ref])
        np.testing.assert_array_equal(halo_px, [f.halo_px for f in ref])
        np.testing.assert_array_equal(out, np.stack([f.image for f in ref]))
