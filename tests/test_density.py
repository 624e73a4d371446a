import numpy as np
import pytest
from scipy import ndimage

from ctseg import density_map
from ctseg.errors import InputError, ParameterError


def test_spec_formula_without_saturation():
    rng = np.random.default_rng(1)
    img = rng.normal(size=(30, 40)).cumsum(axis=1)
    rho = density_map(img, density_sigma_px=1.5, density_floor=0.05, density_saturation=1.0,
                      density_ridge=0.0, density_small_boost=1.0)
    # independent evaluation of SPEC 1 on the min-max normalised image
    norm = (img - img.min()) / (img.max() - img.min())
    gy, gx = np.gradient(ndimage.gaussian_filter(norm, 1.5, mode="nearest"))
    mag = np.hypot(gx, gy)
    np.testing.assert_allclose(rho, 0.05 + mag / mag.max(), rtol=1e-12, atol=1e-12)


def test_range_and_edges_get_the_density():
    img = np.zeros((40, 40))
    img[:, 20:] = 100.0
    img[10:15, 5:8] = 3.0  # a weak edge must still be dense in 'auto' mode
    rho = density_map(img, density_small_boost=1.0)
    assert rho.min() >= 0.02 - 1e-12 and rho.max() <= 1.02 + 1e-12
    assert rho[:, 19:21].min() > 0.9  # strong edge saturates
    assert rho[12, 4:6].max() > 0.9  # weak edge too (auto saturation)
    assert np.allclose(rho[30:, 30:36], 0.02)  # flat region falls to the floor


def test_small_closed_features_get_the_boost():
    """A disc of radius 3 (a pin) and a 5 x 3 blob: their edges and 2 px around them get
    density_small_boost times the density; the long straight edge does not; the flat
    pixels that measure the levels do not see the boost."""
    from ctseg.density import flat_pixels

    yy, xx = np.mgrid[:60, :60]
    img = np.zeros((60, 60))
    img[:, 40:] = 100.0
    img[(yy - 20) ** 2 + (xx - 15) ** 2 <= 9] = 300.0
    img[45:50, 10:13] = 50.0
    plain = density_map(img)  # the default: off
    boosted = density_map(img, density_small_boost=4.0)
    ratio = boosted / plain
    assert np.allclose(ratio[[20, 47], [12, 10]], 4.0)  # on the disc's and the blob's edges
    assert np.allclose(ratio[15, 15], 4.0) and np.allclose(ratio[20, 25], 1.0)  # 2 px out; 7 px
    assert np.allclose(ratio[:, 35:], 1.0)  # the long edge, 60 px: not small
    np.testing.assert_array_equal(flat_pixels(img), (density_map(img, density_ridge=0.0, density_small_boost=1.0)
                                                     - 0.02) < 0.5)


def test_constant_image_is_floor():
    assert np.all(density_map(np.full((5, 7), 3.0), density_floor=0.1) == 0.1)


@pytest.mark.parametrize("bad", [np.zeros(5), np.zeros((2, 3, 4)), np.array([[np.nan, 1], [1, 1]])])
def test_bad_images(bad):
    with pytest.raises(InputError):
        density_map(bad)


@pytest.mark.parametrize("kw", [dict(density_sigma_px=-1), dict(density_floor=0),
                                dict(density_saturation=2.0)])
def test_bad_parameters(kw):
    with pytest.raises(ParameterError):
        density_map(np.eye(4), **kw)


def test_ridge_keeps_the_peak_on_the_edge_and_narrows_the_band():
    img = np.zeros((30, 40))
    img[:, 20:] = 100.0
    flat_top = density_map(img, density_ridge=0.0)
    ridge = density_map(img, density_ridge=2.0)
    row = 15
    assert np.argmax(ridge[row]) in (19, 20) and ridge[row].max() > 0.99
    assert np.sum(ridge[row] > 0.5) < np.sum(flat_top[row] > 0.5)


@pytest.mark.parametrize("shape, spacing", [((2, 2, 2), (1.0, 1.0, 1.0)), ((3, 5, 7), (0.3, 0.1, 0.1)),
                                            ((12, 9, 4), (1.5, 0.5, 0.7))])
def test_compiled_gradient_magnitude_is_numpys(shape, spacing):
    # the one-pass kernel of density_volume against numpy.gradient (the slow reference)
    from ctseg import _gradient

    f = np.random.default_rng(len(shape) * shape[0]).normal(size=shape)
    gz, gy, gx = np.gradient(f, *spacing)
    expected = np.sqrt(gx * gx + gy * gy + gz * gz)
    for kernel in (_gradient.gradient_magnitude, _gradient.gradient_magnitude_parallel):
        out = np.empty(shape)
        kernel(f, out, *spacing)
        assert np.array_equal(out, expected)
