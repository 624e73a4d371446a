"""Accuracy of the default segmentation on the second simulator's fan-beam slices.

    python benchmarks/accuracy_fan.py [--out benchmarks/results/accuracy_fan.md] [--save DIR]

ctseg's defaults were chosen on :mod:`ctseg.phantoms` (parallel beam); these slices come
from :mod:`ctseg.phantoms_fan` (fan beam, exact line integrals, tungsten spectrum and NIST
attenuation, scatter, rings, detector crosstalk, 8-bit export) and were not looked at
while choosing them. Twelve slices: four multi-insert plates (metal discs in a row, the
dark beam-hardening and scatter bands between them), two 8-bit clipped ones, PEEK/alumina
and carbon-fibre/titanium parts, low-dose, high-scatter and 120/160 kV cases.

The table is accuracy.py's (Dice per material against the per-pixel truth, min Dice, min
Dice against the sub-pixel truth, boundary distance both ways, materials found) plus the
streak correction's outcome (kept with its weight and the share of variance it explained,
or why it was skipped), the min Dice after renaming each found material to the true one
holding most of its pixels (an extra or merged level then costs only its own area), and
the largest confusions: the share of a true material's pixels given another found
material (found materials numbered 0.. by ascending gray, with that gray).
``--save DIR`` writes each slice's image and truth as .npy (for ``ctseg mesh --figure``).
About 3-5 min.
"""
import argparse
import os
import subprocess
import time

import numpy as np

from accuracy import write_results  # benchmarks/ is this script's folder

import ctseg
from ctseg.metrics import dice_per_label, evaluate
from ctseg.phantoms_fan import make_fan_phantom
from ctseg.raster import label_image

# (name, make_fan_phantom keywords); none of these was used to choose any default
CASES = [
    ("inserts Al: steel/Cu/Ti", dict(part="inserts", size=512, seed=0)),
    ("inserts Al: steel x4", dict(part="inserts", size=512, seed=1, metals=("steel",))),
    ("inserts POM: steel/Cu", dict(part="inserts", size=512, seed=2, plate="polymer",
                                   metals=("steel", "copper"))),
    ("inserts POM: steel, 5e4 photons", dict(part="inserts", size=512, seed=11, plate="polymer",
                                             metals=("steel",), photons=5e4)),
    ("inserts Al: steel, 8-bit clipped", dict(part="inserts", size=512, seed=3, metals=("steel",),
                                              clip8=True)),
    ("composite: steel fastener, 8-bit clipped", dict(part="composite", size=512, seed=5,
                                                      fastener="steel", clip8=True)),
    ("composite: Ti fastener", dict(part="composite", size=512, seed=4)),
    ("composite: Ti, 120 kV, 256 px", dict(part="composite", size=256, seed=8, kvp=120.0)),
    ("ceramic: PEEK/alumina", dict(part="ceramic", size=512, seed=6)),
    ("ceramic: 3e4 photons, 256 px", dict(part="ceramic", size=256, seed=7, photons=3e4)),
    ("ceramic: scatter 0.03, rings 0.6 %", dict(part="ceramic", size=512, seed=10, scatter=0.03,
                                                ring=0.006)),
    ("inserts Al: Ti x4, 160 kV, 256 px", dict(part="inserts", size=256, seed=9,
                                               metals=("titanium",), kvp=160.0)),
    # made after the halo streak model was chosen on the clipped steel fastener above:
    # the same part at other sizes and another seed
    ("composite: steel, clipped, seed 12", dict(part="composite", size=512, seed=12,
                                                fastener="steel", clip8=True)),
    ("composite: steel, clipped, 1024 px", dict(part="composite", size=1024, seed=5,
                                                fastener="steel", clip8=True)),
    ("composite: steel, clipped, 256 px", dict(part="composite", size=256, seed=5,
                                               fastener="steel", clip8=True)),
]


def confusions(pred, seg, p, top=2):
    """The ``top`` largest shares of a true material's pixels given another found material
    (named by its number and its gray in the image's units)."""
    out = []
    for k, name in enumerate(p.names):
        mask = p.truth == k
        if not mask.any():
            continue
        counts = np.bincount(pred[mask], minlength=seg.n_materials)
        for j, c in enumerate(counts):
            if j != k and c:
                out.append((c / mask.sum(), f"{name}->#{j} ({seg.material_gray[j]:.3g})"))
    out.sort(reverse=True)
    return [f"{what} {share:.1%}" for share, what in out[:top]]


def matched_min_dice(pred, truth, n_true):
    """Min Dice after each found material is renamed to the true one holding most of its
    pixels: an extra or a merged level then costs only its area, not every later label."""
    pred = np.asarray(pred, np.int64)
    truth = np.asarray(truth, np.int64)
    rename = np.array([np.bincount(truth[pred == j], minlength=n_true).argmax() if np.any(pred == j) else j
                       for j in range(pred.max() + 1)])
    return float(np.nanmin(dice_per_label(rename[pred], truth, n_true)))


def run_case(name, kw):
    t0 = time.perf_counter()
    p = make_fan_phantom(**kw)
    sim = time.perf_counter() - t0
    t0 = time.perf_counter()
    seg = ctseg.segment_image(p.image)
    wall = time.perf_counter() - t0
    ev = evaluate(seg, p.truth, p.truth_hr, p.supersample)
    pred = label_image(seg.points, seg.triangles, seg.material, seg.shape).astype(np.int64)
    sc = seg.diagnostics.get("streak_correction") or {}
    if not sc:
        streak = "off"
    elif sc.get("weight", 0) > 0:
        streak = f"kept, w={sc['weight']:.3g}, explained {sc['explained']:.2f}"
    else:
        streak = f"skipped: {sc.get('skipped')}"
    ev.update(case=name, materials=list(p.names), wall_s=wall, sim_s=sim, streak=streak,
              confusions=confusions(pred, seg, p), window=p.window,
              min_dice_matched=matched_min_dice(pred, p.truth, len(p.names)),
              material_gray=[float(g) for g in seg.material_gray])
    return ev, p


def table(results):
    rows = ["| slice | materials | found | Dice per material | min Dice | min Dice, sub-pixel truth "
            "| min Dice, found matched to true | boundary px (mean; mesh->truth, truth->mesh) "
            "| streak correction | largest confusions (true->#found (its gray)) | time s |",
            "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        b = r["boundary_px"]
        rows.append(
            f"| {r['case']} | {', '.join(r['materials'])} | {r['n_materials_found']} | "
            f"{', '.join(f'{d:.3f}' for d in r['dice'])} | {r['min_dice']:.3f} | "
            f"{r['min_dice_subpixel']:.3f} | {r['min_dice_matched']:.3f} | "
            f"{b['mean']:.2f} ({b['mesh_to_truth']:.2f}, {b['truth_to_mesh']:.2f}) | {r['streak']} | "
            f"{'; '.join(r['confusions'])} | {r['wall_s']:.1f} |")
    ok = [r["min_dice"] >= 0.97 and r["boundary_px"]["mean"] <= 1.0 for r in results]
    right = [r["n_materials_found"] == len(r["materials"]) for r in results]
    rows.append("")
    rows.append(f"{sum(ok)} of {len(results)} slices reach min Dice >= 0.97 and boundary <= 1.0 px; "
                f"{sum(right)} of {len(results)} find the true number of materials; smallest min Dice "
                f"{min(r['min_dice'] for r in results):.3f}, largest boundary "
                f"{max(r['boundary_px']['mean'] for r in results):.2f} px.")
    return "\n".join(rows)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=None)
    ap.add_argument("--save", default=None, help="folder for each slice's image and truth (.npy)")
    ap.add_argument("--only", type=int, nargs="*", help="run only these case numbers (0-based)")
    args = ap.parse_args()
    picked = [CASES[i] for i in args.only] if args.only else CASES
    results = []
    for i, (name, kw) in enumerate(picked):
        ev, p = run_case(name, kw)
        results.append(ev)
        print(f"{name}: min Dice {ev['min_dice']:.3f}, found {ev['n_materials_found']}/"
              f"{len(p.names)}, {ev['streak']}, {ev['wall_s']:.1f} s", flush=True)
        if args.save:
            os.makedirs(args.save, exist_ok=True)
            np.save(os.path.join(args.save, f"fan{i:02d}_image.npy"), p.image)
            np.save(os.path.join(args.save, f"fan{i:02d}_truth.npy"), p.truth)
    md = table(results)
    try:  # which ctseg was measured: other work may sit uncommitted in the tree
        rev = subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True,
                             cwd=os.path.dirname(os.path.abspath(__file__))).stdout.strip()
    except OSError:
        rev = "unknown"
    md = (f"Default segmentation on the fan-beam simulator (ctseg.phantoms_fan), "
          f"`python benchmarks/accuracy_fan.py`, ctseg {rev or 'unknown'}, {time.strftime('%Y-%m-%d %H:%M')}.\n\n"
          + md)
    print(md)
    if args.out:
        write_results(args.out, md, results)
