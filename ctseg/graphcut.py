"""Stage 6: binary graph cut of a triangle graph with Boykov-Kolmogorov max-flow (paper 6.1, SPEC 6)."""
from dataclasses import dataclass

import maxflow
import numpy as np

from .errors import InputError, ParameterError
from .params import AUTO, DEFAULTS, check


@dataclass
class GraphCapacities:
    """Capacities of the s-t graph of SPEC 6 (label 0 = source side s0).

    ``source_cap[t]`` = cap(t, s0), paid when t takes label 1; ``sink_cap[t]`` = cap(t, s1),
    paid when t takes label 0; ``edge_cap[k]`` is paid when the triangles ``edges[k]`` take
    different labels. Infinite capacities are the finite ``inf_cap``, larger than the sum
    of every finite capacity, so that they are never cut.
    """

    source_cap: np.ndarray
    sink_cap: np.ndarray
    edges: np.ndarray
    edge_cap: np.ndarray
    inf_cap: float
    seeds: tuple


def graphcut_capacities(gray, edges, centroids, seeds=None, theta_255=DEFAULTS.theta_255,
                        lam=DEFAULTS.lam, beta=DEFAULTS.beta, eps_255=DEFAULTS.eps_255,
                        edge_length=None, edge_distance=None):
    """Build the t-link and n-link capacities of the paper's eqs. (6)-(9).

    Parameters
    ----------
    gray : (m,) array_like
        Triangle gray values f(t) on the 0-255 scale.
    edges : (k, 2) int array_like
        Adjacent triangle pairs (indices into ``gray``).
    centroids : (m, 2) or (m, 3) array_like
        Element barycentres (for d(tm, tn), the Euclidean distance in 2D or 3D).
    seeds : (int, int), optional
        (s0, s1) triangles; default the lowest and highest f.
    theta_255 : float or 'auto', optional
        Seed-set radius on the 0-255 scale; 'auto' = 10% of f(s1) - f(s0).
    lam, beta : float
        The paper's lambda and beta (defaults in :mod:`ctseg.params`: the paper's values).
    eps_255 : float
        Added to |f(tm) - f(tn)| so that equal neighbours get a finite n-link.
    edge_length : (k,) array_like, optional
        If given, n-links are multiplied by the shared edge length (an option, not the paper's).
    edge_distance : (k,) array_like, optional
        d(tm, tn) of every edge, if known (a caller that cuts parts of one graph many times
        computes them once); the centroids are then not read.

    Returns
    -------
    GraphCapacities

    References
    ----------
    Yang et al. 2014, section 6.1, eqs. (6)-(9); eq. (8) read with "1 -" for both labels.

    Example
    -------
    >>> caps = graphcut_capacities([0.0, 10.0, 250.0], [[0, 1], [1, 2]], [[0, 0], [1, 0], [2, 0]])
    >>> caps.seeds
    (0, 2)
    """
    f = np.asarray(gray, dtype=np.float64)
    m = len(f)
    if m < 2:
        raise InputError(f"graph cut: need at least 2 triangles, got {m}")
    lam, beta, eps = check("lam", lam), check("beta", beta), check("eps_255", eps_255)
    theta = check("theta_255", theta_255)
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if seeds is None:
        s0, s1 = int(np.argmin(f)), int(np.argmax(f))
    else:
        s0, s1 = (int(s) for s in seeds)
        if not (0 <= s0 < m and 0 <= s1 < m) or s0 == s1:
            raise ParameterError(f"seeds: need two distinct triangle indices in 0..{m - 1}, got {seeds}")
    f0, f1 = f[s0], f[s1]
    if theta == AUTO:
        theta = 0.1 * abs(f1 - f0)
    d0, d1 = np.abs(f - f0), np.abs(f - f1)
    in0 = d0 <= theta
    in1 = (d1 <= theta) & ~in0
    in0[s0], in1[s0] = True, False
    in1[s1], in0[s1] = True, False
    free = ~(in0 | in1)
    tot = d0 + d1
    tot = np.where(tot > 0, tot, 1.0)
    src = np.where(free, 1.0 - d0 / tot, 0.0)
    snk = np.where(free, 1.0 - d1 / tot, 0.0)

    if len(edges):
        d = (edge_distances(centroids, edges) if edge_distance is None
             else np.asarray(edge_distance, dtype=np.float64))
        dbar = d.mean()
        dist_term = d / (d + dbar) if dbar > 0 else np.zeros_like(d)
        w = lam * (1.0 / (np.abs(f[edges[:, 0]] - f[edges[:, 1]]) + eps) + beta * dist_term)
        if edge_length is not None:
            w = w * np.asarray(edge_length, dtype=np.float64)
    else:
        w = np.zeros(0)
    inf_cap = float(src.sum() + snk.sum() + w.sum() + 1.0)
    src[in0] = inf_cap
    snk[in1] = inf_cap
    return GraphCapacities(source_cap=src, sink_cap=snk, edges=edges, edge_cap=w,
                           inf_cap=inf_cap, seeds=(s0, s1))


def edge_distances(centroids, edges):
    """d(tm, tn): the Euclidean distance between the barycentres of each edge's elements."""
    c = np.asarray(centroids, dtype=np.float64)
    return np.linalg.norm(c[edges[:, 0]] - c[edges[:, 1]], axis=1)


def graphcut_split(gray, edges, centroids, **params):
    """Split a set of triangles in two by the minimum s-t cut (paper 6.1).

    The elements tied to s0 (its seed set, infinite source capacity) are merged into the
    source before the max-flow: an edge from one of them becomes a source t-link of its
    other element, an edge between two of them is never cut. The minimum cut is the same;
    the graph is only what is not already decided, a small part of a component that is
    mostly one material (the recursive cut splits such components many times).

    Parameters
    ----------
    gray, edges, centroids, **params
        As :func:`graphcut_capacities`.

    Returns
    -------
    labels : (m,) int8 ndarray
        0 for the source side (with s0, the darker seed), 1 for the sink side.
    flow : float
        The max-flow value, equal to the smallest s-t cut value of any labelling.

    References
    ----------
    Boykov and Kolmogorov 2004 (PyMaxflow); Yang et al. 2014, section 6.1.

    Example
    -------
    >>> labels, flow = graphcut_split([0.0, 10.0, 240.0, 250.0], [[0, 1], [1, 2], [2, 3]],
    ...                               [[0, 0], [1, 0], [2, 0], [3, 0]])
    >>> labels.tolist()
    [0, 0, 1, 1]
    """
    caps = graphcut_capacities(gray, edges, centroids, **params)
    m = len(caps.source_cap)
    untied = caps.source_cap < caps.inf_cap
    n = int(untied.sum())
    index = np.cumsum(untied) - 1
    src, snk = caps.source_cap[untied], caps.sink_cap[untied]
    e, w = caps.edges, caps.edge_cap
    if len(e):
        ua, ub = untied[e[:, 0]], untied[e[:, 1]]
        one = ua != ub
        src = src + np.bincount(index[np.where(ua[one], e[one, 0], e[one, 1])], w[one], n)
        both = ua & ub
        e, w = index[e[both]], w[both]
    g = maxflow.Graph[float](n, len(e))
    nodes = g.add_nodes(n)
    if len(e):
        g.add_edges(nodes[e[:, 0]], nodes[e[:, 1]], w, w)
    g.add_grid_tedges(nodes, src, snk)
    flow = g.maxflow()
    labels = np.zeros(m, np.int8)
    labels[untied] = g.get_grid_segments(nodes)
    return labels, float(flow)
