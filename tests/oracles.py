"""Reference computations the tests check ctseg against (not used by ctseg itself).

Imported by the tests as ``from oracles import ...`` (pytest puts tests/ on sys.path: the
folder has no __init__.py).
"""
import numpy as np

from ctseg._cvt import _nearest_many
from ctseg.errors import InputError


def nearest_site(points, sites):
    """Index of the nearest site for each point (Euclidean; ties go to the lower index).

    Runs the CVT's compiled grid search (:mod:`ctseg._cvt`) on arbitrary points, so that
    the tests can check it against brute force and the CVT's regions against it.
    """
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    sites = np.ascontiguousarray(sites, dtype=np.float64).reshape(-1, 2)
    if len(sites) == 0:
        raise InputError("sites: need at least one site")
    lo = np.minimum(points.min(axis=0, initial=np.inf), sites.min(axis=0))
    return _nearest_many(points - lo, sites - lo)


def pixel_centres(shape):
    """(rows * cols, 2) pixel centres (x, y) in row-major order."""
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    return np.column_stack([xx.ravel(), yy.ravel()]).astype(np.float64)


def cvt_energy(rho, sites, labels):
    """CVT energy F = sum_j rho_j ||c_j - x_{label(j)}||^2 over pixels j (paper eq. 4)."""
    rho = np.asarray(rho, float)
    d = pixel_centres(rho.shape) - np.asarray(sites, float)[np.asarray(labels).ravel()]
    return float(np.sum(rho.ravel() * (d[:, 0] ** 2 + d[:, 1] ** 2)))


def ward_cost(w_a, m_a, w_b, m_b):
    """Increase of the weighted energy when clusters a and b merge (Ward 1963).

    ``Delta(A, B) = W_A W_B / (W_A + W_B) * ||m_A - m_B||^2`` with weight sums W and
    weighted centroids m; works on scalars or arrays (centroids on the last axis).
    """
    d = np.asarray(m_a, float) - np.asarray(m_b, float)
    return w_a * w_b / (w_a + w_b) * np.sum(d * d, axis=-1)


def cut_energy(caps, labels):
    """Energy of a labelling (0/1 per node) under ``caps`` (a
    :class:`ctseg.graphcut.GraphCapacities`): the value of its s-t cut."""
    labels = np.asarray(labels).astype(bool)
    e = np.where(labels, caps.source_cap, caps.sink_cap).sum()
    if len(caps.edges):
        e += caps.edge_cap[labels[caps.edges[:, 0]] != labels[caps.edges[:, 1]]].sum()
    return float(e)


def box_share(shape):
    """Volume of each voxel inside the box of voxel centres: 1, 1/2, 1/4, 1/8."""
    w = np.ones(shape)
    for ax in range(3):
        idx = [slice(None)] * 3
        for end in (0, -1):
            idx[ax] = end
            w[tuple(idx)] *= 0.5
    return w
