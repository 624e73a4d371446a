import itertools

import numpy as np
import pytest

from ctseg.errors import ParameterError
from ctseg.graphcut import graphcut_capacities, graphcut_split
from oracles import cut_energy


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
