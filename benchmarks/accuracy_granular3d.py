"""3D mode on packed-ball granular volumes with known truth (ctseg.phantoms_granular3d).

    python benchmarks/accuracy_granular3d.py [--out benchmarks/results/accuracy_granular3d.md]

Snow, sand and sintered powder in 3D: grains a few voxels across, air gaps of 0 to a few
voxels. Each volume is segmented with the defaults, with the size rule's sites only
(``site_rule='area'``, as before the 3D site rule) and, as a per-voxel reference, by
thresholding the image half-way between the two phases (what a voxel method gets). Dice
per phase, the grain fraction's error in points, tetrahedra and time. About 2 min.
"""
import argparse
import time

import numpy as np

from accuracy import write_results  # benchmarks/ is this script's folder

import ctseg
from ctseg.metrics import dice_per_label
from ctseg.phantoms_granular3d import make_granular_3d
from ctseg.raster import tetra_label_volume

CASES = [(48, 0), (48, 1), (64, 2), (64, 7)]  # (size, seed); none used to choose a default


def run(size, seed):
    g = make_granular_3d(size, seed=seed)
    truth = g.truth.astype(np.int64)
    rows = []
    for name, kw in (("defaults", {}), ("size rule only", {"site_rule": "area"})):
        t0 = time.perf_counter()
        seg = ctseg.segment_volume(g.image, mode="3d", **kw)
        wall = time.perf_counter() - t0
        lab = tetra_label_volume(seg.points, seg.tetrahedra, seg.material, g.image.shape)
        rows.append({"case": f"{size}^3 seed {seed}", "method": name,
                     "n_sites": int(seg.diagnostics["n_sites"]),
                     "n_tetrahedra": int(len(seg.tetrahedra)),
                     "iso50_moved": int(seg.diagnostics["relabelled_iso50"]),
                     "dice": [float(d) for d in dice_per_label(lab, truth, 2)],
                     "fraction_error_points": 100.0 * float((lab == lab.max()).mean() - truth.mean()),
                     "wall_s": wall})
    thr = (g.image >= 0.5).astype(np.int64)
    rows.append({"case": f"{size}^3 seed {seed}", "method": "voxel threshold at 0.5",
                 "n_sites": None, "n_tetrahedra": None, "iso50_moved": None,
                 "dice": [float(d) for d in dice_per_label(thr, truth, 2)],
                 "fraction_error_points": 100.0 * float(thr.mean() - truth.mean()), "wall_s": None})
    return rows


def table(rows):
    lines = ["| volume | method | sites | tetrahedra | Dice air, grain | min Dice | grain fraction "
             "error, points | time s |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        fmt = lambda v, f: "" if v is None else format(v, f)  # noqa: E731
        lines.append(f"| {r['case']} | {r['method']} | {fmt(r['n_sites'], 'd')} | "
                     f"{fmt(r['n_tetrahedra'], 'd')} | {r['dice'][0]:.3f}, {r['dice'][1]:.3f} | "
                     f"{min(r['dice']):.3f} | {r['fraction_error_points']:+.1f} | "
                     f"{fmt(r['wall_s'], '.1f')} |")
    return "\n".join(lines)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    rows = [r for case in CASES for r in run(*case)]
    md = table(rows)
    print(md)
    if args.out:
        write_results(args.out, md, rows)
