"""The blur correction's floor on the self weight (``blur_min_self_weight``) against the
accuracy of slices from two simulators and the real scans' slices.

    python benchmarks/blur_floor.py [--out benchmarks/results/blur_floor.md]
                                    [--floors 0.6 0.7 0.8] [--families granular fan real]

The correction divides a triangle's deviation from the blur its labelling predicts by
its self weight, at most ``1 / blur_min_self_weight`` times. A lower floor sharpens small
triangles more: better where the image is the labels seen through a Gaussian (the
granular slices of :mod:`ctseg.phantoms_granular`), worse where it is not (the fan-beam
slices of :mod:`ctseg.phantoms_fan`: metal halos, scatter, a non-Gaussian point spread).
Each slice is made once and segmented with every floor, defaults otherwise; min Dice and
mean boundary distance against the truth (accuracy.py's measures), and for the real
scans (``../shared/realdata``, the slices and hand references of realdata_fractions.py)
the Dice of each reported phase against the hand reference. Also printed: the fit's
RMS residual in the edge band over the pixel noise, at the default floor (how well the
Gaussian model explains the edges).
"""
import argparse
import os
import time

import numpy as np
from scipy import ndimage

from accuracy import GRANULAR, write_results  # benchmarks/ is this script's folder
from accuracy_fan import CASES as FAN

import ctseg
import ctseg.blur
from ctseg.metrics import evaluate
from ctseg.phantoms_fan import make_fan_phantom
from ctseg.phantoms_granular import make_granular


def _residual_recorder():
    """Wrap estimate_blur to keep the RMS residual of its fit in the edge band."""
    seen = {}
    fit = ctseg.blur.estimate_blur

    def recording(image, levels_image, band_px=3, **kw):
        sigma = fit(image, levels_image, band_px=band_px, **kw)
        lev = np.asarray(levels_image, float)
        change = (ndimage.maximum_filter(lev, 3, mode="nearest")
                  - ndimage.minimum_filter(lev, 3, mode="nearest")) > 0
        band = ndimage.binary_dilation(change, iterations=band_px)
        model = ndimage.gaussian_filter(lev, sigma, mode="nearest") if sigma > 0 else lev
        seen["rms"] = float(np.sqrt(np.mean((np.asarray(image, float)[band] - model[band]) ** 2)))
        return sigma
    ctseg.blur.estimate_blur = recording
    return seen


def phantom_cases(families):
    if "granular" in families:
        for kind, size, seed, opt in GRANULAR:
            shape = "x".join(map(str, np.broadcast_to(size, 2)))
            yield (f"granular {kind} {shape} seed {seed}" + (" 8-bit" if opt.get("clip8") else ""),
                   lambda kind=kind, size=size, seed=seed, opt=opt: make_granular(kind, size, seed=seed, **opt))
    if "fan" in families:
        for name, kw in FAN:
            yield f"fan {name}", lambda kw=kw: make_fan_phantom(**kw)


def run_phantoms(families, floors, residual):
    rows = []
    for name, make in phantom_cases(families):
        p = make()
        row = {"case": name, "min_dice": {}, "boundary_px": {}}
        for floor in floors:
            seg = ctseg.segment_image(p.image, blur_min_self_weight=floor)
            ev = evaluate(seg, p.truth, p.truth_hr, p.supersample)
            row["min_dice"][floor] = ev["min_dice"]
            row["boundary_px"][floor] = ev["boundary_px"]["mean"]
            if floor == floors[-1]:
                row["residual_over_noise"] = residual["rms"] / max(seg.diagnostics["pixel_noise_255"], 1e-12)
        rows.append(row)
        print(row, flush=True)
    return rows


def run_real(floors):
    import realdata_fractions as R
    if not os.path.isdir(R.REALDATA):
        print(f"no real scans at {R.REALDATA}: skipped")
        return []
    rows = []
    segment = ctseg.segment_image
    for floor in floors:
        R.ctseg.segment_image = lambda img, floor=floor: segment(img, blur_min_self_weight=floor)
        try:
            for name in R.HAND:
                for r in R.run_scan(name, False)[1]:
                    rows.append({"floor": floor, **r})
        finally:
            R.ctseg.segment_image = segment
    return rows


def table(rows, real, floors):
    cols = " | ".join(f"{f}" for f in floors)
    out = [f"| slice | min Dice at floor {cols} | boundary px at floor {cols} | fit residual / noise |",
           "|---|" + "---|" * (2 * len(floors) + 1)]
    for r in rows:
        out.append(f"| {r['case']} | " + " | ".join(f"{r['min_dice'][f]:.3f}" for f in floors) + " | "
                   + " | ".join(f"{r['boundary_px'][f]:.2f}" for f in floors)
                   + f" | {r.get('residual_over_noise', float('nan')):.2f} |")
    if real:
        out += ["", f"| real scan slice | phase | Dice against the hand reference at floor {cols} |",
                "|---|---|" + "---|" * len(floors)]
        keys = sorted({(r["scan"], r["where"], r["phase"]) for r in real}, key=str)
        for key in keys:
            d = {r["floor"]: r["dice"] for r in real if (r["scan"], r["where"], r["phase"]) == key}
            out.append(f"| {key[0]} {key[1]} | {key[2]} | " + " | ".join(f"{d[f]:.3f}" for f in floors) + " |")
    return "\n".join(out)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=None)
    ap.add_argument("--floors", type=float, nargs="+", default=[0.6, 0.7, 0.8])
    ap.add_argument("--families", nargs="+", default=["granular", "fan", "real"],
                    choices=["granular", "fan", "real"])
    args = ap.parse_args()
    floors = sorted(args.floors)
    residual = _residual_recorder()
    rows = run_phantoms(args.families, floors, residual)
    real = run_real(floors) if "real" in args.families else []
    md = (f"2D slices with the blur correction's floor `blur_min_self_weight` at {floors} "
          f"(default {ctseg.params.DEFAULTS.blur_min_self_weight}), defaults otherwise, "
          f"{time.strftime('%Y-%m-%d')}.\n\n" + table(rows, real, floors))
    print(md)
    if args.out:
        write_results(args.out, md, {"phantoms": rows, "real": real})
