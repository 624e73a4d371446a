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


def _grid_tets(n=4, seed=0):
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(*[np.arange(n + 1.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    inner = np.all((g > 0) & (g < n), axis=1)
    g[inner] += rng.uniform(-0.2, 0.2, (int(inner.sum()), 3))
    return g, Delaunay(g).simplices


def test_tet_surface_report_closed_and_pinched():
    from tet_baselines import tet_surface_report

    pts, tets = _grid_tets()
    c = pts[tets].mean(axis=1)
    material = (c[:, 0] > 2.0).astype(int)  # two slabs: closed surfaces, one interface
    report, pairs = tet_surface_report(tets, material)
    assert all(r["non_manifold_edges"] == 0 and r["boundary_edges"] == 0 for r in report.values())
    assert list(pairs) == [(0, 1)] and len(pairs[(0, 1)]) > 0
    # two tetrahedra of material 1 sharing an edge and no face: that edge is non-manifold
    faces = [set(map(frozenset, itertools.combinations(t, 3))) for t in tets]
    for a in range(len(tets)):
        for b in range(a + 1, len(tets)):
            if len(set(tets[a]) & set(tets[b])) == 2 and not faces[a] & faces[b]:
                break
        else:
            continue
        break
    material = np.zeros(len(tets), int)
    material[[a, b]] = 1
    report, _ = tet_surface_report(tets, material)
    assert report[1]["non_manifold_edges"] == 1 and report[1]["boundary_edges"] == 0


def test_label_voxels_of_a_mesh_over_the_voxels_outer_faces():
    from tet_baselines import label_voxels

    pts, tets = _grid_tets(4)  # voxel corners of a 4^3 volume: -0.5 .. 3.5
    pts = (pts - 0.5) * [1.0, 1.0, 2.0]
    c = pts[tets].mean(axis=1)
    material = (c[:, 2] > 3.0).astype(int)  # z above 1.5 voxels (3.0 physical)
    lab = label_voxels(pts, tets, material, (4, 4, 4), (1.0, 1.0, 2.0), outside=9)
    assert np.all(lab[:1] == 0) and np.all(lab[-1:] == 1)
    keep = c[:, 0] < 1.5  # a mesh covering part of the box: the rest is outside
    lab = label_voxels(pts, tets[keep], material[keep], (4, 4, 4), (1.0, 1.0, 2.0), outside=9)
    assert np.all(lab[:, :, 3] == 9) and not np.any(lab[:, :, 0] == 9)
