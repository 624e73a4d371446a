"""The density raised below a dense material's level (ctseg.density_capped) and its use by the
3D pipeline."""
import numpy as np
import pytest
from scipy import ndimage

import ctseg.pipeline3d as pipeline3d
from ctseg.density import density_volume
from ctseg.density_capped import CAP_MARGIN_PX, _near, capped_density_volume
from ctseg.errors import InputError
from ctseg.levels import volume_levels
from ctseg.params import resolve
from ctseg.phantoms3d import make_part_3d
from ctseg.stages3d import density_cap


def groove_next_to_steel(gap_vox=4, steel=1000.0, seed=0):
    """Aluminium (gray 10, noise sd 0.3) with two 3-voxel air grooves along x: one far from
    everything (walls at x = 7.5 and 10.5), one (walls at 17.5 and 20.5) ``gap_vox`` voxels
    from a steel slab (``steel``) that ends 20 voxels before the aluminium does."""
    vol = np.zeros((10, 12, 80))
    vol[:, :, 4:] = 10.0
    vol[:, :, 8:11] = 0.0
    vol[:, :, 18:21] = 0.0
    vol[:, :, 21 + gap_vox:60] = steel
    return vol + np.random.default_rng(seed).normal(0.0, 0.3, vol.shape)


def test_raised_where_the_steel_hides_a_wall_and_nowhere_else():
    vol = groove_next_to_steel()
    rho, raised = density_volume(vol), capped_density_volume(vol, cap=100.0)
    assert (raised >= rho).all() and raised.max() <= 1.02
    far_wall = rho[:, :, 10].mean()       # the far groove's wall, as the steel leaves it
    # the near groove's steel-side wall is hidden by the steel's edge: raised to show like it
    assert rho[:, :, 21].mean() < 0.3 * far_wall < 0.7 * far_wall < raised[:, :, 21].mean()
    # the far groove's walls show in the full volume already: nothing changes there
    np.testing.assert_array_equal(raised[:, :, :16], rho[:, :, :16])


def test_full_density_kept_within_the_margin_of_the_capped_voxels():
    """An independent distance: every voxel within CAP_MARGIN_PX (Euclidean, voxel units of
    the finest axis) of a voxel at or above the cap keeps density_volume's value."""
    vol = groove_next_to_steel(gap_vox=2)
    sp = (1.0, 1.0, 2.0)
    rho, raised = density_volume(vol, sp), capped_density_volume(vol, 100.0, sp)
    above = np.argwhere(vol >= 100.0) * np.array([2.0, 1.0, 1.0])   # (z, y, x) in x-voxel units
    pts = np.indices(vol.shape).reshape(3, -1).T * np.array([2.0, 1.0, 1.0])
    nearest = np.full(len(pts), np.inf)
    for x in np.unique(above[:, 2]):          # the steel is a slab along x: one plane each
        nearest = np.minimum(nearest, np.abs(pts[:, 2] - x))
    near = (nearest <= CAP_MARGIN_PX).reshape(vol.shape)
    np.testing.assert_array_equal(raised[near], rho[near])
    assert (raised[~near] > rho[~near]).any()


@pytest.mark.parametrize("cap", [-5.0, 1e6])
def test_a_cap_outside_the_gray_range_changes_nothing(cap):
    vol = groove_next_to_steel()
    np.testing.assert_array_equal(capped_density_volume(vol, cap), density_volume(vol))


def test_constant_volume_and_bad_cap():
    assert (capped_density_volume(np.full((3, 4, 5), 2.0), 1.0) == 0.02).all()
    for bad in (np.nan, np.inf, "10", None, True):
        with pytest.raises(InputError, match="cap"):
            capped_density_volume(groove_next_to_steel(), bad)


def test_density_cap_is_the_second_highest_level_in_input_units():
    assert density_cap([10.0, 250.0, 100.0, 40.0], (-1000.0, 0.5)) == 100.0 / 0.5 - 1000.0
    assert density_cap([10.0, 250.0], (-1000.0, 0.5)) is None


def test_pipeline_meshes_the_raised_density_with_three_or_more_materials(monkeypatch):
    """segment_volume_3d's CVT gets capped_density_volume of its (streak-corrected) volume
    at the second-highest level, and the report says which cap."""
    seen = {}
    real_cvt, real_density = pipeline3d.cvt_sites_3d, pipeline3d.density_3d

    def density_spy(image, p, sp, cap=None):
        seen["image"], seen["cap"] = image.copy(), cap
        return real_density(image, p, sp, cap)

    def cvt_spy(rho, *args, **kwargs):
        seen["rho"] = rho.copy()
        return real_cvt(rho, *args, **kwargs)

    monkeypatch.setattr(pipeline3d, "density_3d", density_spy)
    monkeypatch.setattr(pipeline3d, "cvt_sites_3d", cvt_spy)
    ph = make_part_3d(96, seed=0)
    seg = pipeline3d.segment_volume_3d(ph.image, spacing=ph.spacing)
    scale, levels, _, _ = volume_levels(ph.image.astype(float), resolve(None), 0)
    assert len(levels) >= 3
    assert seen["cap"] == seg.diagnostics["density_cap"] == density_cap(levels, scale)
    expected = capped_density_volume(seen["image"], seen["cap"], ph.spacing)
    np.testing.assert_array_equal(seen["rho"], expected)
    assert (expected > density_volume(seen["image"], ph.spacing)).any()


@pytest.mark.parametrize("spacing_zyx", [(1.0, 1.0, 1.0), (2.0, 1.0, 1.3), (0.7, 1.9, 1.0)])
def test_near_is_the_distance_transform_within_a_radius(spacing_zyx):
    rng = np.random.default_rng(3)
    for share in (0.002, 0.05, 0.3):
        mask = rng.random((9, 11, 13)) < share
        for radius in (0.5, 1.0, 2.5, 3.2):
            expected = ndimage.distance_transform_edt(~mask, sampling=spacing_zyx) <= radius
            np.testing.assert_array_equal(_near(mask, radius, spacing_zyx), expected)
