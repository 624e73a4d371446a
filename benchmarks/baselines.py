"""Pixel baselines the benchmark compares ctseg against (not part of the package).

- :func:`multi_otsu_thresholds`: multi-level Otsu thresholding, the simplest baseline.
- :func:`pixel_graph`: the 4-connected pixel grid as a graph for the same recursive graph
  cut that ctseg runs on triangles (:func:`ctseg.recursive_cut.segment_triangles`).
- :func:`pixel_boundary`: the material boundary of a pixel labelling as segments on the
  pixel edges, for the same boundary distance as the meshes.
"""
import numpy as np


def multi_otsu_thresholds(values, n_classes, bins=256):
    """Thresholds that maximise the between-class variance of ``n_classes`` gray intervals.

    Exact over the histogram's bin edges by dynamic programming (O(K L^2)): the between-class
    variance is, up to a constant, sum over classes of S_c^2 / W_c (S: sum, W: count), a sum
    of independent interval terms. Returns the K-1 thresholds (a value v is in class c when
    thresholds[c-1] <= v < thresholds[c]).

    References
    ----------
    Otsu 1979; Liao, Chen and Chung 2001 (multi-level Otsu).
    """
    v = np.asarray(values, float).ravel()
    lo, hi = float(v.min()), float(v.max())
    if hi <= lo or n_classes < 2:
        return np.array([])
    edges = np.linspace(lo, hi, bins + 1)
    count, _ = np.histogram(v, edges)
    centres = 0.5 * (edges[:-1] + edges[1:])
    W = np.concatenate([[0.0], np.cumsum(count)])
    S = np.concatenate([[0.0], np.cumsum(count * centres)])
    L = bins
    # score[i, j]: interval of bins i..j-1 (i < j)
    dw = W[None, :] - W[:, None]
    ds = S[None, :] - S[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        score = np.where(dw > 0, ds * ds / dw, 0.0)
    score[np.tril_indices(L + 1)] = -np.inf  # empty or reversed intervals
    best = score[0].copy()  # best[j]: one class covering bins 0..j-1
    arg = []
    for _ in range(n_classes - 1):
        cand = best[:, None] + score  # split at i, last class i..j-1
        a = np.argmax(cand, axis=0)
        best = cand[a, np.arange(L + 1)]
        arg.append(a)
    cuts = []
    j = L
    for a in reversed(arg):
        j = int(a[j])
        cuts.append(j)
    return edges[np.array(sorted(cuts))]


def otsu_labels(image, n_classes):
    """Label each pixel by the multi-Otsu class of its gray value (0 = darkest)."""
    t = multi_otsu_thresholds(image, n_classes)
    return np.searchsorted(t, np.asarray(image, float), side="right").astype(np.int64)


def pixel_graph(image255):
    """Nodes, areas, 4-neighbour pairs and centres of the pixel grid, for the graph cut."""
    rows, cols = image255.shape
    ids = np.arange(rows * cols).reshape(rows, cols)
    adj = np.concatenate([np.column_stack([ids[:, :-1].ravel(), ids[:, 1:].ravel()]),
                          np.column_stack([ids[:-1].ravel(), ids[1:].ravel()])])
    yy, xx = np.mgrid[0:rows, 0:cols]
    return {"gray": image255.ravel().astype(float), "area": np.ones(rows * cols),
            "adjacency": adj, "centroids": np.column_stack([xx.ravel(), yy.ravel()]).astype(float)}


def pixel_boundary(labels):
    """(points, edges) of the pixel edges between different labels (pixel centres at
    integer coordinates, so the edges lie on the half-integer lines)."""
    r, c = np.nonzero(labels[:, 1:] != labels[:, :-1])
    r2, c2 = np.nonzero(labels[1:, :] != labels[:-1, :])
    pts = np.vstack([np.column_stack([c + 0.5, r - 0.5]), np.column_stack([c + 0.5, r + 0.5]),
                     np.column_stack([c2 - 0.5, r2 + 0.5]), np.column_stack([c2 + 0.5, r2 + 0.5])])
    n1, n2 = len(r), len(r2)
    edges = np.column_stack([np.r_[np.arange(n1), 2 * n1 + np.arange(n2)],
                             np.r_[n1 + np.arange(n1), 2 * n1 + n2 + np.arange(n2)]])
    return pts, edges
