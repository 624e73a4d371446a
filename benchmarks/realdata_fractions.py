"""Phase fractions of the four real scans: ctseg's defaults against a reference made by
hand.

    python benchmarks/realdata_fractions.py [--out benchmarks/results/realdata_fractions.md]
                                            [--no-3d]

The scans (``../shared/realdata``, see its PROVENANCE.md) have no labels, so the reference
is made by hand, once, from what the images show, and is written down below as numbers
(nothing of it comes from ctseg):

* The pure gray of each phase: the median of rectangles drawn by eye on one slice (``z``)
  well inside a phase (a grain interior, an air gap wide enough to show a flat black; for
  the concrete's pores, which are too small to hold a flat gray, the dark air band round
  the cylinder; for the stent's struts, 1-2 px dots with no flat gray, the brightest pixel
  of eight dots), each checked to have a small spread (the sd is printed).
* The phase boundaries at the half-way grays between adjacent phases' levels (the ISO-50
  rule a careful CT user applies by hand), per pixel.
* For concrete, a region of interest drawn by eye: the disc inside the sample's outer
  surface (centre and radius read off the mid slice; a 2 px rim left out for the
  surface's partial volume). The aggregates and the mortar differ by about 1500 of a 35000
  range, under the noise; neither the reference nor ctseg tells them apart, so concrete's
  phases are pores and solid.

The reference comes from the same hand-drawn levels on every slice of a scan (one scan,
one calibration); the faded end slices of the concrete (z < 10 and z > 90, an intensity
drift along z) are left out. ctseg runs with defaults on each slice (``ctseg mesh SLICE``:
``segment_image``, rasterised by majority area) and, unless ``--no-3d``, in 3D on the
volume (``segment_volume(mode='3d')``, rasterised per voxel); each of its materials is the
hand phase whose level is nearest its mean gray. Per reported phase (``report``: the
complement of a two-phase scan says nothing more), the fractions and the Dice of ctseg's
phase against the reference's, pixel by pixel, and the highest Dice that one ctseg
material reaches against the reference phase.

Done-when of issue 15: pores and grains found, volume fractions within 3 points of the
hand reference. About 2 min with 3D.
"""
import argparse
import os
import time

import numpy as np

from accuracy import write_results  # benchmarks/ is this script's folder

import ctseg
from ctseg.raster import label_image, tetra_label_volume

REALDATA = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "realdata")

# by hand: (y0, y1, x0, x1) rectangles inside one phase on slice z, phases by ascending gray
HAND = {
    "snow": {
        "file": "snow.npy", "slices": (20, 50, 80), "z": 50,
        "rects": {"air": [(59, 64, 2, 9), (30, 36, 0, 5)],
                  "ice": [(45, 55, 5, 15), (88, 96, 55, 65), (8, 14, 60, 70)]},
        "roi": None, "report": ("ice",),
    },
    "concrete": {
        "file": "concrete_xray.npy", "slices": (10, 30, 50, 70, 90), "z": 50,
        "rects": {"pore": [(40, 60, 1, 3)], "solid": [(20, 30, 40, 50), (55, 65, 30, 40)]},
        # centre (y, x) and radius of the sample's outer surface on z = 50, less a 2 px rim
        "roi": (49.5, 50.0, 45.0 - 2.0), "report": ("pore",),
    },
    "tooth": {  # root sections and the pulp chamber, below the enamel cap (z >= 108)
        "file": "tooth.npy", "slices": (60, 80, 100), "z": 80,
        "rects": {"pulp": [(52, 55, 31, 34)], "background": [(2, 20, 2, 30), (82, 92, 5, 30)],
                  "dentin": [(40, 50, 20, 28), (35, 45, 48, 58)]},
        "roi": None, "report": ("pulp", "dentin"),
    },
    "stent": {  # z = 250 is below the stent: no metal there
        "file": "stent.npy", "slices": (70, 128, 190, 250), "z": 128,
        "rects": {"soft tissue": [(10, 30, 10, 30)], "vertebral body": [(90, 105, 35, 60)],
                  "blood": [(46, 54, 69, 77)],
                  "metal": [(y, y + 1, x, x + 1) for y, x in ((36, 75), (40, 62), (40, 85), (43, 59),
                                                             (54, 59), (57, 62), (59, 76), (60, 70))]},
        "roi": None, "report": ("vertebral body", "blood", "metal"),
    },
}


def hand_levels(volume, rects, z):
    """Median and sd of each phase's rectangles on slice ``z``, in the phases' order."""
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


def reference_phases(image, levels):
    """The hand reference: each pixel's phase (index into ``levels``' order) between the
    ISO-50 grays of adjacent levels."""
    gray = np.array([m for m, _ in levels.values()])
    return np.digitize(image, 0.5 * (gray[1:] + gray[:-1]))


def ctseg_phases(labels, material_gray, levels):
    """ctseg's phases: each material is the hand phase of the level nearest its gray."""
    gray = np.array([m for m, _ in levels.values()])
    lut = np.argmin(np.abs(np.asarray(material_gray, float)[:, None] - gray[None, :]), axis=1)
    return lut[labels]


def _dice(a, b):
    return float(2.0 * np.sum(a & b) / max(int(a.sum() + b.sum()), 1))


def compare(ref, found, labels, roi, k):
    """Fraction of phase ``k`` in the ROI by both, the Dice of the two masks there, and
    the highest Dice of one ctseg material against the phase (a material whose mean gray
    lies nearer another phase's level, such as 1-2 voxel struts averaged with the blood
    around them, still shows how well it follows the phase)."""
    r, f, lab = ref[roi] == k, found[roi] == k, labels[roi]
    dice = [_dice(r, lab == m) for m in range(int(lab.max()) + 1)]
    return {"reference": float(r.mean()), "ctseg": float(f.mean()), "dice": _dice(r, f),
            "best_material": int(np.argmax(dice)), "best_dice": float(max(dice))}


def _rows(name, where, n_materials, wall, ref, labels, material_gray, roi, levels, report):
    order = list(levels)
    found = ctseg_phases(labels, material_gray, levels)
    return [{"scan": name, "phase": phase, "where": where, "n_materials": n_materials,
             "wall_s": wall, **compare(ref, found, labels, roi, order.index(phase))}
            for phase in report]


def run_scan(name, with_3d=True):
    spec = HAND[name]
    vol = np.load(os.path.join(REALDATA, spec["file"])).astype(np.float64)
    levels = hand_levels(vol, spec["rects"], spec["z"])
    roi = roi_mask(vol.shape[1:], spec["roi"])
    rows = []
    for z in spec["slices"]:
        img = vol[z]
        t0 = time.perf_counter()
        seg = ctseg.segment_image(img)
        wall = time.perf_counter() - t0
        lab = label_image(seg.points, seg.triangles, seg.material, img.shape)
        rows += _rows(name, f"slice z={z}", int(seg.n_materials), wall, reference_phases(img, levels),
                      lab, seg.material_gray, roi, levels, spec["report"])
    if with_3d:
        z0, z1 = min(spec["slices"]), max(spec["slices"]) + 1
        sub = vol[z0:z1]
        t0 = time.perf_counter()
        res = ctseg.segment_volume(sub, mode="3d")
        wall = time.perf_counter() - t0
        lab = tetra_label_volume(res.points, res.tetrahedra, res.material, sub.shape)
        rows += _rows(name, f"3D, z={z0}..{z1 - 1}", int(res.n_materials), wall,
                      reference_phases(sub, levels), lab, res.material_gray,
                      np.broadcast_to(roi, sub.shape), levels, spec["report"])
    return levels, rows


def table(all_levels, rows):
    lines = ["| scan | where | materials found | phase | reference % | ctseg % | "
             "difference, points | Dice of the phase | best single material: number, Dice | time s |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scan']} | {r['where']} | {r['n_materials']} | {r['phase']} | "
                     f"{100 * r['reference']:.1f} | {100 * r['ctseg']:.1f} | "
                     f"{100 * (r['ctseg'] - r['reference']):+.1f} | {r['dice']:.3f} | "
                     f"{r['best_material']}, {r['best_dice']:.3f} | {r['wall_s']:.1f} |")
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
