"""The paper's claim: the graph cut on triangles is much faster and lighter than on pixels.

    python benchmarks/pixel_vs_triangle.py [--size 512] [--seed 0]

The same recursive graph cut (ctseg.materials.segment_triangles: SPEC 6-7 energy, the
same material levels and rules) runs on the CVT triangles of a simulated slice and on its
4-connected pixel grid (each pixel a node of area 1). Each graph cut runs alone in a fresh
process that loads its prepared graph from disk, so the reported memory is the graph-cut
stage's own peak (peak RSS minus the RSS just before the call). Accuracy: Dice per material
and mean boundary distance against the truth. First measurements for the benchmark issue.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np


def status_mib(field):
    """VmRSS (now) or VmHWM (peak) of this process. ru_maxrss is no use here: Linux keeps it
    across exec, so a child would report the preparing parent's peak."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024
    return float("nan")


def prepare(size, seed, folder):
    import ctseg
    from ctseg.intensity import rescale_gray
    from ctseg.phantoms import make_phantom
    from ctseg.triangulation import triangle_areas

    p = make_phantom(size, seed=seed)
    seg = ctseg.segment_image(p.image)
    g255, (off, fac) = rescale_gray(p.image)
    levels = np.array(seg.diagnostics["material_levels_255"])
    f = np.clip((seg.gray - off) * fac, 0, 255)
    np.savez(os.path.join(folder, "triangles.npz"), gray=f,
             area=triangle_areas(seg.points, seg.triangles), adjacency=seg.adjacency,
             centroids=seg.points[seg.triangles].mean(axis=1), levels=levels)
    rows, cols = g255.shape
    ids = np.arange(rows * cols).reshape(rows, cols)
    adj = np.concatenate([np.column_stack([ids[:, :-1].ravel(), ids[:, 1:].ravel()]),
                          np.column_stack([ids[:-1].ravel(), ids[1:].ravel()])])
    yy, xx = np.mgrid[0:rows, 0:cols]
    np.savez(os.path.join(folder, "pixels.npz"), gray=g255.ravel(), area=np.ones(rows * cols),
             adjacency=adj, centroids=np.column_stack([xx.ravel(), yy.ravel()]).astype(float),
             levels=levels)
    return p, seg


def cut(path):
    from ctseg.materials import segment_triangles

    z = dict(np.load(path))
    base = status_mib("VmRSS")
    t0 = time.perf_counter()
    res = segment_triangles(z["gray"], z["area"], z["adjacency"], z["centroids"], levels=z["levels"])
    wall = time.perf_counter() - t0
    peak = status_mib("VmHWM")
    np.save(path.replace(".npz", "_material.npy"), res.material)
    return {"graphcut_s": wall, "stage_peak_mib": peak - base, "nodes": len(z["gray"])}


def accuracy(p, seg, material, method):
    from ctseg.metrics import boundary_distance, dice_per_label, label_image

    if method == "triangles":
        lab = label_image(seg.points, seg.triangles, material, p.truth.shape)
        from ctseg.boundary import material_boundary
        edges, _ = material_boundary(seg_shared(seg), seg.adjacency, material)
        bd = boundary_distance(seg.points, edges, p.truth_hr, p.supersample)
    else:
        lab = material.reshape(p.truth.shape)
        r, c = np.nonzero(lab[:, 1:] != lab[:, :-1])
        r2, c2 = np.nonzero(lab[1:, :] != lab[:-1, :])
        pts = np.vstack([np.column_stack([c + 0.5, r - 0.5]), np.column_stack([c + 0.5, r + 0.5]),
                         np.column_stack([c2 - 0.5, r2 + 0.5]), np.column_stack([c2 + 0.5, r2 + 0.5])])
        n1, n2 = len(r), len(r2)
        edges = np.column_stack([np.r_[np.arange(n1), 2 * n1 + np.arange(n2)],
                                 np.r_[n1 + np.arange(n1), 2 * n1 + n2 + np.arange(n2)]])
        bd = boundary_distance(pts, edges, p.truth_hr, p.supersample)
    return [float(d) for d in dice_per_label(lab, p.truth)], bd["mean"]


def seg_shared(seg):
    from ctseg.triangulation import edge_adjacency

    return edge_adjacency(seg.triangles)[1]


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cut", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.cut:
        print(json.dumps(cut(args.cut)))
        sys.exit(0)
    with tempfile.TemporaryDirectory() as folder:
        p, seg = prepare(args.size, args.seed, folder)
        results = {}
        for m in ("triangles", "pixels"):
            path = os.path.join(folder, f"{m}.npz")
            proc = subprocess.run([sys.executable, __file__, "--cut", path], capture_output=True,
                                  text=True, check=True)
            r = json.loads(proc.stdout.strip().splitlines()[-1])
            r["dice"], r["boundary_px"] = accuracy(p, seg, np.load(path.replace(".npz", "_material.npy")), m)
            results[m] = r
    for m, r in results.items():
        print(f"{m:9s} nodes {r['nodes']:7d}  graph cut {r['graphcut_s']:7.3f} s  stage peak "
              f"{r['stage_peak_mib']:7.1f} MiB  Dice {', '.join(f'{d:.3f}' for d in r['dice'])}  "
              f"boundary {r['boundary_px']:.2f} px")
    t, q = results["triangles"], results["pixels"]
    print(f"pixels / triangles: time {q['graphcut_s'] / t['graphcut_s']:.0f}x, stage memory "
          f"{q['stage_peak_mib'] / max(t['stage_peak_mib'], 1e-3):.0f}x")
