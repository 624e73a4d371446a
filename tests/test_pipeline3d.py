"""The 3D mode end to end (SPEC 9): tetrahedra that fill the box, one material each, closed
manifold surfaces that enclose exactly their tetrahedra, the materials of the truth."""
import numpy as np
import pytest

import ctseg
from ctseg.errors import InputError, ParameterError
from ctseg.meshcheck import mesh_check_report
from ctseg.metrics import dice_per_label
from ctseg.phantoms import make_volume
from ctseg.tetra_gray import voxel_overlaps
from ctseg.tetrahedra import tetra_volumes


def tetra_labels(seg, shape):
    """Each voxel's material: that of the tetrahedron overlapping it most."""
    t, vox, ov = voxel_overlaps(seg.points, seg.tetrahedra, shape, seg.spacing)
    order = np.argsort(ov, kind="stable")
    lab = np.zeros(int(np.prod(shape)), np.int64)
    lab[vox[order]] = seg.material[t[order]]
    return lab.reshape(shape)


@pytest.fixture(scope="module")
def part():
    ph = make_volume(16, 96, seed=3)
    steps = []
    seg = ctseg.segment_volume(ph.image, mode="3d", n_sites=3000,
                               progress=lambda frac, stage: steps.append((frac, stage)))
    seg.progress_steps = steps
    return ph, seg


def test_progress_never_goes_back(part):
    # the coarse Lloyd reports into the CVT's range before the voxel Lloyd starts
    fracs = [f for f, _ in part[1].progress_steps]
    stages = [s for _, s in part[1].progress_steps]
    assert fracs[0] == 0.0 and fracs[-1] == 1.0 and fracs == sorted(fracs), fracs
    assert stages.index("coarse_cvt") < stages.index("cvt") < stages.index("tetrahedra")


def test_tetrahedra_fill_the_box_and_surfaces_close(part):
    ph, seg = part
    vol = tetra_volumes(seg.points, seg.tetrahedra)
    assert vol.min() > 0
    box = np.prod((np.array(ph.image.shape[::-1]) - 1.0) * seg.spacing)
    assert abs(vol.sum() - box) <= 1e-9 * box
    assert len(seg.surfaces) == seg.n_materials
    for s in seg.surfaces:
        report = mesh_check_report(s.points, s.triangles)
        assert report["ok"], report
        assert abs(s.enclosed_volume - s.element_volume) <= 1e-9 * s.element_volume
        assert np.isclose(s.element_volume, vol[seg.material == s.material].sum(), rtol=1e-12)
    # interface triangles separate different materials, lower number first
    assert np.all(seg.interface_materials[:, 0] < seg.interface_materials[:, 1])
    d = seg.diagnostics
    assert d["n_tetrahedra"] == len(seg.tetrahedra) and d["element_quality"]["min_dihedral_deg"] > 0
    assert np.all(np.diff(d["cvt_energy"]) <= 1e-9 * d["cvt_energy"][0])
    assert set(d["times_s"]) >= {"density", "initial_sites", "cvt", "tetrahedra", "tetra_gray", "graphcut"}


def test_materials_of_the_truth(part):
    ph, seg = part
    assert seg.n_materials == 4
    dice = dice_per_label(tetra_labels(seg, ph.image.shape), ph.truth.astype(np.int64), 4)
    # air, aluminium and steel; the thin polymer bushing is the hard one (README)
    assert min(dice[0], dice[2], dice[3]) > 0.9 and dice[1] > 0.5, dice
    assert np.all(np.diff(seg.material_gray) > 0)


def test_anisotropic_spacing_keeps_the_geometry_physical():
    ph = make_volume(12, 40, seed=1)
    spacing = (0.1, 0.1, 0.3)
    seg = ctseg.segment_volume(ph.image, mode="3d", spacing=spacing, n_sites=800)
    box = (np.array(ph.image.shape[::-1]) - 1.0) * spacing
    assert np.allclose(seg.points.min(axis=0), 0) and np.allclose(seg.points.max(axis=0), box)
    assert np.isclose(tetra_volumes(seg.points, seg.tetrahedra).sum(), np.prod(box), rtol=1e-9)


def test_deterministic():
    ph = make_volume(8, 32, seed=3)
    a = ctseg.segment_volume(ph.image, mode="3d", n_sites=300)
    b = ctseg.segment_volume(ph.image, mode="3d", n_sites=300)
    for name in ("points", "tetrahedra", "material", "gray"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


@pytest.mark.parametrize("volume,kw,error,words", [
    (np.zeros((1, 16, 16)), {}, InputError, "at least 2 voxels"),
    (np.full((4, 8, 8), np.nan), {}, InputError, "NaN"),
    (np.zeros((4, 8, 8)), {"spacing": (1, -1, 1)}, ParameterError, "spacing"),
    (np.zeros((4, 8, 8)), {"n_sites": 10 ** 6}, ParameterError, "n_sites"),
])
def test_bad_input(volume, kw, error, words):
    with pytest.raises(error, match=words):
        ctseg.segment_volume(volume, mode="3d", **kw)


def test_a_constant_volume_is_one_material():
    seg = ctseg.segment_volume(np.full((6, 10, 10), 3.0), mode="3d", n_sites=80)
    assert seg.n_materials == 1 and len(seg.interfaces) == 0
    assert len(seg.surfaces) == 1 and seg.surfaces[0].enclosed_volume > 0


def test_face_area_weighting_passes_the_shared_face_areas(monkeypatch):
    # every tetrahedron's four faces count each shared face twice and each box face once
    # (the vertices as labelled: no sub-voxel move after the cut)
    import ctseg.labelling3d as labelling3d

    seen = []
    real = labelling3d.segment_triangles
    monkeypatch.setattr(labelling3d, "segment_triangles",
                        lambda *a, **kw: seen.append(kw["edge_length"]) or real(*a, **kw))
    ph = make_volume(8, 24, seed=2)
    spacing = np.array([0.2, 0.2, 0.5])
    seg = ctseg.segment_volume(ph.image, mode="3d", spacing=spacing, n_sites=200,
                               weight_by_edge_length=True, subpixel_boundary=False)
    p = seg.points[seg.tetrahedra]
    faces = [p[:, [1, 2, 3]], p[:, [0, 2, 3]], p[:, [0, 1, 3]], p[:, [0, 1, 2]]]
    all_faces = sum(0.5 * np.linalg.norm(np.cross(f[:, 1] - f[:, 0], f[:, 2] - f[:, 0]), axis=1).sum()
                    for f in faces)
    x, y, z = (np.array(ph.image.shape[::-1]) - 1.0) * spacing
    shared = (all_faces - 2 * (x * y + y * z + z * x)) / 2
    assert seen and all(len(e) == len(seen[0]) for e in seen)
    assert np.isclose(seen[0].sum() * np.prod(spacing) ** (2 / 3), shared, rtol=1e-9)


def test_every_z_slice_is_streak_corrected_as_in_slices_mode():
    # slices simulated with steel (beam-hardening streaks): 3D mode corrects each z slice
    # against the volume's levels, with the weights slices mode finds for the same slices
    ph = make_volume(3, 128, seed=0, simulate=True)
    seg3 = ctseg.segment_volume(ph.image, mode="3d", n_sites=300)
    slices = ctseg.segment_volume(ph.image, mode="slices", n_sites=100, n_jobs=1)
    w3 = seg3.diagnostics["streak_weights"]
    ws = [s.diagnostics["streak_correction"]["weight"] for s in slices.slices]
    assert len(w3) == 3 and max(w3) > 0  # (slice 0 holds no streak worth correcting)
    np.testing.assert_allclose(w3, ws, rtol=1e-12)
    off = ctseg.segment_volume(ph.image, mode="3d", n_sites=300, streak_correction=False)
    assert off.diagnostics["streak_weights"] == [] and "streak_correction" not in off.diagnostics["times_s"]
