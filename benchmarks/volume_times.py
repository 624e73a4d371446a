"""Wall time of a volume segmented slice by slice, by executor (median of repeats), with
Dice over the volume; all executors run side by side in this process.

    python benchmarks/volume_times.py [--slices 64] [--size 256] [--repeats 3] [--dask]

The volume is :func:`ctseg.phantoms.make_volume` (fast variant: partial-volume mixing,
0.7 px blur and Gaussian noise, no CT simulation), default sites (one per 128 pixels).
Writes benchmarks/results/volume.json and prints a markdown table.
"""
import argparse
import json
import os
import time

import numpy as np

from ctseg.metrics import evaluate_volume
from ctseg.phantoms import make_volume
from ctseg.volume import segment_volume

HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--slices", type=int, default=64)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--dask", action="store_true", help="also time a 2-worker Dask LocalCluster")
    args = ap.parse_args()
    p = make_volume(args.slices, args.size, seed=0)
    executors = [("serial (1 process)", dict(n_jobs=1)), ("2 local processes", dict(n_jobs=2))]
    cluster = client = None
    if args.dask:
        from distributed import Client, LocalCluster

        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
        executors.append(("Dask LocalCluster, 2 workers", dict(client=client)))
    rows, reference = [], None
    for name, kw in executors:
        walls, result = [], None
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            result = segment_volume(p.image, mode="slices", **kw)
            walls.append(time.perf_counter() - t0)
        same = reference is None or all(
            np.array_equal(a.points, b.points) and np.array_equal(a.material, b.material)
            for a, b in zip(reference.slices, result.slices))
        reference = reference or result
        acc = evaluate_volume(result, p.truth)
        rows.append({"executor": name, "median_s": float(np.median(walls)), "runs_s": walls,
                     "same_as_serial": bool(same), "dice": acc["dice"],
                     "boundary_px": acc["boundary_px"]["mean"],
                     "n_triangles": result.diagnostics["n_triangles"]})
    if client is not None:
        client.close()
        cluster.close()
    base = rows[0]["median_s"]
    print(f"{args.slices} slices of {args.size} x {args.size}, default sites, median of {args.repeats}")
    print("| executor | median s | speed-up | same output | Dice (air, polymer, Al, steel) | boundary px |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['executor']} | {r['median_s']:.1f} | {base / r['median_s']:.2f}x | "
              f"{'yes' if r['same_as_serial'] else 'NO'} | {', '.join(f'{d:.3f}' for d in r['dice'])} | "
              f"{r['boundary_px']:.2f} |")
    os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
    with open(os.path.join(HERE, "results", "volume.json"), "w") as fh:
        json.dump({"slices": args.slices, "size": args.size, "repeats": args.repeats,
                   "cpu_count": os.cpu_count(), "rows": rows}, fh, indent=2)


if __name__ == "__main__":
    main()
