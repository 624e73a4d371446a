"""Compiled kernels (numba) of :mod:`ctseg.sites`: Ward's merge heap.

Private: :func:`ctseg.sites.ward_agglomerate` is the entry point.
"""
import numpy as np
from numba import njit

_ARITY = 4  # children per heap node: half the depth of a binary heap, fewer cache misses
_VERSION = np.int64(1) << 32  # two versions packed in one int64


# Compiled (numba): the pure-Python heap took 0.4-0.6 s of 5.0 s at 512 x 512 / 1000 sites
# and grows with the pixel count. The heap is a 4-ary one over (n, 3) int64 records
# (cost bits, pair, versions): numba's heapq over tuples took 1.2-1.3x as long, a binary
# heap over three arrays (one per field) 1.15x.
@njit(cache=True)
def _ward_merges(w, s, ea, eb, m, n_clusters):
    """Greedy Ward merges on the graph (ea[k], eb[k]) until n_clusters remain.

    Same order as a textbook lazy-deletion heap of (cost, i, j, version_i, version_j) with
    i < j: the tuples order the merges completely, so ties go to the smaller indices.
    A record holds the cost's bits (for costs >= 0 the int64 order of the bits is the
    float order), ``i * m + j`` (the (i, j) order) and both versions (each < 2^32).
    Neighbour lists are linked lists in one record pool; a merge splices j's list onto
    i's, then compacts i's to distinct live clusters. Updates w and s ((m, d): the weighted
    coordinate sums, any dimension d) in place; returns each node's parent (the node it merged
    into, itself for a survivor) and the number of clusters left.
    """
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
    parent = np.arange(m)
    alive = np.ones(m, np.bool_)
    version = np.zeros(m, np.int64)
    stamp = np.full(m, -1, np.int64)
    cost = np.empty(1)
    cost_bits = cost.view(np.int64)
    mm = np.int64(m)

    # first the distinct pairs (duplicated edges give equal records: harmless)
    heap = np.empty((max(2 * e, 16), 3), np.int64)
    for k in range(e):
        i = min(ea[k], eb[k])
        j = max(ea[k], eb[k])
        cost[0] = _ward_pair_cost(w, s, i, j)
        heap[k, 0] = cost_bits[0]
        heap[k, 1] = i * mm + j
        heap[k, 2] = 0
    n = e
    for pos in range((n - 2) // _ARITY, -1, -1):
        _sift_down(heap, n, pos)
    n_alive = m
    while n_alive > n_clusters and n > 0:
        i = heap[0, 1] // mm
        j = heap[0, 1] % mm
        vi = heap[0, 2] // _VERSION
        vj = heap[0, 2] % _VERSION
        n -= 1
        if n > 0:
            heap[0, 0] = heap[n, 0]
            heap[0, 1] = heap[n, 1]
            heap[0, 2] = heap[n, 2]
            _sift_down(heap, n, 0)
        if not (alive[i] and alive[j]) or version[i] != vi or version[j] != vj:
            continue
        w[i] += w[j]
        for ax in range(s.shape[1]):
            s[i, ax] += s[j, ax]
        alive[j] = False
        parent[j] = i
        version[i] += 1
        if head[j] >= 0:  # splice j's records onto i's
            if head[i] < 0:
                head[i] = head[j]
            else:
                nxt[tail[i]] = head[j]
            tail[i] = tail[j]
        head[j] = -1
        # compact i's list to distinct live neighbours, pushing the new pair costs
        stamp[i] = n_alive
        prev = -1
        r = head[i]
        while r >= 0:
            k = tgt[r]
            while not alive[k]:
                k = parent[k]
            tgt[r] = k
            if stamp[k] == n_alive:  # self or already seen: drop the record
                r = nxt[r]
                if prev < 0:
                    head[i] = r
                else:
                    nxt[prev] = r
                continue
            stamp[k] = n_alive
            a = min(i, k)
            b = max(i, k)
            if n == heap.shape[0]:
                grown = np.empty((2 * n, 3), np.int64)
                grown[:n] = heap[:n]
                heap = grown
            cost[0] = _ward_pair_cost(w, s, a, b)
            heap[n, 0] = cost_bits[0]
            heap[n, 1] = a * mm + b
            heap[n, 2] = version[a] * _VERSION + version[b]
            _sift_up(heap, n)
            n += 1
            prev = r
            r = nxt[r]
        tail[i] = prev
        if prev < 0:
            head[i] = -1
        n_alive -= 1
    return parent, n_alive


@njit(cache=True)
def _sift_down(heap, n, pos):
    """Move the record at pos down to its place among the first n."""
    c0 = heap[pos, 0]
    c1 = heap[pos, 1]
    c2 = heap[pos, 2]
    while True:
        first = _ARITY * pos + 1
        if first >= n:
            break
        best = first
        for q in range(first + 1, min(first + _ARITY, n)):
            if heap[q, 0] < heap[best, 0] or (heap[q, 0] == heap[best, 0]
                                              and heap[q, 1] < heap[best, 1]):
                best = q
        if heap[best, 0] < c0 or (heap[best, 0] == c0 and heap[best, 1] < c1):
            heap[pos, 0] = heap[best, 0]
            heap[pos, 1] = heap[best, 1]
            heap[pos, 2] = heap[best, 2]
            pos = best
        else:
            break
    heap[pos, 0] = c0
    heap[pos, 1] = c1
    heap[pos, 2] = c2


@njit(cache=True)
def _sift_up(heap, pos):
    """Move the record at pos up to its place."""
    c0 = heap[pos, 0]
    c1 = heap[pos, 1]
    c2 = heap[pos, 2]
    while pos > 0:
        up = (pos - 1) // _ARITY
        if c0 < heap[up, 0] or (c0 == heap[up, 0] and c1 < heap[up, 1]):
            heap[pos, 0] = heap[up, 0]
            heap[pos, 1] = heap[up, 1]
            heap[pos, 2] = heap[up, 2]
            pos = up
        else:
            break
    heap[pos, 0] = c0
    heap[pos, 1] = c1
    heap[pos, 2] = c2


@njit(cache=True)
def _ward_pair_cost(w, s, i, j):
    wi = w[i]
    wj = w[j]
    d2 = 0.0  # 0.0 + dx * dx + dy * dy: the same bits as dx * dx + dy * dy
    for ax in range(s.shape[1]):
        d = s[i, ax] / wi - s[j, ax] / wj
        d2 += d * d
    return wi * wj / (wi + wj) * d2
