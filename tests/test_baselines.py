"""The benchmark's pixel baselines against slow, obvious references."""
import itertools
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benchmarks"))
from baselines import multi_otsu_thresholds, otsu_labels, pixel_boundary  # noqa: E402


def between_class_variance(v, t):
    lab = np.searchsorted(t, v, side="right")
    mu = v.mean()
    return sum((lab == c).sum() * (v[lab == c].mean() - mu) ** 2
               for c in range(len(t) + 1) if np.any(lab == c))


def test_multi_otsu_matches_exhaustive_search():
    rng = np.random.default_rng(1)
    for n_classes in (2, 3):
        # three well-separated groups of integer grays on 32 bins: thresholds must fall between
        v = np.concatenate([rng.integers(0, 6, 300), rng.integers(12, 18, 200),
                            rng.integers(25, 32, 100)]).astype(float)
        bins = 32
        t = multi_otsu_thresholds(v, n_classes, bins=bins)
        edges = np.linspace(v.min(), v.max(), bins + 1)
        best = max(between_class_variance(v, np.array(c))
                   for c in itertools.combinations(edges[1:-1], n_classes - 1))
        assert len(t) == n_classes - 1
        assert np.isclose(between_class_variance(v, t), best)


def test_otsu_labels_separate_three_levels():
    img = np.repeat([[0.0, 100.0, 250.0]], 4, axis=0)
    img = img + np.random.default_rng(0).normal(0, 3, img.shape)
    assert np.array_equal(otsu_labels(img, 3), np.repeat([[0, 1, 2]], 4, axis=0))


def test_pixel_boundary_edges_lie_between_labels():
    lab = np.zeros((4, 5), int)
    lab[1:3, 2:4] = 1  # a 2 x 2 block: perimeter of 8 unit pixel edges
    pts, edges = pixel_boundary(lab)
    seg = pts[edges]
    assert len(edges) == 8
    assert np.allclose(np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1), 1.0)
    mid = seg.mean(axis=1)
    assert np.all((mid[:, 0] >= 1.5) & (mid[:, 0] <= 3.5) & (mid[:, 1] >= 0.5) & (mid[:, 1] <= 2.5))


def test_surface_nets_gives_closed_surfaces_on_the_interfaces():
    import vtk

    if not hasattr(vtk, "vtkSurfaceNets3D"):
        pytest.skip("vtkSurfaceNets3D came with VTK 9.3")
    from surface_nets import PAD, closed_surface_report, surface_nets

    sp = np.array([0.5, 0.5, 1.0])
    k, j, i = np.indices((16, 28, 28))
    r = np.sqrt(((i - 13.5) * sp[0]) ** 2 + ((j - 13.5) * sp[1]) ** 2 + ((k - 7.5) * sp[2]) ** 2)
    labels = (r < 5.0).astype(np.uint8) + (r < 2.5)  # a ball (1) with a core (2) in air (0)
    pts, tri, pair = surface_nets(labels, sp)
    report = closed_surface_report(tri, pair)
    assert sorted(report) == [0, 1, 2]
    assert all(r["boundary_edges"] == 0 and r["non_manifold_edges"] == 0 for r in report.values())
    assert {tuple(p) for p in np.unique(pair, axis=0)} == {(0, 1), (1, 2), (0, PAD)}
    centre = np.array([13.5, 13.5, 7.5]) * sp
    for (a, b), radius in (((0, 1), 5.0), ((1, 2), 2.5)):
        v = pts[np.unique(tri[np.all(pair == (a, b), axis=1)])]
        assert np.all(np.abs(np.linalg.norm(v - centre, axis=1) - radius) < 1.0)  # within a voxel
