"""The number of sites from the boundary length (ctseg/site_budget.py) and its use in the
2D pipeline."""
import numpy as np
import pytest

import ctseg
from ctseg.errors import ParameterError
from ctseg.params import DEFAULTS
from ctseg.pipeline import default_n_sites
from ctseg.site_budget import DENSE_SPACING_FRACTION, boundary_length, site_budget


def discs(shape, centres, radius, rng=None, noise=2.0, contrast=100.0):
    yy, xx = np.mgrid[:shape[0], :shape[1]]
    img = np.zeros(shape)
    for cy, cx in centres:
        img[(yy - cy) ** 2 + (xx - cx) ** 2 < radius ** 2] = contrast
    if rng is not None:
        img = img + rng.normal(0.0, noise, shape)
    return img


def grid_centres(n, spacing=20, offset=12):
    k = int(np.ceil(np.sqrt(n)))
    return [(offset + spacing * (i // k), offset + spacing * (i % k)) for i in range(n)]


def test_boundary_length_of_a_disc_and_of_noise():
    rng = np.random.default_rng(0)
    length, edges = boundary_length(discs((100, 100), [(50, 50)], 20, rng))
    assert abs(length - 2 * np.pi * 20) < 0.2 * 2 * np.pi * 20
    assert edges.dtype == bool and edges.shape == (100, 100)
    assert boundary_length(rng.normal(0, 1, (100, 100)))[0] < 0.01 * 100 * 100
    assert boundary_length(np.full((50, 60), 7.0)) == (0.0, pytest.approx(np.zeros((50, 60), bool)))


@pytest.mark.parametrize("sd", [20.0, 25.0, 30.0])  # from a third to a half of the step
def test_noise_of_a_quantized_scan_from_its_share_of_zero_differences(sd):
    # a windowed medical scan: noise below its gray step, most neighbours exactly equal
    from ctseg.site_budget import _noise_sigma

    rng = np.random.default_rng(int(sd))
    step = 62.5
    img = np.round(rng.normal(0.0, sd, (300, 300)) / step) * step
    assert abs(_noise_sigma(img) - sd) < 0.12 * sd
    # a low-contrast disc (3 sd) in that noise: its edge is found, not taken for noise
    disc = np.round((discs((300, 300), [(150, 150)], 60, contrast=3 * sd)
                     + rng.normal(0.0, sd, (300, 300))) / step) * step
    length, _ = boundary_length(disc)
    assert length > 0.5 * 2 * np.pi * 60


def test_site_count_is_monotone_in_the_boundary_length():
    rng = np.random.default_rng(1)
    counts, lengths = [], []
    for n in (0, 4, 16, 36, 64, 100):
        img = discs((200, 200), grid_centres(n, spacing=19, offset=10), 6, rng)
        k, report = site_budget(img)
        counts.append(k)
        lengths.append(report["boundary_px"])
    assert all(b >= a for a, b in zip(counts, counts[1:])), counts
    assert all(b > a for a, b in zip(lengths, lengths[1:])), lengths
    assert counts[-1] > 2 * counts[0]


def test_a_flat_slice_gets_the_minimum():
    for shape in ((64, 64), (512, 512), (94, 103)):
        n, report = site_budget(np.zeros(shape))
        assert n == default_n_sites(shape) and report["rule"] == "area"
    noisy = np.random.default_rng(2).normal(100, 5, (256, 256))
    assert site_budget(noisy)[0] == default_n_sites((256, 256))


def test_the_rule_terms_and_the_cap():
    rng = np.random.default_rng(3)
    sparse = discs((128, 128), grid_centres(9, spacing=40, offset=20), 9, rng)
    n, r = site_budget(sparse)
    assert r["rule"] == "boundary" and r["dense_sites"] < n
    assert n == r["boundary_sites"] == round(r["boundary_px"] / DEFAULTS.boundary_px_per_site)
    img = discs((128, 128), grid_centres(36, spacing=20, offset=10), 6, rng)
    n, r = site_budget(img)
    assert r["rule"] == "dense" and n == r["dense_sites"] > r["boundary_sites"]
    assert n == round(r["boundary_px"] ** 2 / img.size / DENSE_SPACING_FRACTION ** 2)
    assert r["n_sites"] == n and r["area_sites"] == default_n_sites(img.shape)
    capped, rc = site_budget(img, min_pixels_per_site=64.0)
    assert rc["rule"] == "boundary_cap" and capped == round(img.size / 64.0)
    assert site_budget(img, site_rule="area")[0] == default_n_sites(img.shape)
    assert site_budget(img, site_rule="area")[1]["boundary_px"] is None
    tiny = np.zeros((4, 4))
    tiny[:, 2:] = 1.0
    assert site_budget(tiny)[0] == 16  # at most one per pixel
    with pytest.raises(ParameterError):
        site_budget(img, site_rule="perimeter")
    with pytest.raises(ParameterError):
        site_budget(img, boundary_px_per_site=0.0)


def test_deterministic():
    img = discs((96, 96), grid_centres(16), 6, np.random.default_rng(4))
    assert site_budget(img) == site_budget(img.copy())


def test_a_machined_part_keeps_the_size_rule():
    """The simulator's 512 x 512 slices have 4000-5500 px of edges: their count stays
    the size rule's (their accuracy and time with it)."""
    from ctseg.phantoms import make_phantom

    p = make_phantom(512, seed=0)
    n, report = site_budget(p.image)
    assert n == default_n_sites((512, 512)) and report["rule"] == "area"
    assert 3000 < report["boundary_px"] < 1.5 * 512 * 512 / DEFAULTS.pixels_per_site * \
        DEFAULTS.boundary_px_per_site


def test_explicit_n_sites_is_honoured():
    img = discs((48, 48), grid_centres(4, spacing=22), 6, np.random.default_rng(5))
    seg = ctseg.segment_image(img, n_sites=60)
    assert seg.diagnostics["n_sites"] == 60
    assert seg.diagnostics["sites"]["rule"] == "given"
    auto = ctseg.segment_image(img)
    assert auto.diagnostics["sites"]["n_sites"] == auto.diagnostics["n_sites"]
    assert auto.diagnostics["sites"]["boundary_px"] > 0


def tooth_like(rng):
    """A 94 x 103 slice: a dentin body with a 15 px pulp cavity, blurred edges, noise."""
    from scipy import ndimage

    yy, xx = np.mgrid[:94, :103]
    img = np.full((94, 103), 77.0)
    img[((yy - 47) / 38.0) ** 2 + ((xx - 51) / 44.0) ** 2 < 1] = 163.0
    cavity = (yy - 40) ** 2 + (xx - 58) ** 2 < 7.5 ** 2
    img[cavity] = 18.0
    img = ndimage.gaussian_filter(img, 1.2) + rng.normal(0, 2.3, img.shape)
    return img, cavity


def test_a_small_slice_with_a_cavity_gets_enough_sites():
    """The size rule gives 76 sites (triangles about 10 px across, 7 vertices on the
    cavity's outline, cavity Dice 0.92); the boundary rule gives 119 (10 vertices on the
    outline, Dice 0.98)."""
    from ctseg.raster import label_image

    img, cavity = tooth_like(np.random.default_rng(6))
    n, report = site_budget(img)
    assert report["rule"] == "boundary" and n > 1.4 * default_n_sites(img.shape)
    scores = {}
    for rule in ("boundary", "area"):
        seg = ctseg.segment_image(img, site_rule=rule)
        d = np.abs(np.hypot(seg.points[:, 0] - 58, seg.points[:, 1] - 40) - 7.5)
        found = label_image(seg.points, seg.triangles, seg.material, seg.shape) == 0
        dice = 2 * np.sum(found & cavity) / (found.sum() + cavity.sum())
        scores[rule] = (seg.diagnostics["n_sites"], int(np.sum(d < 1.5)), dice)
    assert scores["boundary"][0] == n
    assert scores["boundary"][1] >= 9, scores  # vertices within 1.5 px of the outline
    assert scores["boundary"][2] > 0.95 and scores["boundary"][2] > scores["area"][2], scores
