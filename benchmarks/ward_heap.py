"""Ward's merge heap: the indexed heap of :mod:`ctseg._ward` (what the sites stage runs)
against the lazy-deletion heap it replaced (kept below), side by side in this process.

    python benchmarks/ward_heap.py [--repeats 5] [--out benchmarks/results/ward_heap.md]

The graphs are those the sites stage builds with defaults: the pre-merge blocks of the 2D
density (:func:`ctseg.density.density_map`, defaults, on the raw slice) of
:func:`ctseg.phantoms.make_phantom` (512 x 512, seed 0; 1000 and 4000 sites)
and of the 3D density of :func:`ctseg.phantoms3d.make_part_3d` (96^3 and 160^3, seed 0;
the default site count). Both kernels must give the same parents bit for bit; the times
are medians of interleaved repeats.
"""
import argparse
import os
import platform
import time

import numpy as np
from accuracy import publish  # benchmarks/ is this script's folder
from numba import njit
from run import interleaved_medians

from ctseg import stages3d
from ctseg._ward import _neighbour_lists, _ward_merges, _ward_pair_cost
from ctseg.density import density_map
from ctseg.phantoms import make_phantom
from ctseg.phantoms3d import make_part_3d
from ctseg.sites import _block_graph, _block_graph_3d, default_ward_block_px, ward_block_sides_3d

_LAZY_ARITY = 4
_LAZY_VERSION = np.int64(1) << 32


# the lazy-deletion heap, as ctseg._ward had it until 2026-12-06
@njit(cache=False)
def _lazy_ward_merges(w, s, ea, eb, m, n_clusters):
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
    nxt, tgt, head, tail = _neighbour_lists(ea, eb, m)
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
    for pos in range((n - 2) // _LAZY_ARITY, -1, -1):
        _lazy_sift_down(heap, n, pos)
    n_alive = m
    while n_alive > n_clusters and n > 0:
        i = heap[0, 1] // mm
        j = heap[0, 1] % mm
        vi = heap[0, 2] // _LAZY_VERSION
        vj = heap[0, 2] % _LAZY_VERSION
        n -= 1
        if n > 0:
            heap[0, 0] = heap[n, 0]
            heap[0, 1] = heap[n, 1]
            heap[0, 2] = heap[n, 2]
            _lazy_sift_down(heap, n, 0)
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
            heap[n, 2] = version[a] * _LAZY_VERSION + version[b]
            _lazy_sift_up(heap, n)
            n += 1
            prev = r
            r = nxt[r]
        tail[i] = prev
        if prev < 0:
            head[i] = -1
        n_alive -= 1
    return parent, n_alive


@njit(cache=False)
def _lazy_sift_down(heap, n, pos):
    """Move the record at pos down to its place among the first n."""
    c0 = heap[pos, 0]
    c1 = heap[pos, 1]
    c2 = heap[pos, 2]
    while True:
        first = _LAZY_ARITY * pos + 1
        if first >= n:
            break
        best = first
        for q in range(first + 1, min(first + _LAZY_ARITY, n)):
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


@njit(cache=False)
def _lazy_sift_up(heap, pos):
    """Move the record at pos up to its place."""
    c0 = heap[pos, 0]
    c1 = heap[pos, 1]
    c2 = heap[pos, 2]
    while pos > 0:
        up = (pos - 1) // _LAZY_ARITY
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


def _graphs():
    """(name, weights, weighted sums, edges, clusters) of the four cases."""
    image = make_phantom(512, seed=0).image.astype(np.float64)
    rho = density_map(image)
    for n_sites in (1000, 4000):
        w, c, e = _block_graph(rho, default_ward_block_px(rho.shape, n_sites))
        yield f"2D 512 x 512, {n_sites} sites", w, c * w[:, None], e, n_sites
    for size in (96, 160):
        image = make_part_3d(size, seed=0, keep_fractions=False).image.astype(np.float64)
        rho = stages3d.density_3d(image)
        n_sites = stages3d.n_sites_3d(image)[0]
        sp = np.ones(3)
        w, c, e = _block_graph_3d(rho, sp, ward_block_sides_3d(rho.shape, sp, n_sites))
        yield f"3D {size}^3, {n_sites} sites", w, c * w[:, None], e, n_sites


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default=None, help="markdown path; the JSON goes beside it")
    args = ap.parse_args()
    rows = []
    for name, w, s, e, k in _graphs():
        def run(kernel):
            return kernel(w.copy(), np.array(s, order="C"), np.ascontiguousarray(e[:, 0]),
                          np.ascontiguousarray(e[:, 1]), len(w), k)
        ref = run(_lazy_ward_merges)  # also compiles both outside the timings
        if not np.array_equal(run(_ward_merges)[0], ref[0]):
            raise SystemExit(f"{name}: the indexed heap's merges differ from the lazy heap's")
        med = interleaved_medians({"lazy": lambda: run(_lazy_ward_merges),
                                   "indexed": lambda: run(_ward_merges)}, args.repeats)
        rows.append({"graph": name, "nodes": len(w), "edges": len(e), "median_s": med,
                     "ratio": med["lazy"] / med["indexed"]})
        print(rows[-1], flush=True)
    md = ["# Ward's merge heap (benchmarks/ward_heap.py)", "",
          f"{time.strftime('%Y-%m-%d')}, {os.cpu_count()} cores, {platform.machine()}; "
          f"median of {args.repeats}, interleaved; the same merges bit for bit.", "",
          "| graph | blocks | edges | lazy heap s | indexed heap s | lazy / indexed |",
          "|---|---|---|---|---|---|"]
    for r in rows:
        md.append(f"| {r['graph']} | {r['nodes']} | {r['edges']} | {r['median_s']['lazy']:.3f} | "
                  f"{r['median_s']['indexed']:.3f} | {r['ratio']:.2f} |")
    publish(md, args.out, {"rows": rows, "repeats": args.repeats})


if __name__ == "__main__":
    main()
