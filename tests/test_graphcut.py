import itertools

import numpy as np
import pytest

from ctseg.errors import ParameterError
from ctseg.graphcut import edge_distances, graphcut_capacities, graphcut_split
from oracles import cut_energy


def spec6_energy(gray, edges, cent, labels, theta, lam=70.0, beta=0.286, eps=1.0):
    """SPEC 6's cut value of a 0/1 labelling, from its formulas (not from the code's
    capacities): infinite where a seed set is cut off its terminal."""
    f = np.asarray(gray, float)
    s0, s1 = int(np.argmin(f)), int(np.argmax(f))
    d0, d1 = np.abs(f - f[s0]), np.abs(f - f[s1])
    total = 0.0
    for t, lab in enumerate(labels):
        in0 = d0[t] <= theta or t == s0
        in1 = (d1[t] <= theta and not in0) or t == s1
        if (in0 and t != s1 and lab == 1) or (in1 and lab == 0):
            return np.inf
        if not (in0 or in1):  # label 0 cuts the link to s1, label 1 the link to s0
            total += 1 - (d1[t] if lab == 0 else d0[t]) / (d0[t] + d1[t])
    dist = [np.sqrt(sum((cent[a][k] - cent[b][k]) ** 2 for k in range(len(cent[a]))))
            for a, b in edges]
    dbar = np.mean(dist)
    for (a, b), d in zip(edges, dist):
        if labels[a] != labels[b]:
            total += lam * (1 / (abs(f[a] - f[b]) + eps) + beta * d / (d + dbar))
    return total


def tetrahedron_graph(seed):
    """A Delaunay tetrahedralisation of random points stretched along z, with 4 to 12
    tetrahedra: (gray, face-sharing pairs, barycentres)."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    while True:
        pts = rng.uniform(0, 1, (rng.integers(6, 9), 3)) * [2.0, 2.0, 12.0]
        tets = Delaunay(pts).simplices
        if 4 <= len(tets) <= 12:
            break
    faces = {}
    for t, tet in enumerate(tets):
        for drop in range(4):
            faces.setdefault(tuple(sorted(np.delete(tet, drop))), []).append(t)
    edges = np.array([f for f in faces.values() if len(f) == 2])
    return rng.uniform(0, 255, len(tets)), edges, pts[tets].mean(axis=1)


def random_graph(n, seed):
    rng = np.random.default_rng(seed)
    gray = rng.uniform(0, 255, n)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < 0.35]
    pairs += [(i, i + 1) for i in range(n - 1)]  # connected
    edges = np.unique(np.array(pairs), axis=0)
    cent = rng.uniform(0, 20, (n, 2))
    return gray, edges, cent


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("n", [4, 8, 12])
def test_min_cut_equals_brute_force_minimum(n, seed):
    gray, edges, cent = random_graph(n, seed)
    caps = graphcut_capacities(gray, edges, cent, theta_255=20.0)
    best = min(cut_energy(caps, lab) for lab in itertools.product([0, 1], repeat=n))
    labels, flow = graphcut_split(gray, edges, cent, theta_255=20.0)
    assert np.isclose(flow, best, rtol=1e-9, atol=1e-9)
    assert np.isclose(cut_energy(caps, labels), best, rtol=1e-9, atol=1e-9)
    s0, s1 = caps.seeds
    assert labels[s0] == 0 and labels[s1] == 1  # source side is label 0


@pytest.mark.parametrize("seed", range(8))
def test_min_cut_on_tetrahedron_graphs_equals_spec6_enumeration(seed):
    # the distance term in 3D: barycentres 3D, the z distances larger than x and y
    gray, edges, cent = tetrahedron_graph(seed)
    n = len(gray)
    best = min(spec6_energy(gray, edges, cent, lab, 20.0) for lab in itertools.product([0, 1], repeat=n))
    labels, flow = graphcut_split(gray, edges, cent, theta_255=20.0)
    assert np.isclose(flow, best, rtol=1e-9)
    assert np.isclose(spec6_energy(gray, edges, cent, labels, 20.0), best, rtol=1e-9)


def test_capacities_follow_spec():
    gray = np.array([0.0, 10.0, 50.0, 100.0, 95.0])
    edges = np.array([[0, 1], [1, 2], [2, 3], [3, 4]])
    cent = np.array([[0.0, 0], [1, 0], [2, 0], [3, 0], [5, 0]])
    caps = graphcut_capacities(gray, edges, cent, lam=70.0, beta=0.286, eps_255=1.0)
    assert caps.seeds == (0, 3)
    # theta = 10 -> V0 = {0, 1}, V1 = {3, 4}, Vf = {2}
    assert caps.source_cap[0] == caps.inf_cap and caps.sink_cap[0] == 0
    assert caps.source_cap[1] == caps.inf_cap and caps.sink_cap[1] == 0
    assert caps.sink_cap[3] == caps.inf_cap and caps.source_cap[3] == 0
    assert caps.sink_cap[4] == caps.inf_cap
    d0, d1 = 50.0, 50.0
    assert np.isclose(caps.source_cap[2], 1 - d0 / (d0 + d1))
    assert np.isclose(caps.sink_cap[2], 1 - d1 / (d0 + d1))
    d = np.array([1.0, 1.0, 1.0, 2.0])
    dbar = d.mean()
    df = np.array([10.0, 40.0, 50.0, 5.0])
    np.testing.assert_allclose(caps.edge_cap, 70.0 * (1 / (df + 1.0) + 0.286 * d / (d + dbar)))
    assert caps.inf_cap > caps.edge_cap.sum() + caps.source_cap[2] + caps.sink_cap[2]


def test_two_blobs_are_separated():
    # a chain: five dark nodes, then five bright nodes
    gray = np.array([10, 12, 9, 11, 10, 200, 205, 198, 202, 201], float)
    edges = np.array([[i, i + 1] for i in range(9)])
    cent = np.column_stack([np.arange(10.0), np.zeros(10)])
    labels, _ = graphcut_split(gray, edges, cent)
    assert labels.tolist() == [0] * 5 + [1] * 5


def test_bad_seeds():
    gray, edges, cent = random_graph(5, 0)
    with pytest.raises(ParameterError):
        graphcut_split(gray, edges, cent, seeds=(1, 1))
    with pytest.raises(ParameterError):
        graphcut_split(gray, edges, cent, seeds=(0, 9))


def _full_graph_cut(caps):
    """The max-flow of every element and edge, none merged into a terminal (the graph
    graphcut_split solved before it merged the elements tied to s0 into the source)."""
    import maxflow

    m = len(caps.source_cap)
    g = maxflow.Graph[float](m, len(caps.edges))
    nodes = g.add_nodes(m)
    g.add_edges(nodes[caps.edges[:, 0]], nodes[caps.edges[:, 1]], caps.edge_cap, caps.edge_cap)
    g.add_grid_tedges(nodes, caps.source_cap, caps.sink_cap)
    flow = g.maxflow()
    return g.get_grid_segments(nodes).astype(np.int8), flow


@pytest.mark.parametrize("seed", range(4))
def test_merging_the_source_seed_set_keeps_the_cut(seed):
    # a noisy dark grid with bright and middle-gray blobs: most elements are tied to s0
    rng = np.random.default_rng(seed)
    n = 40
    yy, xx = np.mgrid[0:n, 0:n]
    gray = rng.normal(20.0, 4.0, (n, n))
    for _ in range(6):
        cy, cx, r = rng.uniform(4, n - 4), rng.uniform(4, n - 4), rng.uniform(1.5, 4.0)
        gray[(yy - cy) ** 2 + (xx - cx) ** 2 < r * r] = rng.choice([120.0, 230.0])
    ids = np.arange(n * n).reshape(n, n)
    edges = np.concatenate([np.column_stack([ids[:, :-1].ravel(), ids[:, 1:].ravel()]),
                            np.column_stack([ids[:-1].ravel(), ids[1:].ravel()])])
    cent = np.column_stack([xx.ravel(), yy.ravel()]).astype(float)
    caps = graphcut_capacities(gray.ravel(), edges, cent)
    assert np.mean(caps.source_cap == caps.inf_cap) > 0.5
    expected, expected_flow = _full_graph_cut(caps)
    labels, flow = graphcut_split(gray.ravel(), edges, cent)
    assert np.array_equal(labels, expected)
    assert np.isclose(flow, expected_flow, rtol=1e-9)
    # the distances given instead of the centroids: the same capacities
    given = graphcut_capacities(gray.ravel(), edges, None, edge_distance=edge_distances(cent, edges))
    assert np.array_equal(given.edge_cap, caps.edge_cap)
