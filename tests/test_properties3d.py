"""Property-based checks of the 3D mode's invariants on random small volumes (the 2D ones
are in test_properties.py)."""
import numpy as np
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import ctseg
from ctseg.meshcheck import mesh_check_report
from ctseg.tetra_gray import voxel_overlaps
from ctseg.tetrahedra import tetra_volumes
from oracles import box_share


@st.composite
def small_volumes(draw):
    shape = tuple(draw(st.integers(3, 9)) for _ in range(3))
    spacing = tuple(draw(st.sampled_from([0.5, 1.0, 2.0])) for _ in range(3))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    kind = draw(st.sampled_from(["noise", "balls", "steps"]))
    if kind == "noise":
        vol = rng.normal(0, 1, shape)
    elif kind == "balls":
        k, j, i = np.indices(shape)
        vol = np.zeros(shape)
        for _ in range(rng.integers(1, 4)):
            c, r = rng.uniform(0, shape), rng.uniform(1, 4)
            vol[(k - c[0]) ** 2 + (j - c[1]) ** 2 + (i - c[2]) ** 2 < r * r] = rng.uniform(10, 200)
        vol += rng.normal(0, draw(st.floats(0, 5)), shape)
    else:
        vol = np.broadcast_to(rng.integers(0, 4, shape[2]) * 50.0, shape).copy()
    n_sites = draw(st.integers(8, max(8, min(int(np.prod(shape)), 80))))
    return vol, spacing, n_sites


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(small_volumes())
# three columns of three grays: no pixel's 3 x 3 lies in one mode (a level rule once kept none)
@example((np.tile(np.array([50.0, 100.0, 150.0]), (3, 3, 1)), (0.5, 0.5, 0.5), 8))
def test_pipeline_invariants_3d(case):
    vol, spacing, n_sites = case
    seg = ctseg.segment_volume(vol, mode="3d", spacing=spacing, n_sites=n_sites)
    # positive tetrahedra filling the box exactly
    v = tetra_volumes(seg.points, seg.tetrahedra)
    box = np.prod((np.array(vol.shape[::-1]) - 1.0) * spacing)
    assert v.min() > 0 and abs(v.sum() - box) <= 1e-9 * box
    # every voxel's (box-clipped) cube shared out exactly once
    _, vox, ov = voxel_overlaps(seg.points, seg.tetrahedra, vol.shape, spacing)
    np.testing.assert_allclose(np.bincount(vox, ov, vol.size).reshape(vol.shape),
                               box_share(vol.shape), atol=1e-9)
    # CVT energy never increases
    e = np.array(seg.diagnostics["cvt_energy"])
    # (rounding allowed: an energy of zero, a constant density's, reads as +-1e-16)
    assert np.all(np.diff(e) <= 1e-9 * np.abs(e).max() + 1e-12)
    # one material per tetrahedron, 0..K-1 all used, numbered by ascending mean gray
    assert seg.material.shape == (len(seg.tetrahedra),)
    assert set(np.unique(seg.material)) == set(range(seg.n_materials))
    assert np.all(np.diff(seg.material_gray) > 0)
    # interface triangles between different materials, lower number first
    assert np.all(seg.interface_materials[:, 0] < seg.interface_materials[:, 1])
    # each material's closed surface passes the checks and encloses its tetrahedra's volume
    assert len(seg.surfaces) == seg.n_materials
    for s in seg.surfaces:
        assert mesh_check_report(s.points, s.triangles)["ok"]
        assert abs(s.enclosed_volume - s.element_volume) <= 1e-9 * s.element_volume
        assert np.isclose(s.element_volume, v[seg.material == s.material].sum(), rtol=1e-12)
    # same input, same output
    again = ctseg.segment_volume(vol, mode="3d", spacing=spacing, n_sites=n_sites)
    assert np.array_equal(again.tetrahedra, seg.tetrahedra) and np.array_equal(again.material, seg.material)
    assert np.array_equal(again.points, seg.points)
