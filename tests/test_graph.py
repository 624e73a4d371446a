"""Element-graph helpers (ctseg.graph): the connected pieces against scipy's depth-first
search, the slow reference, whose numbering the labelling's order follows."""
import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ctseg.graph import connected_pieces


@pytest.mark.parametrize("seed", range(8))
def test_connected_pieces_number_as_scipy_does(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 400))
    pairs = rng.integers(0, n, (int(rng.integers(0, 2 * n)), 2))  # self-loops, repeats
    count, labels = connected_pieces(pairs, n)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    expected_count, expected = connected_components(graph, directed=False)
    assert count == expected_count
    assert np.array_equal(labels, expected)


def test_connected_pieces_refuse_nodes_out_of_range():
    with pytest.raises(ValueError, match="node indices"):
        connected_pieces([[0, 5]], 5)
