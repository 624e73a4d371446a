"""Volume fractions of the real snow and concrete scans: ctseg's defaults against a
reference made by hand.

    python benchmarks/realdata_fractions.py [--out benchmarks/results/realdata_fractions.md]
                                            [--no-3d]

The scans (``../shared/realdata``, see its PROVENANCE.md) have no labels, so the reference
is made by hand, once, from what the images show, and is written down below as numbers
(nothing of it comes from ctseg):

* The pure gray of each phase: the median of rectangles drawn by eye on the mid slice
  (z = 50) well inside a phase (a grain interior, an air gap wide enough to show a flat
  black; for the concrete's pores, which are too small to hold a flat gray, the dark air
  band round the cylinder), each checked to have a small spread (the sd is printed).
* The phase boundary at the half-way gray between two phases' levels (the ISO-50 rule a
  careful µCT user applies by hand), per pixel.
* For concrete, a region of interest drawn by eye: the disc inside the sample's outer
  surface (centre and radius read off the mid slice; a 2 px rim left out for the
  surface's partial volume). The aggregates and the mortar differ by about 1500 of a 35000
  range, under the noise; neither the reference nor ctseg tells them apart, so concrete's
  phases are pores and solid.

The reference fractions come from the same hand-drawn levels on every slice of a scan (one
scan, one calibration); the faded end slices of the concrete (z < 10 and z > 90, an
intensity drift along z) are left out. ctseg runs with defaults on each slice (``ctseg mesh
SLICE``: ``segment_image``, rasterised by majority area) and, unless ``--no-3d``, in 3D on
the volume (``segment_volume(mode='3d')``, rasterised per voxel); its pore phase is its
lowest material, its ice the highest. Besides the fractions, the Dice of ctseg's phase
against the reference's, pixel by pixel.

Done-when of issue 15: pores and grains found, volume fractions within 3 points of the
hand reference. About 1 min with 3D.
"""
import argparse
import os
import time

import numpy as np

from accuracy import write_results  # benchmarks/ is this script's folder

import ctseg
from ctseg.raster import label_image, tetra_label_volume

REALDATA = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "realdata")

# by hand, on z = 50: (y0, y1, x0, x1) rectangles inside one phase
HAND = {
    "snow": {
        "file": "snow.npy", "slices": (20, 50, 80),
        "rects": {"air": [(59, 64, 2, 9), (30, 36, 0, 5)],
                  "ice": [(45, 55, 5, 15), (88, 96, 55, 65), (8, 14, 60, 70)]},
        "roi": None, "phase": "ice",
    },
    "concrete": {
        "file": "concrete_xray.npy", "slices": (10, 30, 50, 70, 90),
        "rects": {"pore": [(40, 60, 1, 3)], "solid": [(20, 30, 40, 50), (55, 65, 30, 40)]},
        # centre (y, x) and radius of the sample's outer surface on z = 50, less a 2 px rim
        "roi": (49.5, 50.0, 45.0 - 2.0), "phase": "pore",
    },
}


def hand_levels(volume, rects, z=50):
    """Median and sd of each phase's rectangles on slice ``z``."""
    out = {}
    for phase, boxes in rects.items():
        v = np.concatenate([volume[z, y0:y1, x0:x1].ravel() for y0, y1, x0, x1 in boxes])
        out[phase] = (float(np.median(v)), float(np.std(v)))
    return out


def roi_mask(shape, roi):
    if roi is None:
        return np.ones(shape, bool)
    cy, cx, r = roi
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    return np.hypot(yy - cy, xx - cx) <= r


def reference_mask(image, levels, phase):
    """The hand reference of ``phase`` ('ice' or 'pore'): the pixels above (ice) or below
    (pore) the ISO-50 gray between the two phases' levels."""
    lo, hi = sorted(v[0] for v in levels.values())
    above = image >= 0.5 * (lo + hi)
    return above if phase == "ice" else ~above


def ctseg_mask(labels, phase):
    """ctseg's ``phase``: its highest material (ice) or its lowest (pore)."""
    return labels == (labels.max() if phase == "ice" else labels.min())


def compare(ref, found, roi):
    """Fractions of the ROI and the Dice of the two masks there."""
    r, f = ref[roi], found[roi]
    dice = 2.0 * np.sum(r & f) / max(int(r.sum() + f.sum()), 1)
    return {"reference": float(r.mean()), "ctseg": float(f.mean()), "dice": float(dice)}


def run_scan(name, with_3d=True):
    spec = HAND[name]
    vol = np.load(os.path.join(REALDATA, spec["file"])).astype(np.float64)
    levels = hand_levels(vol, spec["rects"])
    roi = roi_mask(vol.shape[1:], spec["roi"])
    phase = spec["phase"]
    rows = []
    for z in spec["slices"]:
        img = vol[z]
        t0 = time.perf_counter()
        seg = ctseg.segment_image(img)
        wall = time.perf_counter() - t0
        lab = label_image(seg.points, seg.triangles, seg.material, img.shape)
        rows.append({"scan": name, "phase": phase, "where": f"slice z={z}",
                     "n_materials": int(seg.n_materials), "wall_s": wall,
                     **compare(reference_mask(img, levels, phase), ctseg_mask(lab, phase), roi)})
    if with_3d:
        z0, z1 = min(spec["slices"]), max(spec["slices"]) + 1
        sub = vol[z0:z1]
        t0 = time.perf_counter()
        res = ctseg.segment_volume(sub, mode="3d")
        wall = time.perf_counter() - t0
        lab = tetra_label_volume(res.points, res.tetrahedra, res.material, sub.shape)
        rows.append({"scan": name, "phase": phase, "where": f"3D, z={z0}..{z1 - 1}",
                     "n_materials": int(res.n_materials), "wall_s": wall,
                     **compare(reference_mask(sub, levels, phase), ctseg_mask(lab, phase),
                               np.broadcast_to(roi, sub.shape))})
    return levels, rows


def table(all_levels, rows):
    lines = ["| scan | where | materials found | phase | reference % | ctseg % | "
             "difference, points | Dice of the phase | time s |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scan']} | {r['where']} | {r['n_materials']} | {r['phase']} | "
                     f"{100 * r['reference']:.1f} | {100 * r['ctseg']:.1f} | "
                     f"{100 * (r['ctseg'] - r['reference']):+.1f} | {r['dice']:.3f} | "
                     f"{r['wall_s']:.1f} |")
    lines.append("")
    for name, lv in all_levels.items():
        lines.append(f"Hand levels, {name}: " + ", ".join(
            f"{p} {m:.0f} (sd {s:.0f})" for p, (m, s) in lv.items()))
    worst = max(abs(r["ctseg"] - r["reference"]) for r in rows)
    lines.append("")
    lines.append(f"Largest difference: {100 * worst:.1f} points "
                 f"({sum(abs(r['ctseg'] - r['reference']) <= 0.03 for r in rows)} of "
                 f"{len(rows)} within 3 points).")
    return "\n".join(lines)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=None)
    ap.add_argument("--no-3d", action="store_true")
    args = ap.parse_args()
    if not os.path.isdir(REALDATA):
        raise SystemExit(f"no real scans at {REALDATA} (../shared/realdata)")
    all_levels, rows = {}, []
    for name in HAND:
        lv, r = run_scan(name, not args.no_3d)
        all_levels[name] = lv
        rows += r
    md = table(all_levels, rows)
    print(md)
    if args.out:
        write_results(args.out, md, rows)
