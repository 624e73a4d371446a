"""Inputs a user would bring, at defaults: does ctseg find the materials that are there?

    python benchmarks/probes.py [--out benchmarks/results/probes.md]

Small volumes unlike the simulators' (exact label-like data, dtype-limit clipping, a
reconstruction's field of view, faces parallel to the slices, a small dense insert, thin
and constant volumes), each meshed with ``ctseg.segment_volume`` at defaults (mode auto:
3D for all of them) and, where the slice-by-slice levels matter, in slices mode. For each: the
materials found against the truth's, and the Dice of each true material after matching
every found material to the true one it overlaps most (so a false extra material costs
only what it holds). Known failures stay in the table, marked. About 3 min.
"""
import argparse
import time

import numpy as np
from scipy.ndimage import gaussian_filter

from accuracy import write_results  # benchmarks/ is this script's folder

import ctseg
from ctseg.metrics import matched_dice_per_label
from ctseg.raster import tetra_label_volume

N = 48


def _grid(n=N):
    return np.indices((n, n, n))


def _ball(r, c=(N / 2, N / 2, N / 2)):
    z, y, x = _grid()
    return ((z - c[0]) ** 2 + (y - c[1]) ** 2 + (x - c[2]) ** 2) < r * r


def _tube(n=64, rod=False):
    """An aluminium tube standing upright (end faces parallel to the slices); with ``rod``
    a solid cylinder holding a steel rod of radius 4 voxels (0.6% of the voxels)."""
    z, y, x = np.indices((n, n, n))
    r2 = (y - n / 2) ** 2 + (x - n / 2 + 2) ** 2
    truth = ((r2 < 14 ** 2) & (z > 8) & (z < n - 8)).astype(int)
    if rod:
        truth[((y - n / 2) ** 2 + (x - n / 2 - 2) ** 2 < 16) & (z > 12) & (z < n - 14)] = 2
    else:
        truth[(r2 < 25) & (z > 20) & (z < n - 20)] = 0
    gray = np.array([1000.0, 9000.0, 30000.0])[truth]
    return gaussian_filter(gray, 0.8) + np.random.default_rng(1).normal(0, 400, truth.shape), truth


def cases():
    """(name, volume, truth, spacing, slices_too, known failure or '')."""
    rng = np.random.default_rng(0)
    big, small = _ball(14), _ball(6)
    yield "exact binary float", big.astype(float), big.astype(int), None, False, ""
    lab = big.astype(np.uint8) + small.astype(np.uint8)
    yield "label-like uint8 0/1/2", lab, lab.astype(int), None, False, ""
    cut = (1000 + 20000 * big + rng.normal(0, 800, big.shape)).clip(0, 65535).astype(np.uint16)
    yield "uint16, air noise cut at 0 (10%)", cut, big.astype(int), (0.5, 0.5, 1.0), False, ""
    sat = (40 + 100 * big + 200 * small + rng.normal(0, 8, big.shape)).clip(0, 255).astype(np.uint8)
    yield "uint8, inner ball saturated at 255", sat, big.astype(int) + small, None, False, ""
    hu = (-1000 + 2000 * big + rng.normal(0, 30, big.shape)).astype(np.float32)
    yield "Hounsfield-like float32", hu, big.astype(int), None, False, ""
    thin = np.full((2, 64, 64), 40.0)
    thin[:, 20:40, 20:40] += 100
    truth_thin = (thin > 90).astype(int)
    yield "2 slices thin", thin + rng.normal(0, 5, thin.shape), truth_thin, None, False, ""
    yield "constant", np.full((20, 20, 20), 7.0), np.zeros((20, 20, 20), int), None, False, ""
    img, truth = _tube()
    yield "upright tube (faces parallel to the slices)", img, truth, None, True, ""
    z, y, x = np.indices(img.shape)
    fov = (y - 31.5) ** 2 + (x - 31.5) ** 2 < 31 ** 2
    yield ("upright tube, outside the field of view 0", np.where(fov, img, 0.0).clip(0, None),
           np.where(fov, truth + 1, 0), None, False, "")
    img, truth = _tube(rod=True)
    yield "cylinder with a steel rod (0.6% of voxels)", img, truth, None, True, ""


def run(name, vol, truth, spacing, slices_too, known):
    t0 = time.perf_counter()
    seg = ctseg.segment_volume(vol, spacing=spacing)
    wall = time.perf_counter() - t0
    pred = tetra_label_volume(seg.points, seg.tetrahedra, seg.material, seg.shape, seg.spacing)
    row = {"case": name, "n_true": int(truth.max()) + 1, "n_found": int(seg.n_materials),
           "kind": type(seg).__name__, "dice": [float(d) for d in matched_dice_per_label(pred, truth)],
           "wall_s": wall, "known": known}
    if slices_too:
        row["n_found_slices"] = len(ctseg.segment_volume(vol, mode="slices", spacing=spacing).material_gray)
    return row


def table(rows):
    out = ["| input | materials true / found (slices mode) | Dice per true material, matched "
           "| time s | known failure |", "|---|---|---|---|---|"]
    for r in rows:
        found = f"{r['n_found']}" + (f" ({r['n_found_slices']})" if "n_found_slices" in r else "")
        flag = "" if r["n_found"] == r["n_true"] and r.get("n_found_slices", r["n_true"]) == r["n_true"] \
            else " **differs**"
        out.append(f"| {r['case']} | {r['n_true']} / {found}{flag} | "
                   f"{', '.join(f'{d:.3f}' for d in r['dice'])} | {r['wall_s']:.1f} | {r['known']} |")
    return "\n".join(out)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    ctseg.segment_volume(np.random.default_rng(0).normal(size=(16, 16, 16)))  # warm-up
    rows = []
    for case in cases():
        rows.append(run(*case))
        print(table(rows[-1:]).splitlines()[-1], flush=True)
    md = table(rows)
    print(md)
    if args.out:
        write_results(args.out, md, rows)
