"""What the streak correction gains in 3D mode, on volumes simulated slice by slice.

    python benchmarks/streaks3d.py [--out benchmarks/results/streaks3d.md] [--seeds 0 1 2]
                                   [--slices 24] [--size 128]

Volumes: :func:`ctseg.phantoms.make_volume` with ``simulate=True`` (every slice a
polychromatic parallel-beam CT simulation with beam hardening, the dark streaks between
steel parts, Poisson noise and filtered back-projection; the part changes along z). 3D
mode with defaults runs with the streak correction (each z slice corrected against the
volume's levels, as in slices mode) and without it; Dice per true material against the
voxel truth (tetrahedra rasterised per voxel centre; each found material matched to the
true one it overlaps most), the materials found, the mean streak
weight over the slices, and the wall time.
"""
import argparse
import time

import numpy as np

from accuracy import write_results  # benchmarks/ is this script's folder

import ctseg
from ctseg.metrics import matched_dice_per_label
from ctseg.phantoms import make_volume
from ctseg.raster import tetra_label_volume


def run(seed, n_slices, size):
    ph = make_volume(n_slices, size, seed=seed, simulate=True)
    truth = ph.truth.astype(np.int64)
    k = int(truth.max()) + 1
    rows = []
    for correct in (True, False):
        t0 = time.perf_counter()
        seg = ctseg.segment_volume(ph.image, mode="3d", streak_correction=correct)
        wall = time.perf_counter() - t0
        lab = tetra_label_volume(seg.points, seg.tetrahedra, seg.material, ph.image.shape)
        # each found material counts as the true one it overlaps most: an artefact's
        # false material costs what it holds, not a whole material's Dice as when it
        # was matched by its gray (a 0.03 shift of one false material's gray flipped it)
        dice = matched_dice_per_label(lab, truth)
        weights = seg.diagnostics.get("streak_weights") or [0.0]
        rows.append({"seed": seed, "streak_correction": correct, "n_materials": int(seg.n_materials),
                     "k_true": k, "dice": [float(d) for d in dice], "min_dice": float(np.min(dice)),
                     "mean_weight": float(np.mean(weights)), "wall_s": wall})
        print(rows[-1], flush=True)
    return rows


def table(rows):
    out = ["| volume | streak correction | materials found | Dice per material | min Dice | "
           "mean streak weight | time s |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| seed {r['seed']} | {'on' if r['streak_correction'] else 'off'} | "
                   f"{r['n_materials']} of {r['k_true']} | {', '.join(f'{d:.3f}' for d in r['dice'])} | "
                   f"{r['min_dice']:.3f} | {r['mean_weight']:.3g} | {r['wall_s']:.1f} |")
    return "\n".join(out)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=None)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--slices", type=int, default=24)
    ap.add_argument("--size", type=int, default=128)
    args = ap.parse_args()
    rows = [r for s in args.seeds for r in run(s, args.slices, args.size)]
    md = (f"3D mode with and without the streak correction, make_volume({args.slices}, {args.size}, "
          f"simulate=True), {time.strftime('%Y-%m-%d')}.\n\n" + table(rows))
    print(md)
    if args.out:
        write_results(args.out, md, rows)
