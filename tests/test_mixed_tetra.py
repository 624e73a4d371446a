"""Mixed tetrahedra relabelled by their voxels' votes (ctseg/mixed_tetra.py)."""
import os

import numpy as np
from scipy.ndimage import gaussian_filter

import ctseg.mixed_tetra
from ctseg.metrics import evaluate_tetra
from ctseg.mixed_tetra import relabel_mixed, voxel_noise
from ctseg.pipeline3d import segment_volume_3d
from ctseg.raster import tetra_label_volume
from ctseg.tetra_gray import tetra_gray
from ctseg.tetrahedra import delaunay_tetrahedra

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LEVELS = np.array([0.0, 50.0, 100.0])


def _slab_volume(n=24, seed=0):
    """Along x: air (0) | metal (100) where y < n/2; air | a real middle-material slab (50),
    5 voxels thick | metal where y >= n/2; blurred, noisy."""
    truth = np.zeros((n, n, n), np.int64)
    h = n // 2
    truth[:, :h, h:] = 2
    truth[:, h:, h - 2:h + 3] = 1
    truth[:, h:, h + 3:] = 2
    vol = gaussian_filter(LEVELS[truth], 0.8) + np.random.default_rng(seed).normal(0, 2.0, truth.shape)
    return vol, truth


def _mesh(n=24, n_inner=500, seed=1):
    rng = np.random.default_rng(seed)
    box = np.full(3, n - 1.0)
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float) * box
    return delaunay_tetrahedra(np.vstack([corners, rng.uniform(0, 1, (n_inner, 3)) * box]), box)


def test_voxel_noise_is_the_noise_sd():
    vol = np.random.default_rng(2).normal(0, 3.0, (20, 20, 20))
    assert abs(voxel_noise(vol) - 3.0) < 0.15


def test_straddling_elements_leave_the_middle_material_and_the_slab_stays():
    vol, truth = _slab_volume()
    mesh = _mesh()
    mean = tetra_gray(vol, mesh.points, mesh.tetrahedra)
    material = np.argmin(np.abs(mean[:, None] - LEVELS[None, :]), axis=1)  # by mean gray
    new, changed = relabel_mixed(vol, mesh.points, mesh.tetrahedra, material, LEVELS)
    assert changed > 0
    before = tetra_label_volume(mesh.points, mesh.tetrahedra, material, truth.shape)
    after = tetra_label_volume(mesh.points, mesh.tetrahedra, new, truth.shape)
    # where there is no slab, the middle material that straddling elements made goes away
    no_slab = np.zeros(truth.shape, bool)
    no_slab[:, :12, :] = True
    wrong_mid = lambda lab: int(((lab == 1) & no_slab).sum())  # noqa: E731
    # measured 798 -> 327 voxels: straddling elements a third in the blur band stay
    assert wrong_mid(before) > 100 and wrong_mid(after) < 0.5 * wrong_mid(before)
    assert (after == truth).mean() > (before == truth).mean()
    # the real slab keeps the tetrahedra inside it
    cent = mesh.points[mesh.tetrahedra].mean(axis=1)
    inside = (cent[:, 0] > 10.5) & (cent[:, 0] < 12.5) & (cent[:, 1] > 13) & (material == 1)
    assert inside.any() and np.all(new[inside] == 1)


def test_voxels_inside_a_transition_vote_for_its_two_sides(monkeypatch):
    """The blur between air and metal passes through the middle material's gray: those
    voxels vote air or metal, so the straddling elements a third in the band go too,
    while the real 5-voxel slab keeps its voxels' votes."""
    def run(seed):
        vol, truth = _slab_volume(seed=seed)
        mesh = _mesh(seed=seed + 1)
        mean = tetra_gray(vol, mesh.points, mesh.tetrahedra)
        material = np.argmin(np.abs(mean[:, None] - LEVELS[None, :]), axis=1)
        new, _ = relabel_mixed(vol, mesh.points, mesh.tetrahedra, material, LEVELS)
        after = tetra_label_volume(mesh.points, mesh.tetrahedra, new, truth.shape)
        no_slab = np.zeros(truth.shape, bool)
        no_slab[:, :12, :] = True
        return int(((after == 1) & no_slab).sum()), int(((after == 1) & (truth == 1)).sum())

    for seed in (0, 1, 2):
        wrong, slab = run(seed)
        with monkeypatch.context() as m:  # no look along the gradient: the nearest level votes
            m.setattr(ctseg.mixed_tetra, "TRANSITION_STEP_VOX", 0.0)
            wrong_without, slab_without = run(seed)
        # measured 59 / 72 / 106 voxels of the middle material left where there is no slab
        # against 272 / 575 / 320 without; the slab's 1080-1106 of 1440 voxels the same
        assert wrong < 0.5 * wrong_without
        assert slab >= slab_without - 10


def test_noise_alone_changes_nothing():
    vol = np.random.default_rng(3).normal(50.0, 2.0, (16, 16, 16))
    mesh = _mesh(16, 200)
    material = np.ones(len(mesh.tetrahedra), np.int64)
    new, changed = relabel_mixed(vol, mesh.points, mesh.tetrahedra, material, LEVELS)
    assert changed == 0 and np.array_equal(new, material)


def test_sample_volume_polymer_gains(monkeypatch):
    """On the sample volume the rule's relabelled tetrahedra become right: most of them
    take the material that holds most of their true volume, which few held before, and
    no material's Dice drops. (Its Dice gain for the polymer is not a fixed margin: the
    same rule gave 0.696 -> 0.739 with numpy 2.4 and 0.773 -> 0.781 with numpy 1.24,
    whose last bits give other sites and so another mesh.)"""
    import importlib

    import nrrd

    from ctseg.tetra_gray import VoxelOverlaps

    image, _ = nrrd.read(os.path.join(ROOT, "sample_data", "part_volume.nrrd"), index_order="C")
    truth = np.load(os.path.join(ROOT, "sample_data", "part_volume_truth.npy"))
    labelling3d = importlib.import_module("ctseg.labelling3d")
    seen = {}

    def recorded(vol255, points, tetrahedra, material, *args, **kwargs):
        out = relabel_mixed(vol255, points, tetrahedra, material, *args, **kwargs)
        seen.update(points=points, tetrahedra=tetrahedra, before=np.array(material), after=out[0])
        return out

    monkeypatch.setattr(labelling3d, "relabel_mixed", recorded)
    seg = segment_volume_3d(image)
    with_rule = evaluate_tetra(seg, truth)["dice"]
    assert seg.diagnostics["relabelled_mixed"] > 0 and len(seg.material_gray) == truth.max() + 1
    # the true material of each tetrahedron: the one holding most of its volume
    overlaps = VoxelOverlaps(seen["points"], seen["tetrahedra"], truth.shape)
    share = np.stack([overlaps.tetra_mean((truth == m).astype(float))
                      for m in range(truth.max() + 1)], axis=1)
    changed = np.flatnonzero(seen["before"] != seen["after"])
    right_before = np.sum(seen["before"][changed] == share[changed].argmax(axis=1))
    right_after = np.sum(seen["after"][changed] == share[changed].argmax(axis=1))
    # measured with numpy 2.4: 375 relabelled, 15 right before, 348 after
    assert right_after >= 0.7 * len(changed) and right_after >= 3 * right_before
    monkeypatch.setattr(ctseg.mixed_tetra, "MIXED_OWN_SHARE", 0.0)  # the rule off
    without = evaluate_tetra(segment_volume_3d(image), truth)["dice"]
    assert with_rule[1] > without[1]
    assert np.all(np.array(with_rule) >= np.array(without) - 0.01)


# ------------------------------------------------------------ relabel_beyond_iso50
def test_iso50_rule_moves_boundary_elements_once_between_adjacent_contrasted_levels():
    from ctseg.mixed_tetra import relabel_beyond_iso50

    lv = [0.0, 100.0, 200.0]
    chain = [[0, 1], [1, 2], [2, 3]]
    # tetrahedron 1 (material 1, gray 20) lies below mid(0, 1) = 50: it joins air
    new, changed = relabel_beyond_iso50([0.0, 20.0, 100.0, 100.0], [0, 1, 1, 1], lv, chain, 2.0)
    assert new.tolist() == [0, 0, 1, 1] and changed == 1
    # just below ISO-50 is beyond it too; on it or above, it stays
    assert relabel_beyond_iso50([0.0, 49.0, 100.0, 100.0], [0, 1, 1, 1], lv, chain, 2.0)[1] == 1
    assert relabel_beyond_iso50([0.0, 50.0, 100.0, 100.0], [0, 1, 1, 1], lv, chain, 2.0)[1] == 0
    assert relabel_beyond_iso50([0.0, 51.0, 100.0, 100.0], [0, 1, 1, 1], lv, chain, 2.0)[1] == 0
    # levels closer than ISO50_MIN_CONTRAST noise units: left to the graph cut
    assert relabel_beyond_iso50([0.0, 20.0, 100.0, 100.0], [0, 1, 1, 1], lv, chain, 11.0)[1] == 0
    # materials 0 and 2 are not adjacent in level order: a mixture reading low stays
    assert relabel_beyond_iso50([0.0, 20.0, 200.0, 200.0], [0, 2, 2, 2], lv, chain, 2.0)[1] == 0
    # no neighbour of the other material: nothing to join
    assert relabel_beyond_iso50([20.0, 20.0], [1, 1], lv, [[0, 1]], 2.0)[1] == 0
    # a tetrahedron moves once: 2 -> 1 in one round, never on to 0
    new, _ = relabel_beyond_iso50([0.0, 100.0, 10.0], [0, 1, 2], lv, [[0, 2], [1, 2]], 2.0)
    assert new.tolist() == [0, 1, 1]
    # a narrow gap reopens from its sides inwards over the rounds
    gap = relabel_beyond_iso50([0.0, 30.0, 30.0, 30.0, 0.0], [0, 1, 1, 1, 0], lv,
                               [[0, 1], [1, 2], [2, 3], [3, 4]], 2.0)[0]
    assert gap.tolist() == [0, 0, 0, 0, 0]


def test_iso50_rule_reopens_narrow_gaps_of_a_granular_volume(monkeypatch):
    """Ground truth: packed balls. The graph cut closes narrow air gaps (ice comes out
    +5 to +7 points); the rule reopens them, and ceasing it loses what it gained."""
    import ctseg.labelling3d

    from ctseg.phantoms_granular3d import make_granular_3d

    g = make_granular_3d(40, seed=1)
    vol, truth = g.image.astype(np.float64), g.truth.astype(np.int64)
    seg = segment_volume_3d(vol)
    lab = tetra_label_volume(seg.points, seg.tetrahedra, seg.material, vol.shape)
    dice_on = ctseg.metrics.dice_per_label(lab, truth, 2)
    assert seg.diagnostics["relabelled_iso50"] > 0
    monkeypatch.setattr(ctseg.labelling3d, "relabel_beyond_iso50", lambda f, m, *a: (np.asarray(m), 0))
    off = segment_volume_3d(vol)
    lab_off = tetra_label_volume(off.points, off.tetrahedra, off.material, vol.shape)
    dice_off = ctseg.metrics.dice_per_label(lab_off, truth, 2)
    assert min(dice_on) >= min(dice_off) + 0.02
    assert abs(lab.mean() - truth.mean()) < abs(lab_off.mean() - truth.mean()) - 0.01


def test_voxel_noise_in_place_equals_the_plain_formula():
    from ctseg.mixed_tetra import voxel_noise

    rng = np.random.default_rng(3)
    for shape in ((5, 6, 7), (4, 4, 4), (9, 3, 8)):  # even and odd counts of differences
        v = rng.normal(size=shape) + np.indices(shape).sum(axis=0)
        d = np.concatenate([np.diff(v, axis=a).ravel() for a in range(3)])
        plain = 1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0)
        before = v.copy()
        assert voxel_noise(v) == plain and np.array_equal(v, before)
