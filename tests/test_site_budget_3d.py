"""The number of sites of a volume in 3D mode from its surface area
(ctseg.site_budget.site_budget_3d), and its use by segment_volume and the stage filter."""
import numpy as np
import pytest

import ctseg
from ctseg.errors import InputError
from ctseg.params import DEFAULTS
from ctseg.site_budget import boundary_area, site_budget_3d
from ctseg.stages3d import default_n_sites_3d


def balls(n, centres, radius, rng=None, noise=2.0):
    zz, yy, xx = np.mgrid[:n, :n, :n]
    vol = np.zeros((n, n, n))
    for c in centres:
        vol[(zz - c[0]) ** 2 + (yy - c[1]) ** 2 + (xx - c[2]) ** 2 < radius ** 2] = 100.0
    return vol if rng is None else vol + rng.normal(0.0, noise, vol.shape)


def lattice(n, spacing, offset):
    ks = range(offset, n - offset + 1, spacing)
    return [(a, b, c) for a in ks for b in ks for c in ks]


def test_boundary_area_of_a_ball_and_of_a_plate():
    rng = np.random.default_rng(0)
    area = boundary_area(balls(48, [(24, 24, 24)], 14, rng))
    assert abs(area - 4 * np.pi * 14 ** 2) < 0.2 * 4 * np.pi * 14 ** 2
    # a plate parallel to the z slices: seen only by the y and x slices
    plate = np.zeros((40, 40, 40))
    plate[15:25] = 100.0
    assert abs(boundary_area(plate) - 2 * 40 * 40) < 0.25 * 2 * 40 * 40
    assert boundary_area(np.full((20, 20, 20), 3.0)) == 0.0
    assert boundary_area(rng.normal(0, 1, (30, 30, 30))) < 0.01 * 30 ** 3


def test_a_part_keeps_the_size_rule_and_a_porous_volume_gets_more():
    rng = np.random.default_rng(1)
    part = balls(48, [(24, 24, 24)], 14, rng)  # one surface, far apart
    n, report = site_budget_3d(part)
    assert report["rule"] == "area" and n == default_n_sites_3d(part.shape)
    assert report["surface_spacing_vox"] > (part.size / n) ** (1 / 3)
    porous = balls(48, lattice(48, 8, 4), 3, rng)  # surfaces ~ 4.5 voxels apart
    n, report = site_budget_3d(porous)
    assert report["rule"] == "dense" and n > 2 * default_n_sites_3d(porous.shape)
    assert n == round(porous.size / report["surface_spacing_vox"] ** 3) or \
        abs(n - porous.size / report["surface_spacing_vox"] ** 3) < 0.01 * n
    assert report["cap_sites"] == round(porous.size / DEFAULTS.min_pixels_per_site ** 1.5)
    capped, rc = site_budget_3d(porous, min_pixels_per_site=30.0)
    assert rc["rule"] == "boundary_cap" and capped == max(default_n_sites_3d(porous.shape),
                                                           round(porous.size / 30.0 ** 1.5))
    assert site_budget_3d(porous, site_rule="area")[0] == default_n_sites_3d(porous.shape)
    # closer surfaces, more sites; never fewer than the size rule
    counts = [site_budget_3d(balls(48, lattice(48, s, 4), 3, rng))[0] for s in (16, 10, 8)]
    assert counts == sorted(counts) and counts[-1] > counts[0] >= default_n_sites_3d((48,) * 3)


def test_segment_volume_reports_the_budget_and_the_filter_agrees():
    from ctseg.filters import CVTSitesFilter, DensityMapFilter
    from ctseg.filters.convert import array_to_image

    vol = balls(24, lattice(24, 6, 3), 2.5, np.random.default_rng(2))
    seg = ctseg.segment_volume(vol, mode="3d", max_iter=2)
    sites = seg.diagnostics["sites"]
    assert sites["n_sites"] == seg.diagnostics["n_sites"] > default_n_sites_3d(vol.shape)
    assert sites["rule"] != "area" and "site_budget" in seg.diagnostics["times_s"]
    f = CVTSitesFilter()
    f.SetMaximumIterations(2)
    out = f.apply(DensityMapFilter().apply(array_to_image(vol)))
    n_site_points = out.GetNumberOfPoints()
    assert n_site_points == seg.diagnostics["n_vertices"]  # the same sites as the composite
    f.SetSiteRule("area")
    n_area_points = f.apply(DensityMapFilter().apply(array_to_image(vol))).GetNumberOfPoints()
    assert n_site_points > n_area_points  # the filter counts as segment_volume does
    given = ctseg.segment_volume(vol, mode="3d", n_sites=100, max_iter=2)
    assert given.diagnostics["sites"]["rule"] == "given"


def test_many_sites_are_refused_up_front_when_memory_is_short(monkeypatch):
    import ctseg.resources

    vol = balls(24, lattice(24, 6, 3), 2.5, np.random.default_rng(3))
    need = vol.size * ctseg.resources.VOLUME_3D_BYTES_PER_VOXEL
    monkeypatch.setattr(ctseg.resources, "available_bytes", lambda: need + 1024)
    from ctseg.pipeline3d import segment_volume_3d

    with pytest.raises(InputError, match="sites"):
        segment_volume_3d(vol)
    assert segment_volume_3d(vol, site_rule="area", max_iter=1).n_materials == 2
