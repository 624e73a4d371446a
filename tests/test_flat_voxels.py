"""Flat voxels of a stack (ctseg.density.flat_voxels): the in-plane rule of flat_pixels in
each slice, and no flat voxel on a ramp across the slices, where a face parallel to the
slices is blurred across two or three of them."""
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from ctseg.density import flat_pixels, flat_voxels
from ctseg.intensity import gray_scale
from ctseg.levels import material_levels


def _upright_tube(n=48, blur=0.8, seed=1):
    """An aluminium tube standing upright in air: its end faces and bore ends are parallel
    to the slices."""
    z, y, x = np.indices((n, n, n))
    r2 = (y - n / 2) ** 2 + (x - n / 2 + 2) ** 2
    truth = ((r2 < 11 ** 2) & (z > 6) & (z < n - 6)).astype(int)
    truth[(r2 < 16) & (z > 15) & (z < n - 15)] = 0
    gray = np.array([1000.0, 9000.0])[truth]
    if blur:
        gray = gaussian_filter(gray, blur)
    return gray + np.random.default_rng(seed).normal(0, 400, truth.shape), truth


def test_without_across_it_is_flat_pixels_per_slice():
    vol, _ = _upright_tube()
    expected = np.stack([flat_pixels(sl) for sl in vol])
    assert np.array_equal(flat_voxels(vol, across=False), expected)


def test_the_ramp_voxels_across_the_end_faces_are_not_flat():
    vol, truth = _upright_tube()
    across = flat_voxels(vol)
    # the partial-volume slices at the tube's end faces, inside the tube's cross-section
    z, y, x = np.indices(vol.shape)
    section = (y - 24) ** 2 + (x - 22) ** 2 < 7 ** 2
    for k in (6, 41):
        assert across[k][section[k]].mean() < 0.2
        assert flat_voxels(vol, across=False)[k][section[k]].mean() > 0.8
    # only voxels near faces parallel to the slices are dropped
    dropped = flat_voxels(vol, across=False) & ~across
    near_face = np.abs(np.diff(truth, axis=0, prepend=truth[:1])).astype(bool)
    near_face |= np.roll(near_face, 1, axis=0) | np.roll(near_face, -1, axis=0)
    assert dropped[~near_face].mean() < 1e-3


def test_faces_parallel_to_the_slices_make_no_level():
    vol, _ = _upright_tube()
    scale = gray_scale(vol, 0.0, 100.0)
    per_slice, _ = material_levels(vol, scale)
    across, _ = material_levels(vol, scale, volume=True)
    assert len(per_slice) == 3  # the partial-volume slices alone make a third level
    assert len(across) == 2


@pytest.mark.parametrize("seed", range(3))
def test_sharp_steps_between_slices_stay_flat(seed):
    # independently reconstructed slices: no blur across z, a face on a slice boundary
    vol, _ = _upright_tube(blur=0.0, seed=seed)
    vol = np.stack([gaussian_filter(sl, 0.8) for sl in vol])
    assert np.array_equal(flat_voxels(vol), flat_voxels(vol, across=False))


def test_constant_and_noise_only_stacks():
    assert flat_voxels(np.full((4, 6, 6), 3.0)).all()
    noise = np.random.default_rng(0).normal(0, 1, (20, 32, 32))
    assert np.mean(flat_voxels(noise, across=False) & ~flat_voxels(noise)) < 1e-3


def test_a_stack_must_be_3d():
    from ctseg.errors import InputError
    with pytest.raises(InputError, match="3D"):
        flat_voxels(np.zeros((4, 4)))


def _ramps_numpy(smooth, noise, full):
    """The ramp rule written with numpy arrays (the slow reference of the compiled pass)."""
    up, down = smooth[2:] - smooth[1:-1], smooth[1:-1] - smooth[:-2]
    step = np.minimum(np.abs(up), np.abs(down))
    noise_k, full_k = noise[1:-1, None, None], full[1:-1, None, None]
    return (np.sign(up) == np.sign(down)) & (up != 0) & (step - noise_k >= 0.5 * (full_k - noise_k))


@pytest.mark.parametrize("quantized", [False, True])
def test_the_compiled_ramp_pass_is_the_numpy_rule(quantized):
    from ctseg import _ramp

    vol, _ = _upright_tube()
    smooth = np.stack([gaussian_filter(sl, 1.0) for sl in vol]) / 9000.0
    if quantized:  # equal grays in consecutive slices: zero steps of either sign
        smooth = np.round(smooth * 20) / 20
    rng = np.random.default_rng(2)
    noise, full = rng.uniform(0, 0.01, len(vol)), rng.uniform(0.02, 0.2, len(vol))
    full[3] = np.inf  # a slice without gradient
    expected = np.ones(vol.shape, bool)
    expected[1:-1] = ~_ramps_numpy(smooth, noise, full)
    assert 0 < (~expected).sum() < expected.size
    for kernel in (_ramp.clear_ramps, _ramp.clear_ramps_parallel):
        flat = np.ones(vol.shape, bool)
        kernel(smooth, noise, full, flat)
        assert np.array_equal(flat, expected)
