"""Compiled kernels (numba) of :mod:`ctseg.sites`: Ward's merge heap.

Private: :func:`ctseg.sites.ward_agglomerate` is the entry point.
"""
import heapq

import numpy as np
from numba import njit


# Compiled (numba): the pure-Python heap took 0.4-0.6 s of 5.0 s at 512 x 512 / 1000 sites
# and grows with the pixel count.
@njit(cache=True)
def _ward_merges(w, s, ea, eb, m, n_clusters):
    """Greedy Ward merges on the graph (ea[k], eb[k]) until n_clusters remain.

    Same order as a textbook lazy-deletion heap of (cost, i, j, version_i, version_j) with
    i < j: the tuples order the merges completely, so ties go to the smaller indices.
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

    heap = [(0.0, np.int64(0), np.int64(0), np.int64(0), np.int64(0))]
    heap.pop()
    # first the distinct pairs (duplicated edges give equal tuples: harmless)
    for k in range(e):
        i = min(ea[k], eb[k])
        j = max(ea[k], eb[k])
        heap.append((_ward_pair_cost(w, s, i, j), i, j, np.int64(0), np.int64(0)))
    heapq.heapify(heap)
    n_alive = m
    while n_alive > n_clusters and len(heap) > 0:
        _, i, j, vi, vj = heapq.heappop(heap)
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
            heapq.heappush(heap, (_ward_pair_cost(w, s, a, b), a, b, version[a], version[b]))
            prev = r
            r = nxt[r]
        tail[i] = prev
        if prev < 0:
            head[i] = -1
        n_alive -= 1
    return parent, n_alive


@njit(cache=True)
def _ward_pair_cost(w, s, i, j):
    wi = w[i]
    wj = w[j]
    d2 = 0.0  # 0.0 + dx * dx + dy * dy: the same bits as dx * dx + dy * dy
    for ax in range(s.shape[1]):
        d = s[i, ax] / wi - s[j, ax] / wj
        d2 += d * d
    return wi * wj / (wi + wj) * d2
