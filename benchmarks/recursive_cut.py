"""The recursive graph cut on the tetrahedron graphs of the 3D mode: each cut on the graph
of what its seed sets leave undecided (the elements tied to s0 merged into the source)
and the connected pieces by union-find (what :func:`ctseg.recursive_cut.segment_triangles`
runs), against each cut on the whole component and scipy's connected components (kept
below), side by side in this process.

    python benchmarks/recursive_cut.py [--sizes 96 160] [--repeats 5] [--out benchmarks/results/recursive_cut.md]

The inputs are those the 3D labelling passes (both of its cuts, before and after the blur
correction) on :func:`ctseg.phantoms3d.make_part_3d` (seed 0, defaults), caught by
running :func:`ctseg.segment_volume` once. Both must give the same labels bit for bit;
the times are medians of interleaved repeats. The edge distances are computed once per
call in both (the old code computed them again for every cut: not timed here).
"""
import argparse
import os
import platform
import time

import maxflow
import numpy as np
from accuracy import publish  # benchmarks/ is this script's folder
from scipy.sparse import coo_matrix
from run import interleaved_medians
from scipy.sparse.csgraph import connected_components

import ctseg
import ctseg.labelling3d as labelling3d
import ctseg.recursive_cut as recursive_cut
from ctseg.graphcut import graphcut_capacities
from ctseg.phantoms3d import make_part_3d


# the whole-component cut and scipy's components, as ctseg had them until 2026-12-07
def _whole_graph_split(gray, edges, centroids, **params):
    caps = graphcut_capacities(gray, edges, centroids, **params)
    m = len(caps.source_cap)
    g = maxflow.Graph[float](m, len(caps.edges))
    nodes = g.add_nodes(m)
    if len(caps.edges):
        g.add_edges(nodes[caps.edges[:, 0]], nodes[caps.edges[:, 1]], caps.edge_cap, caps.edge_cap)
    g.add_grid_tedges(nodes, caps.source_cap, caps.sink_cap)
    flow = g.maxflow()
    return g.get_grid_segments(nodes).astype(np.int8), float(flow)


def _scipy_pieces(pairs, n):
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)


VARIANTS = {"whole graph, scipy": (_whole_graph_split, _scipy_pieces),
            "merged seeds, union-find": (recursive_cut.graphcut_split, recursive_cut.connected_pieces)}


def _calls(size):
    """The (args, kwargs) of every segment_triangles call of the 3D labelling."""
    calls = []
    original = labelling3d.segment_triangles

    def catch(*args, **kwargs):
        calls.append((args, kwargs))
        return original(*args, **kwargs)

    labelling3d.segment_triangles = catch
    try:
        ctseg.segment_volume(make_part_3d(size, seed=0).image, mode="3d")
    finally:
        labelling3d.segment_triangles = original
    return calls


def _run(variant, args, kwargs):
    split, pieces = VARIANTS[variant]
    saved = recursive_cut.graphcut_split, recursive_cut.connected_pieces
    recursive_cut.graphcut_split, recursive_cut.connected_pieces = split, pieces
    try:
        return recursive_cut.segment_triangles(*args, **kwargs)
    finally:
        recursive_cut.graphcut_split, recursive_cut.connected_pieces = saved


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="+", default=[96, 160])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default=None, help="markdown path; the JSON goes beside it")
    args = ap.parse_args()
    rows = []
    for size in args.sizes:
        for n, (a, k) in enumerate(_calls(size)):
            ref, new = (_run(v, a, k) for v in VARIANTS)
            for field in ("material", "leaf", "mode_gray", "material_gray"):
                if not np.array_equal(getattr(ref, field), getattr(new, field)):
                    raise SystemExit(f"{size}^3 call {n}: {field} differs between the variants")
            med = interleaved_medians({v: (lambda v=v: _run(v, a, k)) for v in VARIANTS},
                                      args.repeats)
            rows.append({"volume": f"{size}^3", "call": n + 1, "tetrahedra": len(a[0]),
                         "cuts": int(new.graphcut_calls), "median_s": med,
                         "ratio": med["whole graph, scipy"] / med["merged seeds, union-find"]})
            print(rows[-1], flush=True)
    md = ["# The recursive cut of the 3D labelling (benchmarks/recursive_cut.py)", "",
          f"{time.strftime('%Y-%m-%d')}, {os.cpu_count()} cores, {platform.machine()}; "
          f"median of {args.repeats}, interleaved; the same labels bit for bit.", "",
          "| volume | labelling pass | tetrahedra | graph cuts | whole graph, scipy s | "
          "merged seeds, union-find s | ratio |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        m = r["median_s"]
        md.append(f"| {r['volume']} | {r['call']} | {r['tetrahedra']} | {r['cuts']} | "
                  f"{m['whole graph, scipy']:.3f} | {m['merged seeds, union-find']:.3f} | "
                  f"{r['ratio']:.2f} |")
    publish(md, args.out, {"rows": rows, "repeats": args.repeats})


if __name__ == "__main__":
    main()
