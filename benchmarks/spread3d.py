"""How far one run of ctseg 3D can be trusted: the spread of its accuracy when the density
is perturbed by a relative 1e-12 (k = 0, 1, ... runs), with and without the density's
raise below the densest material (``ctseg.density_capped``).

The CVT turns a change in the 12th digit of the density into other sites, and so other
labels: a difference between two single runs smaller than this spread is not a
measurement. Accuracy as ``benchmarks/volume3d.py`` measures it (its own functions), on
``make_part_3d`` (volumes SIZE:SEED), and as ``benchmarks/streaks3d.py`` does (Dice only,
each found material matched to the true one it overlaps most, streak correction on) on its
streaked volumes (streaks:SEED, ``make_volume(24, 128, simulate=True)``).

Usage: python benchmarks/spread3d.py [--volumes 96:0 96:1 160:0 streaks:0] [--runs 4] [--raised-only]
[--set NAME=VALUE ...] [--out PREFIX]; ``--set`` applies parameters (as ``ctseg mesh --set``)
to every run, so that two invocations compare a parameter over the spread.
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import volume3d  # noqa: E402  (its post-processing and evaluation)

import ctseg  # noqa: E402
import ctseg.pipeline3d as pipeline3d  # noqa: E402
from ctseg.metrics import matched_dice_per_label  # noqa: E402
from ctseg.params import SPECS  # noqa: E402
from ctseg.phantoms import make_volume  # noqa: E402
from ctseg.phantoms3d import make_part_3d  # noqa: E402
from ctseg.raster import tetra_label_volume  # noqa: E402

PERTURBATION = 1e-12


def run(size, seed, runs, overrides=None, variants=(False, True)):
    """Rows of the runs on ``make_part_3d(size, seed)`` (``size`` 'streaks': the streaked
    volume of ``benchmarks/streaks3d.py``), and the material names."""
    streaked = size == "streaks"
    ph = make_volume(24, 128, seed=seed, simulate=True) if streaked else make_part_3d(size, seed=seed)
    aux = None if streaked else volume3d.aux_maps(ph)
    density_3d = pipeline3d.density_3d
    rows = []
    try:
        for capped in variants:
            for k in range(runs):
                def perturbed(image, p, sp, cap=None, k=k, capped=capped):
                    return density_3d(image, p, sp, cap if capped else None) * (1 + PERTURBATION * k)
                pipeline3d.density_3d = perturbed
                if streaked:
                    seg = ctseg.segment_volume(ph.image, mode="3d", **(overrides or {}))
                    lab = tetra_label_volume(seg.points, seg.tetrahedra, seg.material, ph.image.shape)
                    dice = matched_dice_per_label(lab, ph.truth.astype(np.int64))
                    rows.append({"size": size, "seed": seed, "capped": capped, "k": k,
                                 "dice": [float(d) for d in dice]})
                    print(rows[-1], flush=True)
                    continue
                seg = ctseg.segment_volume(ph.image, mode="3d", spacing=ph.spacing, **(overrides or {}))
                labels, gray, extra, arrays = volume3d.post("ctseg_3d", seg, ph.image, ph.spacing)
                arrays["labels"] = labels
                ev = volume3d.evaluate(ph, dict(class_gray=gray, **extra), arrays, aux)
                right = int(np.trace(np.asarray(ev["confusion"])))
                rows.append({"size": size, "seed": seed, "capped": capped, "k": k, "dice": ev["dice"],
                             "voxels_wrong": int(ph.truth.size - right),
                             "interface_mean": ev["interface_vox"]["mean"],
                             "interface_p95": ev["interface_vox"]["p95"]})
                print(rows[-1], flush=True)
    finally:
        pipeline3d.density_3d = density_3d
    return rows, list(ph.names)


def parse_overrides(items):
    """NAME=VALUE strings -> parameters, each value parsed by its spec."""
    out = {}
    for item in items:
        name, _, text = item.partition("=")
        out[name] = SPECS[name].parse(text)
    return out


def summary(rows, names):
    out = []
    groups = list(dict.fromkeys((r["size"], r["seed"], r["capped"]) for r in rows))  # run order
    for size, seed, capped in groups:
        g = [r for r in rows if (r["size"], r["seed"], r["capped"]) == (size, seed, capped)]
        dice = np.array([r["dice"] for r in g])
        cols = [f"{m:.3f} ± {s:.3f}" for m, s in zip(dice.mean(0), dice.std(0))]

        def spread(key, digits):
            if "voxels_wrong" not in g[0]:
                return "-"
            v = np.array([r[key] for r in g])
            return f"{v.mean():.{digits}f} ± {v.std():.{digits}f}"

        volume = f"streaked, seed {seed}" if size == "streaks" else f"{size}^3 seed {seed}"
        out.append(f"| {volume} | {'yes' if capped else 'no'} | {len(g)} | {' | '.join(cols)} | "
                   f"{dice.min(1).min():.3f} | {spread('voxels_wrong', 0)} | "
                   f"{spread('interface_mean', 2)} | {spread('interface_p95', 2)} |")
    head = (f"| volume | raised density | runs | {' | '.join(f'Dice {n}' for n in names)} | lowest min Dice | "
            "voxels wrong | interface mean vox | interface p95 vox |\n|" + "---|" * (7 + len(names)))
    return head + "\n" + "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--volumes", nargs="+", default=["96:0", "96:1", "160:0"],
                    help="SIZE:SEED (make_part_3d) or streaks:SEED each")
    ap.add_argument("--runs", type=int, default=4)
    ap.add_argument("--raised-only", action="store_true", help="skip the runs without the raise")
    ap.add_argument("--set", nargs="+", default=[], metavar="NAME=VALUE")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    overrides = parse_overrides(args.set)
    rows = []
    for volume in args.volumes:
        size, seed = volume.split(":")
        size, seed = (size if size == "streaks" else int(size)), int(seed)
        got, names = run(size, seed, args.runs, overrides, (True,) if args.raised_only else (False, True))
        rows += got
    md = (f"# ctseg 3D's spread over density perturbations (benchmarks/spread3d.py)\n\n"
          f"Each volume {args.runs} runs, the density times (1 + {PERTURBATION:g} k), k = 0..{args.runs - 1}; "
          "mean ± sd over the runs; 'raised density' = ctseg.density_capped in use (the default)"
          + (f"; parameters {overrides}" if overrides else "") + ".\n\n"
          + summary(rows, names) + "\n")
    print(md)
    if args.out:
        with open(args.out + ".md", "w") as f:
            f.write(md)
        with open(args.out + ".json", "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
