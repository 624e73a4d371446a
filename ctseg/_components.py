"""Compiled kernel (numba) of :func:`ctseg.graph.connected_pieces`: connected components
by union-find, numbered as scipy's depth-first search numbers them (in the order of each
component's smallest node), without building a sparse matrix of the graph (the recursive
cut asks for the pieces of its largest component once per cut).

Private: :func:`ctseg.graph.connected_pieces` is the entry point.
"""
import numpy as np
from numba import njit


@njit(cache=True)
def _root(parent, v):
    while parent[v] != v:
        parent[v] = parent[parent[v]]  # path halving
        v = parent[v]
    return v


@njit(cache=True)
def components(a, b, n):
    """Component of each of the ``n`` nodes joined by the edges (a[k], b[k]), numbered
    0, 1, ... in the order of their smallest node; returns (count, labels)."""
    parent = np.arange(n)
    for k in range(a.shape[0]):
        ra = _root(parent, a[k])
        rb = _root(parent, b[k])
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    label = np.full(n, -1, np.int32)
    count = 0
    for v in range(n):
        r = _root(parent, v)
        if label[r] < 0:
            label[r] = count
            count += 1
        label[v] = label[r]
    return count, label
