"""The 3D Lloyd's step factor: CVT energy by iteration and time to the energy stop, for
plain Lloyd (w = 1) and over-relaxed steps, side by side in this process.

    python benchmarks/lloyd3d.py [--size 96] [--repeats 3] [--omegas 1.0 1.7 1.9] [--rtol 1e-5]
                                 [--out benchmarks/results/lloyd3d.md]

The volume is :func:`ctseg.phantoms3d.make_part_3d` (seed 0); the density is the 3D
stage's on the raw volume (:func:`ctseg.stages3d.density_3d`, defaults), the sites its
Ward sites with the default count. Each step factor runs twice from the
same sites: with the energy stop off to a fixed cap (the energy after 25 / 50 / 100 / 200
iterations), and with the energy stop ``--rtol`` (iterations and wall time, median of
repeats, ratio to w = 1 timed in the same process). Both are opt-in (the defaults are
w = 1 and no energy stop; README, *Accuracy in 3D*).
"""
import argparse
import json
import os
import platform
import time

import numpy as np

from ctseg import stages3d
from ctseg.cvt3d import lloyd_cvt_3d
from ctseg.params import DEFAULTS
from ctseg.phantoms3d import make_part_3d
from ctseg.sites import initial_sites_3d

CHECKPOINTS = (25, 50, 100, 200)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=96)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--omegas", type=float, nargs="+", default=[1.0, 1.7, 1.9])
    ap.add_argument("--rtol", type=float, default=1e-5, help="energy_rtol_3d of the stopped runs")
    ap.add_argument("--out", default=None, help="markdown path; the JSON goes beside it")
    args = ap.parse_args()
    image = make_part_3d(args.size, seed=0, keep_fractions=False).image.astype(np.float64)
    rho = stages3d.density_3d(image)
    n_sites = stages3d.n_sites_3d(image)[0]
    start = initial_sites_3d(rho, n_sites, (1.0, 1.0, 1.0), seed=DEFAULTS.seed)
    lloyd_cvt_3d(rho, start, max_iter=2)  # compile outside the timings
    rows = []
    for w in args.omegas:
        capped = lloyd_cvt_3d(rho, start, max_iter=max(CHECKPOINTS), energy_rtol_3d=0.0,
                              overrelaxation_3d=w)
        rows.append({"omega": w, "energy": {c: capped.energy[c] for c in CHECKPOINTS
                                            if c < len(capped.energy)},
                     "capped_iterations": capped.n_iter, "times_s": []})
    for _ in range(args.repeats):  # the step factors interleaved: the machine's drift hits all
        for row in rows:
            t = time.perf_counter()
            r = lloyd_cvt_3d(rho, start, overrelaxation_3d=row["omega"], energy_rtol_3d=args.rtol)
            row["times_s"].append(time.perf_counter() - t)
            row["stop_iterations"], row["stop_energy"] = r.n_iter, r.energy[-1]
    base = float(np.median(rows[0]["times_s"]))
    head = ("| w | energy after " + " / ".join(map(str, CHECKPOINTS)) + " iterations (stop off)"
            " | iterations to the stop | energy there | time s (median) | ratio to w = 1 |")
    lines = ["# 3D Lloyd step factor (benchmarks/lloyd3d.py)\n",
             f"{time.strftime('%Y-%m-%d')}, {os.cpu_count()} cores, {platform.machine()}; "
             f"make_part_3d({args.size}, seed 0), {len(start)} Ward sites, the stop at "
             f"energy_rtol_3d {args.rtol:g} (cap {DEFAULTS.max_iter}); "
             f"median of {args.repeats}.\n", head, "|---|---|---|---|---|---|"]
    for row in rows:
        med = float(np.median(row["times_s"]))
        row["median_s"], row["ratio"] = med, med / base
        energies = " / ".join(f"{e:.6g}" for e in row["energy"].values())
        lines.append(f"| {row['omega']:g} | {energies} | {row['stop_iterations']} | "
                     f"{row['stop_energy']:.6g} | {med:.2f} | {med / base:.2f} |")
    md = "\n".join(lines)
    print(md)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(md + "\n")
        with open(os.path.splitext(args.out)[0] + ".json", "w") as fh:
            json.dump(rows, fh, indent=1)


if __name__ == "__main__":
    main()
