"""Element-graph helpers shared by the labelling stages: an element is a triangle or a
tetrahedron, and the graph joins elements that share an edge (2D) or a face (3D)."""
import numpy as np

from ._components import components


def neighbour_lists(pairs, n):
    """Neighbours of every node in CSR form.

    Parameters
    ----------
    pairs : (k, 2) int array_like
        Undirected edges between nodes 0..n-1.
    n : int
        Number of nodes.

    Returns
    -------
    start : (n + 1,) int64 ndarray
    neighbours : (2 k,) int64 ndarray
        The neighbours of node i are ``neighbours[start[i]:start[i + 1]]``, in the order
        the pairs list them: first the pairs where i is first, then where it is second.

    Example
    -------
    >>> start, nb = neighbour_lists([[0, 1], [1, 2]], 3)
    >>> nb[start[1]:start[2]].tolist()
    [2, 0]
    """
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    src = np.concatenate([pairs[:, 0], pairs[:, 1]])
    dst = np.concatenate([pairs[:, 1], pairs[:, 0]])
    order = np.argsort(src, kind="stable")
    return np.searchsorted(src[order], np.arange(n + 1)), dst[order]


def connected_pieces(pairs, n):
    """Connected components of an undirected graph of ``n`` nodes.

    Returns
    -------
    n_pieces : int
    piece : (n,) int ndarray
        Component of every node, numbered in the order of each component's smallest
        node (as scipy.sparse.csgraph.connected_components numbers them).

    Example
    -------
    >>> connected_pieces([[0, 1], [2, 3]], 5)[0]
    3
    """
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    if len(pairs) and (pairs.min() < 0 or pairs.max() >= n):
        raise ValueError(f"connected_pieces: node indices must lie in [0, {n - 1}]")
    return components(np.ascontiguousarray(pairs[:, 0]), np.ascontiguousarray(pairs[:, 1]), int(n))


def core_bounds(levels):
    """Half-widths of each level's core zone: a quarter of the gap to the neighbouring
    levels below and above (infinite past the first and last).

    Returns
    -------
    below, above : (K,) ndarray

    Example
    -------
    >>> [b.tolist() for b in core_bounds([0.0, 100.0])]
    [[inf, 25.0], [25.0, inf]]
    """
    gaps = np.diff(np.asarray(levels, float))
    return np.r_[np.inf, gaps] * 0.25, np.r_[gaps, np.inf] * 0.25


def nearest_level_core(values, levels):
    """The nearest level of every value and whether the value lies in that level's core
    (:func:`core_bounds`).

    Returns
    -------
    nearest : (m,) int ndarray
    in_core : (m,) bool ndarray
    """
    f = np.asarray(values, float)
    levels = np.asarray(levels, float)
    below, above = core_bounds(levels)
    nearest = np.argmin(np.abs(f[:, None] - levels[None, :]), axis=1)
    dev = f - levels[nearest]
    return nearest, np.where(dev < 0, -dev <= below[nearest], dev <= above[nearest])
