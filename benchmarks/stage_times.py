"""Per-stage wall time of the default pipeline at the paper's sizes (median of repeats).

    python benchmarks/stage_times.py [--repeats 3]

Sizes: 512 x 512 with 1000 sites and 700 x 500 with 1200 sites (Yang et al. 2014, Table 1),
plus 512 x 512 with the default number of sites, on simulated slices.
"""
import argparse

import numpy as np

import ctseg
from ctseg.phantoms import make_phantom


def slice_of(rows, cols, seed=0):
    size = max(rows, cols)
    p = make_phantom(size, seed=seed)
    r0, c0 = (size - rows) // 2, (size - cols) // 2
    return p.image[r0:r0 + rows, c0:c0 + cols]


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    for (rows, cols), n in [((512, 512), 1000), ((500, 700), 1200), ((512, 512), None)]:
        img = slice_of(rows, cols)
        runs = [ctseg.segment_image(img, n_sites=n).diagnostics for _ in range(args.repeats)]
        stages = list(runs[0]["times_s"])
        med = {s: float(np.median([r["times_s"][s] for r in runs])) for s in stages}
        total = float(np.median([r["total_time_s"] for r in runs]))
        print(f"{cols} x {rows}, {runs[0]['n_sites']} sites: total {total:.2f} s (median of "
              f"{args.repeats}); " + ", ".join(f"{s} {v:.2f}" for s, v in med.items())
              + f"; Lloyd iterations {runs[0]['lloyd_iterations']}")
