"""The fan-beam CT simulator (ctseg.phantoms_fan, ctseg.fan_beam, ctseg.xray_spectra)
checked against closed forms: chord lengths, FBP of a monochromatic disc, cupping from beam
hardening, 8-bit saturation, determinism and the truth's area fractions."""
import numpy as np
import pytest

from ctseg.fan_beam import Scene, fan_fbp, fan_geometry, path_lengths
from ctseg.phantoms_fan import PARTS, make_fan_phantom, simulate_fan_ct
from ctseg.xray_spectra import (MASS_ATTENUATION, TABLE_KEV, effective_attenuation,
                                linear_attenuation, mass_attenuation, tungsten_spectrum)

ALL_OFF = dict(photons=0, scatter=0, ring=0, crosstalk=0)


def _disc_scene(cx, cy, r):
    sc = Scene()
    sc.disc(cx, cy, r, 1)
    return sc


def test_disc_chords_are_exact():
    g = fan_geometry(64, n_views=16)
    cx, cy, r = 35.0, 28.0, 14.0
    o, d = g.rays(slice(None))
    o, d = o.reshape(-1, 2), d.reshape(-1, 2)
    got = path_lengths(_disc_scene(cx, cy, r), o, d, 2)[:, 1]
    dist = np.abs((cx - o[:, 0]) * d[:, 1] - (cy - o[:, 1]) * d[:, 0])
    want = 2 * np.sqrt(np.maximum(r * r - dist ** 2, 0))
    assert np.abs(got - want).max() < 1e-9
    assert (want > 0).mean() > 0.1  # the rays do cross the disc


def test_rotated_box_ellipse_and_painting_order():
    sc = Scene()
    sc.box(0.0, 0.0, 10.0, 4.0, np.pi / 4, 1)  # a rotated rectangle
    sc.ellipse(0.0, 0.0, 2.0, 1.0, 0.0, 2)  # painted over it
    sc.disc(0.0, 0.0, 0.5, 0)  # a hole in the ellipse
    # along the box's long axis: 20 through the box, of which 2 a through the ellipse's
    # (rotated) chord, minus the hole's 1
    u = np.array([[np.cos(np.pi / 4), np.sin(np.pi / 4)]])
    lengths = path_lengths(sc, -30 * u, u, 3)[0]
    # the ellipse along direction (1, 1)/sqrt 2: x = t/sqrt2, y = t/sqrt2, x^2/4 + y^2 = 1
    ell = 2 * np.sqrt(1 / (1 / 8 + 1 / 2))
    assert lengths[0] == pytest.approx(1.0)
    assert lengths[2] == pytest.approx(ell - 1.0)
    assert lengths[1] == pytest.approx(20.0 - ell)
    # a ray missing everything
    assert path_lengths(sc, [[-30.0, 20.0]], [[1.0, 0.0]], 3).sum() == 0


def test_fan_fbp_reconstructs_a_monochromatic_disc():
    size, mu = 96, 0.8  # 1/cm
    pixel_mm = 0.5
    sc = _disc_scene(52.0, 44.0, 25.0)
    mono = (np.array([1.0]), np.array([[0.0], [mu]]))
    img = simulate_fan_ct(sc, 2, mono, size, pixel_mm, **ALL_OFF)
    yy, xx = np.mgrid[:size, :size]
    rr = np.hypot(xx - 52.0, yy - 44.0)
    inner = img[rr < 21]
    assert abs(inner.mean() - mu) < 0.02 * mu
    assert np.abs(inner - mu).max() < 0.05 * mu
    assert np.abs(img[rr > 29]).max() < 0.05 * mu


def test_fbp_of_zero_line_integrals_is_zero():
    g = fan_geometry(32, n_views=40)
    assert np.abs(fan_fbp(np.zeros((g.n_views, g.n_det)), g)).max() == 0


def test_beam_hardening_cups_a_thick_steel_disc():
    size, pixel_mm = 96, 0.4  # a 2.4 cm steel disc
    sc = _disc_scene(47.5, 47.5, 30.0)
    e, w = tungsten_spectrum(150.0)
    ww = w * e / (w @ e)
    poly = (ww, np.array([np.zeros_like(e), linear_attenuation("steel", e)]))
    img = simulate_fan_ct(sc, 2, poly, size, pixel_mm, **ALL_OFF)
    yy, xx = np.mgrid[:size, :size]
    rr = np.hypot(xx - 47.5, yy - 47.5)
    centre, rim = img[rr < 5].mean(), img[(rr > 22) & (rr < 26)].mean()
    assert centre < 0.9 * rim  # cupping
    # and a monochromatic scan of the same disc is flat
    mono = (np.array([1.0]), np.array([[0.0], [2.0]]))
    flat = simulate_fan_ct(sc, 2, mono, size, pixel_mm, **ALL_OFF)
    assert abs(flat[rr < 5].mean() / flat[(rr > 22) & (rr < 26)].mean() - 1) < 0.02


def test_scatter_and_rings_add_their_artefacts():
    size, pixel_mm = 64, 0.5
    sc = _disc_scene(31.5, 31.5, 18.0)
    e, w = tungsten_spectrum(150.0)
    poly = (w * e / (w @ e), np.array([np.zeros_like(e), linear_attenuation("copper", e)]))
    clean = simulate_fan_ct(sc, 2, poly, size, pixel_mm, **ALL_OFF)
    scattered = simulate_fan_ct(sc, 2, poly, size, pixel_mm, **dict(ALL_OFF, scatter=0.05))
    assert scattered[28:36, 28:36].mean() < clean[28:36, 28:36].mean() - 0.05
    empty = Scene()
    no_rings = simulate_fan_ct(empty, 2, poly, size, pixel_mm, **ALL_OFF)
    rings = simulate_fan_ct(empty, 2, poly, size, pixel_mm, **dict(ALL_OFF, ring=0.01))
    # the transmission is summed in float32 (sum(w) = 1 to ~1e-7), so an empty scene
    # reconstructs to 0 within float32 rounding: 1.04e-7 on numpy 1.24 on an Intel Xeon
    assert np.abs(no_rings).max() < 1e-5 and rings.std() > 1e-3


def test_attenuation_table_and_spectrum():
    for k, e in enumerate(TABLE_KEV):  # the table's own values at its energies
        assert mass_attenuation("Cu", e) == pytest.approx(MASS_ATTENUATION["Cu"][k])
    # log-log interpolation lies between the neighbours
    assert MASS_ATTENUATION["Fe"][6] < mass_attenuation("Fe", 70.0) < MASS_ATTENUATION["Fe"][5]
    e0, w0 = tungsten_spectrum(150.0, {"aluminium": 1.0})
    e1, w1 = tungsten_spectrum(150.0, {"aluminium": 1.0, "copper": 2.0})
    assert e1 @ w1 > e0 @ w0  # filtering hardens the beam
    assert tungsten_spectrum(120.0)[0].max() < 120.0
    order = ["air", "peek", "polymer", "cfrp", "aluminium", "alumina", "titanium", "steel", "copper"]
    mus = [effective_attenuation(m, e1, w1, 0.3) for m in order]
    assert mus == sorted(mus)


@pytest.mark.parametrize("part", PARTS)
def test_phantom_truth_conventions(part):
    p = make_fan_phantom(part, size=64, seed=2, n_views=96)
    n = len(p.names)
    assert p.names[0] == "air" and p.image.shape == (64, 64) and p.image.dtype == np.float32
    assert p.truth_hr.shape == (64 * p.supersample,) * 2 and p.truth.dtype == np.uint8
    assert set(np.unique(p.truth_hr)) == set(range(n))
    # truth is the majority of the supersampled labels
    s = p.supersample
    frac = np.stack([(p.truth_hr == k).reshape(64, s, 64, s).mean(axis=(1, 3)) for k in range(n)])
    assert np.array_equal(p.truth, np.argmax(frac, axis=0))
    # labels ascend in the reconstructed attenuation
    med = [np.median(p.image[p.truth == k]) for k in range(n) if np.any(p.truth == k)]
    assert med == sorted(med)


def test_truth_area_fractions_match_the_shapes():
    sc = Scene()
    sc.disc(40.0, 30.0, 20.0, 1)
    sc.box(40.0, 30.0, 6.0, 3.0, 0.3, 2)
    hr = sc.paint(80, 8)
    area = np.bincount(hr.ravel(), minlength=3) / 64.0
    assert area[2] == pytest.approx(72.0, rel=0.01)
    assert area[1] == pytest.approx(np.pi * 400 - 72.0, rel=0.005)


def test_same_seed_same_slice_other_seed_other_slice():
    a = make_fan_phantom("inserts", size=48, seed=5, n_views=64)
    b = make_fan_phantom("inserts", size=48, seed=5, n_views=64)
    c = make_fan_phantom("inserts", size=48, seed=6, n_views=64)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.truth_hr, b.truth_hr)
    assert not np.array_equal(a.image, c.image)


def test_eight_bit_clipping_saturates_the_densest_material():
    p = make_fan_phantom("inserts", size=64, seed=1, n_views=96, metals=("steel",), clip8=True)
    assert p.image.dtype == np.uint8 and p.window[0] == 0.0
    dense = p.image[p.truth == len(p.names) - 1]
    assert np.mean(dense == 255) >= 0.7
    assert np.mean(p.image[p.truth == 1] == 255) < 0.05  # the plate does not saturate
    fixed = make_fan_phantom("inserts", size=64, seed=1, n_views=96, clip8=(0.0, 1.0))
    assert fixed.window == (0.0, 1.0) and np.mean(fixed.image[fixed.truth >= 2] == 255) > 0.8


def test_metrics_accept_the_phantom():
    import ctseg
    from ctseg.metrics import evaluate

    p = make_fan_phantom("ceramic", size=64, seed=0, n_views=96)
    seg = ctseg.segment_image(p.image, n_sites=300)
    ev = evaluate(seg, p.truth, p.truth_hr, p.supersample)
    assert len(ev["dice"]) >= len(p.names) and "dice_subpixel" in ev
