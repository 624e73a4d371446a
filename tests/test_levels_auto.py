"""Material levels where the flat pixels cannot be trusted (granular and porous scans, all
partial volume) and on clipped data: ctseg.levels.material_levels' fallback rules, checked
against generated images with a known truth."""
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter, uniform_filter

import ctseg
from ctseg.intensity import rescale_gray
from ctseg.levels import clipped_extremes, flat_pixels, material_levels, pixel_material_levels
from ctseg.metrics import dice_per_label
from ctseg.phantoms import make_phantom
from ctseg.raster import label_image


def packed_disks(n=160, seed=0, levels=(50, 150), fractions=(1.0,), r=(5, 12), blur=2.0,
                 noise=9.0, fill=0.6):
    """Random disks (grains, classes 1.. by ``fractions``) on a pore background (class 0),
    blurred, noisy, rounded to uint8 (so grains near 255 are clipped). Returns the image
    and the per-pixel truth."""
    rng = np.random.default_rng(seed)
    lab = np.zeros((n, n), np.int64)
    yy, xx = np.mgrid[0:n, 0:n]
    for _ in range(20000):
        if (lab > 0).mean() >= fill:
            break
        rad = rng.uniform(*r)
        cy, cx = rng.uniform(-rad / 2, n + rad / 2, 2)
        d = np.hypot(yy - cy, xx - cx)
        if (lab[d <= 0.8 * rad] > 0).mean() > 0.1:
            continue
        cls = 1 + rng.choice(len(fractions), p=np.asarray(fractions) / sum(fractions))
        lab[(d <= rad) & (lab == 0)] = cls
    img = gaussian_filter(np.asarray(levels, float)[lab], blur) + rng.normal(0, noise, (n, n))
    return np.clip(np.round(img), 0, 255).astype(np.uint8), lab


def porous_solid(n=160, seed=0, noise=8.0, blur=2.0):
    """A porous solid: a smoothed random field cut at 40% pores (class 0) in a matrix."""
    rng = np.random.default_rng(seed)
    f = gaussian_filter(rng.normal(size=(n, n)), 5)
    lab = (f <= np.quantile(f, 0.4)).astype(int) ^ 1
    img = gaussian_filter(np.array([60.0, 170.0])[lab], blur) + rng.normal(0, noise, (n, n))
    return np.clip(np.round(img), 0, 255).astype(np.uint8), lab


def levels_of(img):
    report = {}
    g, scale = rescale_gray(np.asarray(img, float))
    levels, _ = material_levels(img, scale, report=report)
    return g, levels, report


def level_dice(g, levels, truth):
    """Dice per truth class of the pixels classified by the nearest level."""
    cls = np.searchsorted(0.5 * (levels[1:] + levels[:-1]), g)
    return dice_per_label(cls, truth, len(levels))


# (image, true number of materials, smallest per-material Dice of the level classes)
# measured (160 px, seeds 0-3): two-phase 0.927-0.956, three-phase 0.764-0.883 (0.821 at
# seeds 0-1), porous 0.966-0.981
CASES = [
    ("two-phase", lambda s: packed_disks(seed=s), 2, 0.9),
    ("three-phase", lambda s: packed_disks(seed=s, levels=(40, 110, 190),
                                           fractions=(0.6, 0.4), blur=1.8, noise=8.0), 3, 0.78),
    ("porous", lambda s: porous_solid(seed=s), 2, 0.95),
]


@pytest.mark.parametrize("name,make,k_true,dice_min", CASES, ids=[c[0] for c in CASES])
@pytest.mark.parametrize("seed", [0, 1])
def test_granular_levels_match_truth(name, make, k_true, dice_min, seed):
    img, truth = make(seed)
    g, levels, report = levels_of(img)
    assert len(levels) == k_true, report
    assert report["method"] == "low_gradient"
    assert report["clipped"] is False
    assert np.min(level_dice(g, levels, truth)) >= dice_min


def test_the_flat_pixels_alone_fail_here():
    """Without the low-gradient rule the flat pixels give one level on this image (all of
    it counts as flat): the test above then fails."""
    img, _ = packed_disks(seed=0)
    g, scale = rescale_gray(img.astype(float))
    flat = flat_pixels(img.astype(float))
    assert flat.mean() >= 0.995
    assert len(pixel_material_levels(g, flat)[0]) == 1
    assert len(levels_of(img)[1]) == 2


@pytest.mark.parametrize("seed", [1, 5])  # seeds where no low-gradient pixel finds the pores
def test_a_phase_too_fine_for_flat_pixels_is_found_beyond_the_tail(seed, monkeypatch):
    """Sintered powder: the pores are so thin that no low-gradient pixel sits in one, but
    >= 1% of the pixels lie further than the separation below the grains' level, which one
    material cannot explain; the pore level comes from that tail. Without the rule the
    levels are the grains' alone (checked with the rule switched off)."""
    import ctseg.levels_auto as levels_auto
    from ctseg.phantoms_granular import image_levels, make_granular

    p = make_granular("sintered", 160, seed=seed)
    g, levels, report = levels_of(p.image)
    assert len(levels) == 2 and report["tail_levels_255"] == [round(levels[0], 2)], report
    offset, factor = rescale_gray(p.image.astype(float))[1]
    true_255 = (np.array(image_levels("sintered")) - offset) * factor
    assert abs(levels[0] - true_255[0]) < 8.0 and abs(levels[1] - true_255[1]) < 3.0
    assert np.min(level_dice(g, levels, p.truth)) >= 0.8
    monkeypatch.setattr(levels_auto, "TAIL_MIN_FRACTION", 2.0)
    assert len(levels_of(p.image)[1]) == 1


def test_the_tail_counts_regions_not_outlying_pixels():
    """Isolated outlying pixels (hot pixels, spikes) spread over exactly their 3 x 3 window
    by the smoothing, and hold no material however many they are; blobs of a denser phase
    at under 1% of the pixels (the old share) but at least TAIL_MIN_FRACTION do."""
    from ctseg.levels_auto import TAIL_MIN_FRACTION, tail_levels

    sep = lambda g: 20.0  # noqa: E731
    spikes = np.full((200, 200), 20.0)
    spikes[4::8, 4::8] = 255.0  # 1.6% of the pixels, each alone in its window
    assert tail_levels(spikes, [20.0], sep) == []
    blobs = np.full((200, 200), 20.0)
    for k in range(6):  # six 4 x 4 dense grains
        blobs[20 + 35 * k:24 + 35 * k, 30 + 30 * k:34 + 30 * k] = 255.0
    sm = np.asarray(uniform_filter(blobs, 3, mode="nearest"))
    share = float((sm > 40.0).mean())
    assert TAIL_MIN_FRACTION <= share < 0.01
    (level,) = tail_levels(blobs, [20.0], sep)
    assert 200.0 < level <= 255.0


def _spots(dense, dark, n=200, seed=0):
    """Air with an aluminium block (both flat enough for levels) and spots of radius 3 px,
    too small for flat pixels of their own: nine dense ones inside the block (0.8% of the
    pixels), six dark ones in the air (0.6%)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:n, 0:n]
    lab = np.zeros((n, n), int)
    lab[50:150, 50:150] = 1
    for cx in (70, 100, 130):
        for cy in (70, 100, 130):
            lab[(np.hypot(yy - cy, xx - cx) < 3.2) & dense] = 2
        for cy in (20, 180):
            lab[(np.hypot(yy - cy, xx - cx) < 3.2) & dark] = 3
    img = gaussian_filter(np.array([60.0, 150.0, 240.0, 0.0])[lab], 1.0) + rng.normal(0, 3, (n, n))
    return img, lab


def test_with_trusted_flat_pixels_the_tail_adds_a_denser_material_only():
    """Flat pixels trusted: the dense spots get a level above the highest (the tail rule);
    the dark spots, which the same rule would find below the lowest, do not (with trusted
    flat pixels the dark bands between metal parts lie there); without the dense spots
    the levels are the flat pixels' two."""
    from ctseg.levels_auto import tail_levels
    from ctseg.params import DEFAULTS

    img, lab = _spots(dense=True, dark=True)
    g, levels, report = levels_of(img)
    assert report["method"] == "flat_pixels" and len(report["flat_levels_255"]) == 2
    assert len(levels) == 3 and report["tail_levels_255"] == [round(levels[-1], 2)]
    assert levels[-1] > levels[1] + 50
    base = max(DEFAULTS.merge_floor_255, DEFAULTS.merge_k * report["sigma_255"])
    below, above = tail_levels(g, report["flat_levels_255"], lambda x: base + DEFAULTS.merge_rel * x)
    assert below < report["flat_levels_255"][0] and above == pytest.approx(levels[-1])
    assert len(levels_of(_spots(dense=False, dark=True)[0])[1]) == 2


def test_a_dense_phase_under_one_percent_is_found_beyond_the_tail():
    """The 200 x 200 porous casting: its dense inclusions leave no flat pixel and hold 0.8%
    of the pixels beyond the separation above the metal, in regions; their level comes
    from the tail and the mesh gives them a material (Dice 0 when the tail needed 1%)."""
    from ctseg.phantoms_granular import make_granular

    p = make_granular("casting", 200, seed=0)
    g, levels, report = levels_of(p.image)
    assert len(levels) == 3 and report["tail_levels_255"] == [round(levels[-1], 2)], report
    assert level_dice(g, levels, p.truth)[2] >= 0.6
    seg = ctseg.segment_image(p.image)
    pred = label_image(seg.points, seg.triangles, seg.material, seg.shape)
    assert len(seg.material_gray) == 3
    assert dice_per_label(pred, p.truth, 3)[2] >= 0.6


def test_clipped_grains_are_a_material_of_their_own():
    """Dense grains saturating at 255 (uint8): the clipped voxels get a level at 255, are
    reported, and are not merged into the grains below them."""
    img, truth = packed_disks(seed=2, levels=(40, 115, 254), fractions=(0.88, 0.12))
    low, high = clipped_extremes(img)
    assert not low.any() and high.any()
    g, levels, report = levels_of(img)
    assert report["clipped"] is True
    assert report["clipped_high_fraction"] == pytest.approx(float((img == 255).mean()), abs=1e-6)
    assert report["clipped_fraction"] > 0.005
    assert len(levels) == 3 and levels[-1] == 255.0
    assert np.min(level_dice(g, levels, truth)) >= 0.85  # measured 0.888
    seg = ctseg.segment_image(img)
    assert seg.n_materials == 3
    assert seg.diagnostics["levels"]["clipped"] is True
    assert seg.diagnostics["levels"]["levels_255"][-1] == 255.0


def test_clipped_with_trusted_flat_pixels():
    """A clipped bright region next to a flat one: flat pixels trusted, the clipped end
    still a level of its own, even when it is as close as the rule would merge."""
    rng = np.random.default_rng(3)
    img = np.full((96, 96), 215.0) + rng.normal(0, 3, (96, 96))
    img[:, :40] = 20 + rng.normal(0, 3, (96, 40))
    img[30:60, 60:90] = 253 + rng.normal(0, 3, (30, 30))  # a third clipped at 255
    img = np.clip(np.round(img), 0, 255).astype(np.uint8)
    g, levels, report = levels_of(img)
    assert report["method"] == "flat_pixels" and report["clipped"] is True
    assert levels[-1] == 255.0 and len(levels) == 3
    assert len(report["flat_levels_255"]) == 2  # the flat-pixel rule merged it


def test_constant_and_noise_images_give_one_material():
    for img in (np.full((64, 64), 7.0),
                100 + np.random.default_rng(0).normal(0, 5, (64, 64))):
        g, levels, report = levels_of(img)
        assert len(levels) == 1, report
        assert report["clipped"] is False
    assert ctseg.segment_image(np.full((48, 48), 7.0), n_sites=40).n_materials == 1


def test_simulated_slice_keeps_the_flat_pixel_rule():
    """ctseg's simulator: flat pixels trusted, nothing clipped (its outputs are unchanged)."""
    p = make_phantom(128, seed=0)
    _, levels, report = levels_of(p.image)
    assert report["method"] == "flat_pixels" and report["clipped"] is False
    assert report["reason"] == "flat pixels trusted"
    assert len(levels) == int(p.truth.max()) + 1


def test_report_in_segment_image_diagnostics():
    img, truth = porous_solid(seed=0)
    seg = ctseg.segment_image(img)
    rep = seg.diagnostics["levels"]
    assert rep["method"] == "low_gradient" and seg.n_materials == 2
    assert rep["k_chosen"] == 2 and rep["k_candidates"][1]["k"] == 2
    assert rep["k_candidates"][1]["min_gap_over_separation"] >= 1.0
    assert {"criterion", "reason", "flat_fraction", "low_gradient_fraction"} <= set(rep)


def test_a_volume_s_low_gradient_voxels_see_the_3d_gradient():
    """Packed balls in 3D: every voxel counts as flat, so the levels come from the
    low-gradient voxels. Found slice by slice, the voxels on a ball's cap (no in-plane
    gradient) make a false middle level; with the 3D gradient (volume_levels of a whole
    volume) the two phases alone remain, near their true grays."""
    from ctseg.levels import volume_levels
    from ctseg.params import resolve
    from ctseg.phantoms_granular3d import make_granular_3d

    vol = make_granular_3d(48, seed=0).image.astype(float)
    scale, levels, _, sample = volume_levels(vol, resolve(None))
    assert len(sample) == vol.shape[0] and len(levels) == 2
    true_255 = (np.array([0.0, 1.0]) - scale[0]) * scale[1]
    assert np.all(np.abs(levels - true_255) < 25.0)
    report = {}
    per_slice, _ = material_levels(vol, scale, report=report)  # volume=False
    assert report["method"] == "low_gradient" and len(per_slice) == 3


def _ball_with_air_cut_at_zero(n=40, seed=0):
    """A uint16 ball in air whose air noise (sd 800 about 1000) is cut at 0: about 10% of the
    air voxels read 0, scattered, not a region."""
    z, y, x = np.indices((n, n, n))
    truth = (((z - n / 2) ** 2 + (y - n / 2) ** 2 + (x - n / 2) ** 2) < (0.3 * n) ** 2).astype(int)
    noise = np.random.default_rng(seed).normal(0, 800, truth.shape)
    return (1000 + 20000 * truth + noise).clip(0, 65535).astype(np.uint16), truth


def test_noise_cut_at_the_dtype_limit_is_not_a_material():
    """Noise hits at 0 scattered through the air are its tail, not clipped data: no level of
    their own (before: a level at 0 beside the air's, and given 2 materials, the air's tail
    took one of them and the ball's partial volume went to the other). The same volume with
    the whole ball at 0 too (a region) is clipped data."""
    vol, truth = _ball_with_air_cut_at_zero()
    assert 0.05 < (vol == 0).mean() < 0.15
    low, high = clipped_extremes(vol)
    assert not low.any() and not high.any()
    saturated = vol.copy()
    saturated[(vol == 0) | (truth == 1)] = 0  # the same voxels at 0 and the ball: a region
    assert clipped_extremes(saturated)[0].sum() == (saturated == 0).sum()
    scale = ctseg.intensity.gray_scale(vol)
    auto, _ = material_levels(vol, scale)
    given, _ = material_levels(vol, scale, n_materials=2)
    air_255, ball_255 = (np.array([1000.0, 21000.0]) - scale[0]) * scale[1]
    assert len(auto) == 2
    for levels in (auto, given):
        assert abs(levels[0] - air_255) < 2.0 and abs(levels[1] - ball_255) < 3.0
    seg = ctseg.segment_volume(vol, n_materials=2, mode="3d")
    assert seg.n_materials == 2
    assert ctseg.metrics.evaluate_tetra(seg, truth)["min_dice"] > 0.93


def _pin_in_disc(n, r, seed=0, levels=(20.0, 120.0, 360.0), ss=4):
    """Air, an aluminium disc and a steel pin of radius ``r`` px inside it (under 0.3% of
    the pixels: beyond the 99.5th percentile), 4 x 4 partial volume, blur 0.8 px, noise 5%
    of the air-aluminium contrast. Returns the image and the per-pixel truth."""
    rng = np.random.default_rng(seed)
    y, x = (np.mgrid[0:n * ss, 0:n * ss] + 0.5) / ss - 0.5
    c = n / 2
    lab = np.zeros(y.shape, int)
    lab[(x - c) ** 2 + (y - c) ** 2 < (0.4 * n) ** 2] = 1
    lab[(x - c - 0.13 * n - 0.3) ** 2 + (y - c + 0.07 * n - 0.2) ** 2 < r ** 2] = 2
    blocks = (n, ss, n, ss)
    img = np.asarray(levels)[lab].reshape(blocks).mean(axis=(1, 3))
    truth = np.stack([(lab == k).reshape(blocks).mean(axis=(1, 3)) for k in range(3)]).argmax(0)
    img = gaussian_filter(img, 0.8) + rng.normal(0.0, 0.05 * (levels[1] - levels[0]), (n, n))
    return img, truth


def test_a_small_dense_insert_keeps_its_contrast_in_the_gray_map():
    """The gray map's 255 moves up to a pin that the 99.5th percentile clips (a 3 x 3
    square of it lies beyond); hot pixels, a pair of them and a bright line 1 px wide do
    not move it (the percentile map, as before)."""
    from ctseg.intensity import gray_scale

    img, truth = _pin_in_disc(256, 4)
    assert (truth == 2).mean() < 0.005
    offset, factor = gray_scale(img)
    g = (img - offset) * factor
    assert np.median(g[truth == 2]) > 230 and np.median(g[truth == 1]) < 100
    plain, _ = _pin_in_disc(256, 0)
    expect = np.percentile(plain, [0.5, 99.5])
    for r, c in ((20, 30), (200, 40), (100, 100), (101, 100)):
        plain[r, c] = 1000.0
    plain[5:250, 128] = 900.0
    offset, factor = gray_scale(plain)
    assert offset == pytest.approx(expect[0], rel=1e-3)
    assert offset + 255.0 / factor == pytest.approx(np.percentile(plain, 99.5))


@pytest.mark.parametrize("n, r", [(128, 3), (256, 4), (256, 6)])
def test_a_small_dense_insert_is_a_material_of_its_own(n, r):
    """A steel pin of 0.04-0.3% of the slice: its own material, found (it was clipped onto
    the aluminium's gray 229-255 and merged: 2 materials, pin Dice 0) and when 3 are asked
    for (the third was a partial-volume rim: pin Dice 0). Measured: 0.63, 0.78, 0.91."""
    from ctseg.metrics import matched_dice_per_label

    img, truth = _pin_in_disc(n, r)
    for params in ({}, {"n_materials": 3}):
        seg = ctseg.segment_image(img, **params)
        pred = label_image(seg.points, seg.triangles, seg.material, seg.shape)
        assert seg.n_materials == 3
        assert matched_dice_per_label(pred, truth)[2] >= 0.5


def test_a_dense_region_needs_a_3x3_core_to_be_a_material():
    """Below TAIL_MIN_FRACTION of the pixels a region beyond the highest level is a
    material only if a whole 3 x 3 square of its pixels lies beyond: a 2 x 2 blob of hot
    pixels (a 16-px region after the 3 x 3 smoothing) is not; a 4 x 4 one is."""
    from ctseg.levels_auto import TAIL_MIN_FRACTION, TAIL_MIN_REGION_PX, tail_levels

    g = np.full((200, 200), 100.0)
    g[:, :100] = 10.0
    hot = g.copy()
    hot[50:52, 150:152] = 250.0
    sep = lambda x: 30.0  # noqa: E731
    region = (uniform_filter(hot, 3) > 130.0).sum()
    assert TAIL_MIN_REGION_PX <= region < TAIL_MIN_FRACTION * hot.size
    assert tail_levels(hot, [10.0, 100.0], sep) == []
    hot[50:54, 150:154] = 250.0
    (level,) = tail_levels(hot, [10.0, 100.0], sep)
    assert level > 200.0


def test_small_features_get_more_sites_with_the_density_boost():
    """density_small_boost (off by default) gives the pin's edges four times the density:
    twice the sites around it, and its Dice 0.78 -> 0.97 (256 px, radius 4)."""
    from ctseg.metrics import matched_dice_per_label

    img, truth = _pin_in_disc(256, 4)
    dice = []
    for boost in (1.0, 4.0):
        seg = ctseg.segment_image(img, density_small_boost=boost)
        pred = label_image(seg.points, seg.triangles, seg.material, seg.shape)
        near = np.hypot(*(seg.points - np.argwhere(truth == 2).mean(0)[::-1]).T) < 8
        dice.append((matched_dice_per_label(pred, truth)[2], int(near.sum())))
    assert dice[1][0] >= 0.9 > dice[0][0] and dice[1][1] > 1.5 * dice[0][1], dice
