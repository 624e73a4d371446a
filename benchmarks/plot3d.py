"""Plots of the 3D benchmark (issue 16's README plots), from the JSON that volume3d.py wrote.

    python benchmarks/plot3d.py [--ctseg benchmarks/results/volume3d_ctseg3d.json]
                                [--baselines benchmarks/results/volume3d_baselines.json]
                                [--size 160]

Writes benchmarks/results/volume3d_scaling.png (ctseg 3D's wall time and peak memory
against the voxel count, log-log, with the least-squares slope and the goals) and
volume3d_methods.png (every method at one size, seed 0: wall time, peak memory, min Dice,
the mean distance of the surface vertices to the nearest true interface and non-manifold
edges; the meshers' time is the voxel graph cut's plus their own). Needs the ``bench``
extra (matplotlib).
"""
import argparse
import json
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from run import slope  # noqa: E402  (the benchmarks' one log-log slope)

RESULTS = os.path.join(HERE, "results")
LABELS = {"ctseg_3d": "ctseg 3D", "ctseg_slices": "ctseg slices", "otsu": "multi-Otsu\n+ SurfaceNets",
          "graphcut": "voxel graph cut\n+ SurfaceNets", "cgal": "CGAL Mesh_3\non the cut",
          "cleaver": "Cleaver\non the cut"}


def scaling_rows(res):
    """(voxels, wall s, peak MiB) of ctseg 3D, seed 0, ascending."""
    rows = [(float(np.prod(c["shape"])), c["methods"]["ctseg_3d"]["wall_s"],
             c["methods"]["ctseg_3d"]["peak_mib"]) for c in res["cases"]
            if c["seed"] == 0 and "wall_s" in c["methods"].get("ctseg_3d", {})]
    return sorted(rows)


def method_rows(results, size):
    """{method: metrics} at ``size``, seed 0, over every results file given."""
    rows = {}
    for res in results:
        for c in res["cases"]:
            if c["size"] != size or c["seed"] != 0:
                continue
            for name, m in c["methods"].items():
                if "eval" not in m:
                    continue
                wall = m["wall_s"] + (c["methods"]["graphcut"]["wall_s"]
                                      if name in ("cgal", "cleaver") else 0.0)
                rows[name] = {"wall_s": wall, "peak_mib": m["peak_mib"],
                              "min_dice": m["eval"]["min_dice"],
                              "distance_vox": m["eval"]["interface_vox"]["any_pair_mean"],
                              "non_manifold": m["eval"]["non_manifold_edges"]}
    return rows


def plot_scaling(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    vox, wall, peak = (np.array(c) for c in zip(*rows))
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4))
    for ax, y, goal, unit in ((axes[0], wall, {160 ** 3: 15.0, 256 ** 3: 60.0}, "wall time, s"),
                              (axes[1], peak, {256 ** 3: 4096.0}, "peak memory, MiB")):
        ax.loglog(vox, y, "o-", label=f"ctseg 3D (slope {slope(vox, y):.2f})")
        ax.loglog(list(goal), list(goal.values()), "r*", ms=10, label="goal")
        for v, t in zip(vox, y):
            ax.annotate(f"{round(v ** (1 / 3))}^3: {t:.0f}", (v, t), textcoords="offset points",
                        xytext=(4, -10), fontsize=8)
        ax.set_xlabel("voxels")
        ax.set_ylabel(unit)
        ax.legend(fontsize=8)
    fig.suptitle("ctseg 3D at defaults on make_part_3d, 2 cores")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_methods(rows, size, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [n for n in LABELS if n in rows]
    panels = (("wall_s", "wall time, s", True), ("peak_mib", "peak memory, MiB", True),
              ("min_dice", "min Dice over the materials", False),
              ("distance_vox", "surface to nearest true\ninterface, mean voxel", False),
              ("non_manifold", "non-manifold edges", False))
    fig, axes = plt.subplots(1, len(panels), figsize=(15, 3.6))
    colours = ["tab:green" if n == "ctseg_3d" else "tab:grey" for n in names]
    for ax, (key, title, log) in zip(axes, panels):
        vals = [rows[n][key] for n in names]
        ax.barh(range(len(names)), vals, color=colours)
        ax.set_yticks(range(len(names)), [LABELS[n] for n in names], fontsize=7)
        ax.invert_yaxis()
        if log:
            ax.set_xscale("log")
        ax.set_title(title, fontsize=9)
        for i, v in enumerate(vals):
            ax.annotate(f"{v:.0f}" if v >= 100 else f"{v:.3g}", (v, i), fontsize=7, va="center")
    fig.suptitle(f"{size}^3 seed 0, 2 cores (meshers: their time + the voxel graph cut's)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ctseg", default=os.path.join(RESULTS, "volume3d_ctseg3d.json"))
    ap.add_argument("--baselines", default=os.path.join(RESULTS, "volume3d_baselines.json"))
    ap.add_argument("--size", type=int, default=160)
    args = ap.parse_args()
    ours = json.load(open(args.ctseg))
    rows = scaling_rows(ours)
    if len(rows) >= 2:
        plot_scaling(rows, os.path.join(RESULTS, "volume3d_scaling.png"))
        vox, wall, peak = zip(*rows)
        print(f"slope against voxels: time {slope(vox, wall):.2f}, memory {slope(vox, peak):.2f}")
    results = [ours] + ([json.load(open(args.baselines))] if os.path.exists(args.baselines) else [])
    plot_methods(method_rows(results, args.size), args.size,
                 os.path.join(RESULTS, "volume3d_methods.png"))


if __name__ == "__main__":
    main()
