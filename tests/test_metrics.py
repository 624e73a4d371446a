"""Accuracy measures (ctseg.metrics) against values computed independently."""
import numpy as np
import pytest

from ctseg.metrics import dice_per_label, evaluate_volume, matched_dice_per_label
from ctseg.raster import label_image, subpixel_label_image, volume_labels


def split_mesh(x_split, size=8):
    """The domain [0, size-1]^2 cut by the vertical line x = x_split: material 0 left, 1 right."""
    e = size - 1.0
    pts = np.array([[0, 0], [x_split, 0], [e, 0], [0, e], [x_split, e], [e, e]], float)
    tri = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    return pts, tri, np.array([0, 0, 1, 1])


@pytest.mark.parametrize("s", [1, 2, 4])
def test_subpixel_labels_follow_the_true_line(s):
    pts, tri, mat = split_mesh(3.3)
    lab, covered = subpixel_label_image(pts, tri, mat, (8, 8), s)
    assert lab.shape == (8 * s, 8 * s)
    centre = (np.arange(8 * s) + 0.5) / s - 0.5  # sub-pixel centres in pixel units
    # a sub-pixel is covered when at least half of it lies in the domain [0, 7]^2
    lo, hi = centre - 0.5 / s, centre + 0.5 / s
    frac = np.clip(np.minimum(hi, 7) - np.maximum(lo, 0), 0, None) * s
    expect_cov = np.outer(frac, frac) >= 0.5
    np.testing.assert_array_equal(covered, expect_cov)
    expect = np.broadcast_to((centre > 3.3)[None, :], lab.shape)
    np.testing.assert_array_equal(lab[covered], expect[covered].astype(int))


def test_subpixel_dice_counts_the_area_between_two_lines():
    s = 4
    truth_pts, tri, mat = split_mesh(3.3)
    truth, covered = subpixel_label_image(truth_pts, tri, mat, (8, 8), s)
    mesh_pts, _, _ = split_mesh(3.8)
    pred, _ = subpixel_label_image(mesh_pts, tri, mat, (8, 8), s)
    d = dice_per_label(pred[covered], truth[covered], 2)
    centre = (np.arange(8 * s) + 0.5) / s - 0.5
    cols = centre[covered.any(axis=0)]
    n_rows = covered.any(axis=1).sum()
    left_t, left_p = (cols < 3.3).sum(), (cols < 3.8).sum()
    right_t, right_p = len(cols) - left_t, len(cols) - left_p
    exp0 = 2 * min(left_t, left_p) / (left_t + left_p)
    exp1 = 2 * min(right_t, right_p) / (right_t + right_p)
    assert n_rows > 0
    np.testing.assert_allclose(d, [exp0, exp1])


def _fake_volume(x_splits, axis, size=8):
    """A volume 'segmentation' of len(x_splits) slices, each a split_mesh, along ``axis``."""
    from types import SimpleNamespace
    slices = []
    for x in x_splits:
        pts, tri, mat = split_mesh(x, size)
        slices.append(SimpleNamespace(points=pts, triangles=tri, material=mat,
                                      shape=(size, size), boundary_edges=np.array([[1, 4]])))
    return SimpleNamespace(slices=slices, axis=axis, n_materials=2)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_volume_labels_stack_the_slice_label_images(axis):
    vseg = _fake_volume([2.2, 3.3, 5.6], axis)
    shape = [8, 8, 8]
    shape[axis] = 3
    lab = volume_labels(vseg, tuple(shape))
    for k, seg in enumerate(vseg.slices):
        want = label_image(seg.points, seg.triangles, seg.material, seg.shape)
        np.testing.assert_array_equal(np.take(lab, k, axis=axis), want)
        np.testing.assert_array_equal(want, np.broadcast_to(np.arange(8) > [2.2, 3.3, 5.6][k],
                                                            (8, 8)))


def test_evaluate_volume_against_its_own_labels():
    vseg = _fake_volume([2.2, 3.3, 5.6], 0)
    truth = volume_labels(vseg, (3, 8, 8))
    r = evaluate_volume(vseg, truth)
    assert r["dice"] == [1.0, 1.0] and r["n_materials_true"] == 2
    assert r["slices_with_boundaries"] == 3
    # the true boundary lies midway between pixel columns, the mesh's at x_split; the mesh
    # boundary is sampled at every true boundary point's row
    want = np.mean([abs(x - (np.floor(x) + 0.5)) for x in (2.2, 3.3, 5.6)])
    assert np.isclose(r["boundary_px"]["truth_to_mesh"], want)


def test_metrics_does_not_import_volume():
    # ctseg.volume imports the metrics' rasterisers (ctseg.raster): no cycle back
    import ast
    import ctseg.metrics
    tree = ast.parse(open(ctseg.metrics.__file__).read())
    names = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    names |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert not any(name and name.split(".")[-1] == "volume" for name in names)


def test_matched_dice_maps_each_found_label_by_overlap_against_brute_force():
    rng = np.random.default_rng(3)
    truth = rng.integers(0, 3, 400)
    # found labels: the truth with 10% noise and two false labels split off 0 and 2
    pred = np.where(rng.random(400) < 0.1, rng.integers(0, 3, 400), truth)
    pred[(truth == 0) & (rng.random(400) < 0.3)] = 3
    pred[(truth == 2) & (rng.random(400) < 0.2)] = 4
    # brute force: for every found label, the true label with the most common voxels
    to_true = [max(range(3), key=lambda t: np.sum((pred == k) & (truth == t))) for k in range(5)]
    expected = [2 * np.sum((np.take(to_true, pred) == t) & (truth == t))
                / (np.sum(np.take(to_true, pred) == t) + np.sum(truth == t)) for t in range(3)]
    assert np.allclose(matched_dice_per_label(pred, truth), expected)
