"""Accuracy measures (ctseg.metrics) against values computed independently."""
import numpy as np
import pytest

from ctseg.metrics import dice_per_label, subpixel_label_image


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
