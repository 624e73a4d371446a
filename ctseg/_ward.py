"""Compiled kernels (numba) of :mod:`ctseg.sites`: Ward's merge heap, and the rounds of
reciprocal-pair merges that pre-merge a large 3D block graph.

Private: :func:`ctseg.sites.ward_agglomerate` and :func:`ctseg.sites.ward_sites_3d` are
the entry points.
"""
import numpy as np
from numba import njit, prange

from . import _threads
from ._sets import unique_ints

_ARITY = 4  # children per heap node: half the depth of a binary heap, fewer cache misses

ROUND_SHARE = 0.5
"""Share of the reciprocal pairs (the cheapest) that merge in one round of
:func:`reciprocal_premerge`. Merging all of them would merge every region at the same
pace, as if the density were flat; the cheapest half keeps greedy Ward's order between
dense and flat regions (README, *Accuracy in 3D*, has the measurements)."""
ROUNDS_PER_SITE = 4
"""The rounds stop at this many clusters per site; the greedy heap takes them from there."""


def reciprocal_premerge(weights, centroids, edges, n_clusters):
    """Ward pre-merge by rounds of reciprocal nearest-neighbour pairs
    (:func:`_reciprocal_rounds`, :data:`ROUND_SHARE`) down to ``n_clusters``: the
    clusters' weights, weighted centroids and (unique) adjacency, numbered in node order.
    """
    w = np.asarray(weights, np.float64).copy()
    s = np.ascontiguousarray(np.asarray(centroids, np.float64) * w[:, None])
    edges = np.asarray(edges, np.int64).reshape(-1, 2)
    ea, eb = np.ascontiguousarray(edges[:, 0]), np.ascontiguousarray(edges[:, 1])
    parent, _, n_edges = _reciprocal_rounds(w, s, ea, eb, int(n_clusters), ROUND_SHARE,
                                            _threads.workers())
    roots = np.flatnonzero(parent == np.arange(len(w)))
    index = np.full(len(w), -1, np.int64)
    index[roots] = np.arange(len(roots))
    a, b = index[ea[:n_edges]], index[eb[:n_edges]]
    key = unique_ints(np.minimum(a, b) * len(roots) + np.maximum(a, b))
    return (w[roots], s[roots] / w[roots, None],
            np.column_stack([key // len(roots), key % len(roots)]))


# Compiled (numba): the pure-Python heap took 0.4-0.6 s of 5.0 s at 512 x 512 / 1000 sites
# and grows with the pixel count. The heap is indexed (each live pair once, its position
# kept, its key changed in place): a lazy-deletion heap, which pushes a new record for
# every changed pair and skips the stale ones when they surface, popped 11.6 records per
# merge on the 512000 blocks of a 160^3 volume and took 1.85x as long.


@njit(cache=True)
def _ward_merges(w, s, ea, eb, m, n_clusters):
    """Greedy Ward merges on the graph (ea[k], eb[k]) until n_clusters remain.

    Same order as a textbook lazy-deletion heap of (cost, i, j, version_i, version_j) with
    i < j: the tuples order the merges completely, so ties go to the smaller indices. The
    heap holds one record per live edge k: the cost's bits (for costs >= 0 the int64 order
    of the bits is the float order), ``i * m + j`` (the (i, j) order) and k; ``pos[k]`` is
    its place (-1 once the edge is dead). Neighbour lists are linked lists in one record
    pool (record r belongs to edge r // 2); a merge splices j's list onto i's, then walks
    it: the first live edge to each neighbour gets the new pair's cost in place, a second
    live edge to the same neighbour (or one to i itself) dies, and the records of dead edges
    leave the list. So every adjacent pair of clusters has exactly one live edge, whose
    records lie in both clusters' lists. Updates w and s ((m, d): the weighted coordinate
    sums, any dimension d) in place; returns each node's parent (the node it merged into,
    itself for a survivor) and the number of clusters left.
    """
    e = ea.shape[0]
    nxt, tgt, head, tail = _neighbour_lists(ea, eb, m)
    parent = np.arange(m)
    alive = np.ones(m, np.bool_)
    stamp = np.full(m, -1, np.int64)
    cost = np.empty(1)
    cost_bits = cost.view(np.int64)
    mm = np.int64(m)
    heap = np.empty((max(e, 1), 3), np.int64)
    pos = np.empty(max(e, 1), np.int64)
    for k in range(e):
        i = min(ea[k], eb[k])
        j = max(ea[k], eb[k])
        cost[0] = _ward_pair_cost(w, s, i, j)
        heap[k, 0] = cost_bits[0]
        heap[k, 1] = i * mm + j
        heap[k, 2] = k
        pos[k] = k
    n = e
    for p in range((n - 2) // _ARITY, -1, -1):
        _sift_down(heap, pos, n, p)
    n_alive = m
    while n_alive > n_clusters and n > 0:
        i = heap[0, 1] // mm
        j = heap[0, 1] % mm
        n = _delete(heap, pos, n, heap[0, 2])
        w[i] += w[j]
        for ax in range(s.shape[1]):
            s[i, ax] += s[j, ax]
        alive[j] = False
        parent[j] = i
        if head[j] >= 0:
            if head[i] < 0:
                head[i] = head[j]
            else:
                nxt[tail[i]] = head[j]
            tail[i] = tail[j]
        head[j] = -1
        stamp[i] = n_alive
        prev = -1
        r = head[i]
        while r >= 0:
            eid = r // 2
            if pos[eid] >= 0:
                k = tgt[r]
                while not alive[k]:
                    k = parent[k]
                tgt[r] = k
                if stamp[k] != n_alive:
                    stamp[k] = n_alive
                    a = min(i, k)
                    b = max(i, k)
                    cost[0] = _ward_pair_cost(w, s, a, b)
                    p = pos[eid]
                    heap[p, 0] = cost_bits[0]
                    heap[p, 1] = a * mm + b
                    _fix(heap, pos, n, p)
                    prev = r
                    r = nxt[r]
                    continue
                n = _delete(heap, pos, n, eid)  # self, or a second edge to k
            r = nxt[r]  # drop the record of a dead edge
            if prev < 0:
                head[i] = r
            else:
                nxt[prev] = r
        tail[i] = prev
        if prev < 0:
            head[i] = -1
        n_alive -= 1
    return parent, n_alive


@njit(cache=True)
def _neighbour_lists(ea, eb, m):
    """The graph's neighbour lists as linked lists in one record pool: record 2k (in
    ea[k]'s list) points to eb[k], record 2k + 1 (in eb[k]'s) to ea[k]; returns (next
    record, target, each node's first and last record; -1 for none)."""
    e = ea.shape[0]
    nxt = np.full(2 * e, -1, np.int64)
    tgt = np.empty(2 * e, np.int64)
    head = np.full(m, -1, np.int64)
    tail = np.full(m, -1, np.int64)
    for k in range(2 * e):
        a = ea[k // 2] if k % 2 == 0 else eb[k // 2]
        b = eb[k // 2] if k % 2 == 0 else ea[k // 2]
        tgt[k] = b
        if head[a] < 0:
            head[a] = k
        else:
            nxt[tail[a]] = k
        tail[a] = k
    return nxt, tgt, head, tail


@njit(cache=True)
def _less(heap, p, q):
    """Record p orders before record q."""
    return heap[p, 0] < heap[q, 0] or (heap[p, 0] == heap[q, 0] and heap[p, 1] < heap[q, 1])


@njit(cache=True)
def _delete(heap, pos, n, eid):
    """Remove edge eid's record from the first n; returns the new count."""
    p = pos[eid]
    pos[eid] = -1
    n -= 1
    if p != n:
        heap[p, 0] = heap[n, 0]
        heap[p, 1] = heap[n, 1]
        heap[p, 2] = heap[n, 2]
        pos[heap[p, 2]] = p
        _fix(heap, pos, n, p)
    return n


@njit(cache=True)
def _fix(heap, pos, n, p):
    """Move the record at p, whose key changed, to its place among the first n."""
    if p > 0 and _less(heap, p, (p - 1) // _ARITY):
        _sift_up(heap, pos, p)
    else:
        _sift_down(heap, pos, n, p)


@njit(cache=True)
def _sift_down(heap, pos, n, p):
    """Move the record at p down to its place among the first n, keeping pos."""
    c0 = heap[p, 0]
    c1 = heap[p, 1]
    c2 = heap[p, 2]
    while True:
        first = _ARITY * p + 1
        if first >= n:
            break
        best = first
        for q in range(first + 1, min(first + _ARITY, n)):
            if heap[q, 0] < heap[best, 0] or (heap[q, 0] == heap[best, 0]
                                              and heap[q, 1] < heap[best, 1]):
                best = q
        if heap[best, 0] < c0 or (heap[best, 0] == c0 and heap[best, 1] < c1):
            heap[p, 0] = heap[best, 0]
            heap[p, 1] = heap[best, 1]
            heap[p, 2] = heap[best, 2]
            pos[heap[p, 2]] = p
            p = best
        else:
            break
    heap[p, 0] = c0
    heap[p, 1] = c1
    heap[p, 2] = c2
    pos[c2] = p


@njit(cache=True)
def _sift_up(heap, pos, p):
    """Move the record at p up to its place, keeping pos."""
    c0 = heap[p, 0]
    c1 = heap[p, 1]
    c2 = heap[p, 2]
    while p > 0:
        up = (p - 1) // _ARITY
        if c0 < heap[up, 0] or (c0 == heap[up, 0] and c1 < heap[up, 1]):
            heap[p, 0] = heap[up, 0]
            heap[p, 1] = heap[up, 1]
            heap[p, 2] = heap[up, 2]
            pos[heap[p, 2]] = p
            p = up
        else:
            break
    heap[p, 0] = c0
    heap[p, 1] = c1
    heap[p, 2] = c2
    pos[c2] = p


@njit(cache=True)
def _ward_pair_cost(w, s, i, j):
    wi = w[i]
    wj = w[j]
    d2 = 0.0  # 0.0 + dx * dx + dy * dy: the same bits as dx * dx + dy * dy
    for ax in range(s.shape[1]):
        d = s[i, ax] / wi - s[j, ax] / wj
        d2 += d * d
    return wi * wj / (wi + wj) * d2


@njit(cache=True)
def _reciprocal_rounds(w, s, ea, eb, n_target, share, n_threads):
    """Merge reciprocal nearest neighbours of the graph (ea[k], eb[k]) in rounds until
    n_target clusters remain (or no edge joins two).

    Each round every cluster finds its cheapest neighbour by the Ward cost (ties: the
    smaller index); the pairs that chose each other are ranked by cost (ties: the smaller
    first index) and the cheapest ``share`` of them (at least one, at most as many as
    reach n_target) merge, the larger index into the smaller. Updates w and s in place;
    returns each node's parent (itself for a survivor: follow the chain to the root), the
    number of clusters left and of edges: the first ones of ea, eb join survivors.
    """
    m = w.shape[0]
    e = ea.shape[0]
    parent = np.arange(m)
    nodes = np.arange(m)  # the live clusters
    n_nodes = m
    best, best_cost = np.empty(m, np.int64), np.empty(m)
    n_parts = max(1, min(n_threads, e // 65536))
    part_best, part_cost = np.empty((n_parts, m), np.int64), np.empty((n_parts, m))
    pa, pb, pc = np.empty(m, np.int64), np.empty(m, np.int64), np.empty(m)
    while n_nodes > n_target and e > 0:
        _cheapest_neighbours(w, s, ea, eb, e, nodes, n_nodes, part_best, part_cost, best,
                             best_cost)
        n = 0
        for q in range(n_nodes):
            a = nodes[q]
            b = best[a]
            if a < b < m and best[b] == a:
                pa[n] = a
                pb[n] = b
                pc[n] = best_cost[a]
                n += 1
        keep = min(max(1, int(np.ceil(share * n))), n_nodes - n_target, n)
        if keep == 0:  # cannot happen: the cheapest edge by (cost, ends) is a reciprocal pair
            break
        if keep < n:  # a stable sort: equal costs keep the smaller first index first
            sel = np.sort(np.argsort(pc[:n], kind="mergesort")[:keep])
            for q in range(keep):
                pa[q] = pa[sel[q]]
                pb[q] = pb[sel[q]]
        for q in range(keep):
            a = pa[q]
            b = pb[q]
            w[a] += w[b]
            for ax in range(s.shape[1]):
                s[a, ax] += s[b, ax]
            parent[b] = a
        e = _relink(parent, ea, eb, e, m, 8 * (n_nodes - keep))
        n = 0
        for q in range(n_nodes):
            if parent[nodes[q]] == nodes[q]:
                nodes[n] = nodes[q]
                n += 1
        n_nodes = n
    return parent, n_nodes, e


@njit(cache=True, parallel=True)
def _cheapest_neighbours(w, s, ea, eb, e, nodes, n_nodes, part_best, part_cost, best,
                         best_cost):
    """Each live node's cheapest neighbour over the first e edges and its Ward cost (ties:
    the smaller index; m for none). The edges are split among the rows of ``part_best``,
    ``part_cost``, each part's best found apart and then the parts' best: the order
    (cost, index) is total, so the split changes nothing."""
    m = w.shape[0]
    n_parts = part_best.shape[0]
    for t in prange(n_parts):
        pb = part_best[t]
        pc = part_cost[t]
        for q in range(n_nodes):
            pc[nodes[q]] = np.inf
            pb[nodes[q]] = m
        for k in range(t * e // n_parts, (t + 1) * e // n_parts):
            a = ea[k]
            b = eb[k]
            c = _ward_pair_cost(w, s, min(a, b), max(a, b))
            if c < pc[a] or (c == pc[a] and b < pb[a]):
                pc[a] = c
                pb[a] = b
            if c < pc[b] or (c == pc[b] and a < pb[b]):
                pc[b] = c
                pb[b] = a
    for q in prange(n_nodes):
        a = nodes[q]
        c = part_cost[0, a]
        b = part_best[0, a]
        for t in range(1, n_parts):
            if part_cost[t, a] < c or (part_cost[t, a] == c and part_best[t, a] < b):
                c = part_cost[t, a]
                b = part_best[t, a]
        best_cost[a] = c
        best[a] = b


@njit(cache=True)
def _relink(parent, ea, eb, e, m, most):
    """The first e edges moved onto the clusters their nodes merged into this round, those
    inside one cluster dropped; once there are more than ``most``, one edge per pair of
    clusters is kept (two clusters of blocks share many edges, and each edge's cost is
    computed every round). Returns the new count."""
    n = 0
    for k in range(e):
        a = parent[ea[k]]
        b = parent[eb[k]]
        if a != b:
            ea[n] = a
            eb[n] = b
            n += 1
    if n <= most:
        return n
    key = np.empty(n, np.int64)
    for k in range(n):
        key[k] = min(ea[k], eb[k]) * m + max(ea[k], eb[k])
    key = np.sort(key)
    e = 0
    for k in range(n):
        if k == 0 or key[k] != key[k - 1]:
            ea[e] = key[k] // m
            eb[e] = key[k] % m
            e += 1
    return e


@njit(cache=True)
def _block_sums_3d(rho, sides, spacing):
    """Per block of ``sides`` (z, y, x) voxels: the sum of rho and the rho-weighted sums of
    the physical x, y, z (rows 0-3), added in voxel order (as np.bincount adds them)."""
    nz, ny, nx = rho.shape
    nby = -(-ny // sides[1])
    nbx = -(-nx // sides[2])
    out = np.zeros((4, -(-nz // sides[0]) * nby * nbx))
    for k in range(nz):
        z = k * spacing[2]
        for j in range(ny):
            y = j * spacing[1]
            row = ((k // sides[0]) * nby + j // sides[1]) * nbx
            for i in range(nx):
                b = row + i // sides[2]
                r = rho[k, j, i]
                out[0, b] += r
                out[1, b] += r * (i * spacing[0])
                out[2, b] += r * y
                out[3, b] += r * z
    return out
