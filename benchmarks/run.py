"""ctseg's benchmarks in one command: speed, memory, the paper's claims, scaling.

    pip install ".[bench]"
    python benchmarks/run.py [--quick] [--only stages graphcut init scaling]

Writes ``benchmarks/results/benchmark.md`` (tables), ``benchmark.json`` (every number)
and PNG plots next to them. On simulated slices with known truth (ctseg.phantoms):

1. stages: per-stage wall time (median of 5) and end to end with the mesh written
   (.vtp, pymeshlab checks included; loading excluded) at the paper's sizes, 512 x 512 /
   1000 sites and 700 x 500 / 1200 sites, with peak memory and accuracy;
2. graphcut: the recursive graph cut on the CVT triangles vs the same cut (SPEC 6-7
   energy, same levels and rules: ctseg.recursive_cut.segment_triangles) on the 4-connected
   pixel grid, and multi-level Otsu thresholding: time (median of 5, side by side in
   this process), peak memory (each alone in a fresh process), Dice and boundary distance;
3. init: Ward vs random vs density-weighted random initial sites: final CVT energy,
   Lloyd iterations, time, accuracy;
4. scaling: image size 256^2 .. 2048^2 (default sites: one per 128 px) and sites 250 ..
   16000 (on 1024^2): time and peak memory, log-log slopes.

Times are medians of repeated runs in one process; ratios between methods are the
headline. Peak memory is the high-water mark of resident memory over the call, in a fresh
process after a warm-up (the high-water mark reset with /proc/self/clear_refs), minus the
resident memory just before the call.
"""
import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

import numpy as np

from ctseg.resources import peak_rss_mib, reset_peak_rss, rss_mib

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

# (rows, cols), sites: the paper's sizes (Table 1), and 512 x 512 with the default sites
PAPER_SIZES = [((512, 512), 1000), ((500, 700), 1200), ((512, 512), None)]
SEEDS = (0, 1, 2)
INITS = ("ward", "random", "density_random")


# ----------------------------------------------------------------------------- helpers
def median_time(fn, repeats):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def interleaved_medians(variants, repeats):
    """Median wall time of each of ``variants`` (name -> callable), the variants run in
    turn ``repeats`` times so that a machine's drift reaches them alike."""
    times = {name: [] for name in variants}
    for _ in range(repeats):
        for name, fn in variants.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    return {name: float(np.median(t)) for name, t in times.items()}


def phantom(rows, cols, seed, materials=None):
    """A simulated slice (rows x cols, cropped from a square one) with truth."""
    from ctseg.phantoms import MATERIALS, Phantom, make_phantom

    size = max(rows, cols)
    p = make_phantom(size, seed=seed, materials=materials or MATERIALS)
    r0, c0 = (size - rows) // 2, (size - cols) // 2
    s = p.supersample
    return Phantom(image=p.image[r0:r0 + rows, c0:c0 + cols],
                   truth=p.truth[r0:r0 + rows, c0:c0 + cols],
                   truth_hr=p.truth_hr[r0 * s:(r0 + rows) * s, c0 * s:(c0 + cols) * s],
                   supersample=s, names=p.names, pixel_mm=p.pixel_mm)


def big_slice(n):
    """A fast simulated n x n slice (no ray tracing) for the scaling runs."""
    from ctseg.phantoms import make_volume

    return make_volume(1, n, seed=0, supersample=1).image[0].astype(np.float64)


def segment_and_write(image, n_sites, folder, **params):
    """The job the speed goal times: segment, then write the mesh (.vtp, checked)."""
    import ctseg
    from ctseg.filters import segmentation_to_polydata, write_mesh

    seg = ctseg.segment_image(image, n_sites=n_sites, **params)
    mesh, _ = segmentation_to_polydata(seg)
    write_mesh(mesh, os.path.join(folder, "mesh.vtp"))
    return seg


def pixel_accuracy(p, labels):
    from baselines import pixel_boundary
    from ctseg.metrics import boundary_distance, dice_per_label

    n = int(max(labels.max(), p.truth.max())) + 1
    pts, edges = pixel_boundary(labels)
    return ([float(d) for d in dice_per_label(labels, p.truth, n)],
            boundary_distance(pts, edges, p.truth_hr, p.supersample)["mean"])


def mesh_accuracy(p, seg):
    from ctseg.metrics import evaluate

    ev = evaluate(seg, p.truth, p.truth_hr, p.supersample)
    return ev["dice"], ev["boundary_px"]["mean"]


# ------------------------------------------------------------- fresh-process children
def child_main(spec):
    """Run one job alone and print its wall time and peak memory (JSON)."""
    with tempfile.TemporaryDirectory() as folder:
        # load the compiled kernels and VTK first: their code is not the job's memory
        segment_and_write(big_slice(64), 40, folder)
        if spec["kind"] == "segment":
            # made elsewhere: memory freed by making it would hide the job's own peak
            image = np.load(spec["image"]) if "image" in spec else big_slice(spec["rows"])
            job = lambda: segment_and_write(image, spec["n_sites"], folder)  # noqa: E731
        else:  # a prepared graph for the recursive graph cut
            from ctseg.recursive_cut import segment_triangles

            z = dict(np.load(spec["path"]))
            job = lambda: segment_triangles(z["gray"], z["area"], z["adjacency"],  # noqa: E731
                                            z["centroids"], levels=z["levels"])
        exact = reset_peak_rss()
        base = rss_mib()
        t0 = time.perf_counter()
        job()
        wall = time.perf_counter() - t0
        peak = peak_rss_mib()
    print(json.dumps({"wall_s": wall, "peak_mib": peak - base, "peak_reset": exact}))


def in_child(spec):
    out = subprocess.run([sys.executable, __file__, "--child", json.dumps(spec)],
                         capture_output=True, text=True)
    if out.returncode:
        raise RuntimeError(f"child {spec} failed: {out.stderr.strip()[-500:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def slope(x, y):
    """Least-squares slope of log y against log x."""
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


# ------------------------------------------------------------------------ sections
def bench_stages(repeats):
    rows = []
    for (r, c), n in PAPER_SIZES:
        p = phantom(r, c, 0)
        runs = []
        with tempfile.TemporaryDirectory() as folder:
            segment_and_write(p.image, n, folder)  # warm-up
            for _ in range(repeats):
                t0 = time.perf_counter()
                seg = segment_and_write(p.image, n, folder)
                total = time.perf_counter() - t0
                runs.append((total, seg.diagnostics))
        stages = list(runs[0][1]["times_s"])
        med = {s: float(np.median([d["times_s"][s] for _, d in runs])) for s in stages}
        seg_total = float(np.median([d["total_time_s"] for _, d in runs]))
        e2e = float(np.median([t for t, _ in runs]))
        dice, bd = mesh_accuracy(p, seg)
        with tempfile.TemporaryDirectory() as folder:
            np.save(os.path.join(folder, "image.npy"), p.image)
            mem = in_child({"kind": "segment", "image": os.path.join(folder, "image.npy"),
                            "n_sites": n})
        rows.append({"size": f"{c} x {r}", "n_sites": runs[0][1]["n_sites"],
                     "default_sites": n is None, "end_to_end_s": e2e,
                     "segment_s": seg_total, "write_s": e2e - seg_total, "stages_s": med,
                     "lloyd_iterations": runs[0][1]["lloyd_iterations"],
                     "n_triangles": int(len(seg.triangles)), "peak_mib": mem["peak_mib"],
                     "dice": dice, "boundary_px": bd, "repeats": repeats})
        print(f"stages {c}x{r}/{n}: end to end {e2e:.3f} s", flush=True)
    return rows


def bench_graphcut(repeats):
    import ctseg
    from baselines import otsu_labels, pixel_graph
    from ctseg.intensity import rescale_gray
    from ctseg.recursive_cut import segment_triangles
    from ctseg.beam_hardening import correct_streaks
    from ctseg.triangulation import triangle_areas

    rows = []
    for seed in SEEDS:
        p = phantom(512, 512, seed)
        # both graphs from the same streak-corrected image (what segment_image segments)
        image = correct_streaks(p.image).image
        seg = ctseg.segment_image(image, streak_correction=False)
        g255, (off, fac) = rescale_gray(image)
        levels = np.array(seg.diagnostics["material_levels_255"])
        tri = {"gray": np.clip((seg.gray - off) * fac, 0, 255),
               "area": triangle_areas(seg.points, seg.triangles), "adjacency": seg.adjacency,
               "centroids": seg.points[seg.triangles].mean(axis=1)}
        pix = pixel_graph(g255)

        def cut(g):
            return segment_triangles(g["gray"], g["area"], g["adjacency"], g["centroids"],
                                     levels=levels).material

        cut(tri)
        t_tri, m_tri = median_time(lambda: cut(tri), repeats)
        t_pix, m_pix = median_time(lambda: cut(pix), repeats)
        k = len(levels)
        t_otsu, lab_otsu = median_time(lambda: otsu_labels(g255, k), repeats)
        mem = {}
        with tempfile.TemporaryDirectory() as folder:
            for name, g in (("triangles", tri), ("pixels", pix)):
                path = os.path.join(folder, f"{name}.npz")
                np.savez(path, levels=levels, **g)
                mem[name] = in_child({"kind": "cut", "path": path})["peak_mib"]
        d_tri, b_tri = mesh_accuracy(p, _with_material(seg, m_tri))
        d_pix, b_pix = pixel_accuracy(p, m_pix.reshape(p.truth.shape))
        d_otsu, b_otsu = pixel_accuracy(p, lab_otsu)
        rows.append({"seed": seed, "nodes": {"triangles": len(tri["gray"]), "pixels": len(pix["gray"])},
                     "time_s": {"triangles": t_tri, "pixels": t_pix, "otsu": t_otsu},
                     "peak_mib": mem,
                     "dice": {"triangles": d_tri, "pixels": d_pix, "otsu": d_otsu},
                     "boundary_px": {"triangles": b_tri, "pixels": b_pix, "otsu": b_otsu},
                     "repeats": repeats})
        print(f"graphcut seed {seed}: triangles {t_tri:.3f} s, pixels {t_pix:.3f} s "
              f"({t_pix / t_tri:.0f}x), memory {mem['pixels'] / max(mem['triangles'], 1e-3):.0f}x",
              flush=True)
    return rows


def _with_material(seg, material):
    """seg with another material array (boundary edges recomputed)."""
    import dataclasses

    from ctseg.boundary import material_boundary
    from ctseg.triangulation import edge_adjacency

    edges, _ = material_boundary(edge_adjacency(seg.triangles)[1], seg.adjacency, material)
    return dataclasses.replace(seg, material=material, boundary_edges=edges)


def bench_init(repeats):
    import ctseg

    rows = []
    for seed in SEEDS:
        p = phantom(512, 512, seed)
        for init in INITS:
            t, seg = median_time(lambda: ctseg.segment_image(p.image, n_sites=1000, seed=seed,
                                                             init=init), repeats)
            d = seg.diagnostics
            dice, bd = mesh_accuracy(p, seg)
            rows.append({"seed": seed, "init": init, "final_energy": d["cvt_energy"][-1],
                         "initial_energy": d["cvt_energy"][0],
                         "energy_history": d["cvt_energy"],
                         "lloyd_iterations": d["lloyd_iterations"],
                         "converged": d["lloyd_iterations"] < 200,
                         "initial_sites_s": d["times_s"]["initial_sites"],
                         "cvt_s": d["times_s"]["cvt"], "total_s": t, "dice": dice,
                         "boundary_px": bd, "repeats": repeats})
            print(f"init seed {seed} {init}: F {d['cvt_energy'][-1]:.4g}, "
                  f"{d['lloyd_iterations']} iterations, {t:.2f} s", flush=True)
    return rows


def bench_scaling(repeats, sizes, sites):
    import ctseg

    size_rows, site_rows = [], []
    for n in sizes:
        img = big_slice(n)
        with tempfile.TemporaryDirectory() as folder:
            t, seg = median_time(lambda: segment_and_write(img, None, folder),
                                 repeats if n <= 1024 else 1)
        mem = in_child({"kind": "segment", "rows": n, "cols": n, "n_sites": None})
        size_rows.append({"size": n, "pixels": n * n, "n_sites": seg.diagnostics["n_sites"],
                          "time_s": t, "peak_mib": mem["peak_mib"],
                          "stages_s": seg.diagnostics["times_s"],
                          "lloyd_iterations": seg.diagnostics["lloyd_iterations"]})
        print(f"scaling {n}^2: {t:.2f} s, {mem['peak_mib']:.0f} MiB", flush=True)
    img = big_slice(1024)
    for k in sites:
        t, seg = median_time(lambda: ctseg.segment_image(img, n_sites=k), repeats)
        site_rows.append({"n_sites": k, "time_s": t, "stages_s": seg.diagnostics["times_s"],
                          "lloyd_iterations": seg.diagnostics["lloyd_iterations"]})
        print(f"scaling {k} sites on 1024^2: {t:.2f} s", flush=True)
    px = [r["pixels"] for r in size_rows]
    return {"sizes": size_rows, "sites": site_rows,
            "slope_time_vs_pixels": slope(px, [r["time_s"] for r in size_rows]),
            "slope_memory_vs_pixels": slope(px, [r["peak_mib"] for r in size_rows]),
            "slope_time_vs_sites": slope([r["n_sites"] for r in site_rows],
                                         [r["time_s"] for r in site_rows])}


# ------------------------------------------------------------------------- report
def plots(res, folder):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files = []
    if "stages" in res:
        fig, ax = plt.subplots(figsize=(8, 3.2))
        names = list(dict.fromkeys(s for r in res["stages"] for s in r["stages_s"])) + ["write"]
        colours = dict(zip(names, plt.get_cmap("tab20").colors))
        for i, r in enumerate(res["stages"]):
            left = 0.0
            for s, v in list(r["stages_s"].items()) + [("write", r["write_s"])]:
                ax.barh(i, v, left=left, color=colours[s], label=s if i == 0 else None)
                left += v
        ax.axvline(1.0, color="k", ls="--", lw=1)
        ax.set_yticks(range(len(res["stages"])),
                      [f"{r['size']}\n{r['n_sites']} sites"
                       + (" (default)" if r.get("default_sites") else "") for r in res["stages"]])
        ax.set_xlabel("wall time, s (median; dashed: 1 s goal)")
        ax.set_xlim(0, max(1.1, 1.05 * max(r["end_to_end_s"] for r in res["stages"])))
        ax.legend(fontsize=7, ncol=1, loc="center left", bbox_to_anchor=(1.01, 0.5))
        ax.set_title("Stage split, end to end with the mesh written", fontsize=10)
        fig.tight_layout()
        files.append(_save(fig, folder, "bench_stages.png"))
    if "graphcut" in res:
        fig, axes = plt.subplots(1, 3, figsize=(10, 3))
        g = res["graphcut"]
        names = ["triangles", "pixels", "otsu"]
        for ax, key, label, log in ((axes[0], "time_s", "time, s", True),
                                    (axes[1], "peak_mib", "peak memory, MiB", True),
                                    (axes[2], "dice", "min Dice", False)):
            for j, name in enumerate(names):
                vals = [min(r[key][name]) if key == "dice" else r[key].get(name, np.nan)
                        for r in g]
                ax.bar(np.arange(len(g)) + 0.27 * (j - 1), vals, 0.27, label=name)
            ax.set_xticks(range(len(g)), [f"seed {r['seed']}" for r in g])
            if log:
                ax.set_yscale("log")
            else:
                ax.set_ylim(0.5, 1.0)
            ax.set_title(label, fontsize=9)
        axes[0].legend(fontsize=7)
        fig.suptitle("Graph cut on triangles vs pixels (512 x 512), and multi-Otsu", fontsize=10)
        fig.tight_layout()
        files.append(_save(fig, folder, "bench_graphcut.png"))
    if "init" in res:
        fig, ax = plt.subplots(figsize=(6, 3.5))
        for r in res["init"]:
            if r["seed"] == 0:
                ax.plot(r["energy_history"], label=r["init"])
        ax.set_yscale("log")
        ax.set_xlabel("Lloyd iteration")
        ax.set_ylabel("CVT energy F (eq. 4)")
        ax.set_title("Initial sites: energy during Lloyd (512 x 512, 1000 sites, seed 0)")
        ax.legend()
        fig.tight_layout()
        files.append(_save(fig, folder, "bench_init.png"))
    if "scaling" in res:
        s = res["scaling"]
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
        px = np.array([r["pixels"] for r in s["sizes"]])
        for key, label, k in (("time_s", "time, s", "slope_time_vs_pixels"),
                              ("peak_mib", "peak memory, MiB", "slope_memory_vs_pixels")):
            y = np.array([r[key] for r in s["sizes"]])
            axes[0].loglog(px, y, "o-", label=f"{label} (slope {s[k]:.2f})")
        axes[0].set_xlabel("pixels (default sites: one per 128 px)")
        axes[0].legend(fontsize=8)
        axes[0].set_title("Image size 256^2 .. 2048^2", fontsize=9)
        ns = np.array([r["n_sites"] for r in s["sites"]])
        axes[1].loglog(ns, [r["time_s"] for r in s["sites"]], "o-",
                       label=f"total, s (slope {s['slope_time_vs_sites']:.2f})")
        for stage, name in (("cvt", "Lloyd"), ("initial_sites", "Ward"),
                            ("triangle_gray", "triangle gray"), ("graphcut", "graph cut")):
            axes[1].loglog(ns, [r["stages_s"][stage] for r in s["sites"]], ".--", label=name)
        axes[1].set_xlabel("sites (1024 x 1024 image)")
        axes[1].legend(fontsize=8)
        axes[1].set_title("Number of sites", fontsize=9)
        fig.tight_layout()
        files.append(_save(fig, folder, "bench_scaling.png"))
    return files


def _save(fig, folder, name):
    import matplotlib.pyplot as plt

    path = os.path.join(folder, name)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def fmt_dice(d):
    return " / ".join(f"{v:.3f}" for v in d)


def markdown(res):
    out = [f"# ctseg benchmarks ({res['when']}, {res['machine']})", ""]
    if "stages" in res:
        names = list(dict.fromkeys(s for r in res["stages"] for s in r["stages_s"]))
        out += ["## Stage timings at the paper's sizes (median of "
                f"{res['stages'][0]['repeats']}; end to end = segment + write .vtp)", "",
                "| size / sites | end to end s | " + " | ".join(names)
                + " | write | Lloyd it. | triangles | peak MiB | Dice | boundary px |",
                "|---" * (len(names) + 8) + "|"]
        for r in res["stages"]:
            default = " (default)" if r.get("default_sites") else ""
            out.append(f"| {r['size']} / {r['n_sites']}{default} | **{r['end_to_end_s']:.3f}** | "
                       + " | ".join(f"{r['stages_s'][s]:.3f}" if s in r["stages_s"] else "-"
                                    for s in names)
                       + f" | {r['write_s']:.3f} | {r['lloyd_iterations']} | {r['n_triangles']} | "
                       f"{r['peak_mib']:.0f} | {fmt_dice(r['dice'])} | {r['boundary_px']:.2f} |")
        out.append("")
    if "graphcut" in res:
        out += ["## Graph cut on triangles vs on pixels, and multi-Otsu (512 x 512)", "",
                "Same recursive graph cut (SPEC 6-7 energy, same material levels and rules) on "
                "the CVT triangles and on the 4-connected pixel grid. Times: median of "
                f"{res['graphcut'][0]['repeats']}, side by side; memory: each cut alone in a "
                "fresh process.", "",
                "| seed | nodes tri / px | time tri s | time px s | px / tri time | peak tri MiB "
                "| peak px MiB | px / tri memory | Dice tri | Dice px | Dice Otsu | boundary tri / "
                "px / Otsu px | Otsu s |",
                "|---" * 13 + "|"]
        for r in res["graphcut"]:
            t, m = r["time_s"], r["peak_mib"]
            out.append(
                f"| {r['seed']} | {r['nodes']['triangles']} / {r['nodes']['pixels']} | "
                f"{t['triangles']:.4f} | {t['pixels']:.3f} | **{t['pixels'] / t['triangles']:.0f}x** | "
                f"{m['triangles']:.1f} | {m['pixels']:.0f} | "
                f"**{m['pixels'] / max(m['triangles'], 1e-3):.0f}x** | {fmt_dice(r['dice']['triangles'])} | "
                f"{fmt_dice(r['dice']['pixels'])} | {fmt_dice(r['dice']['otsu'])} | "
                f"{r['boundary_px']['triangles']:.2f} / {r['boundary_px']['pixels']:.2f} / "
                f"{r['boundary_px']['otsu']:.2f} | {t['otsu']:.4f} |")
        out.append("")
    if "init" in res:
        out += ["## Initial sites: Ward vs random vs density-weighted random "
                "(512 x 512, 1000 sites)", "",
                "| seed | init | final energy F | vs Ward | Lloyd iterations | init s | Lloyd s | "
                "total s (median) | min Dice | boundary px |", "|---" * 10 + "|"]
        ward = {r["seed"]: r["final_energy"] for r in res["init"] if r["init"] == "ward"}
        for r in res["init"]:
            it = f"{r['lloyd_iterations']}" + ("" if r["converged"] else " (cap)")
            out.append(f"| {r['seed']} | {r['init']} | {r['final_energy']:.5g} | "
                       f"{r['final_energy'] / ward[r['seed']]:.3f} | {it} | "
                       f"{r['initial_sites_s']:.3f} | {r['cvt_s']:.3f} | {r['total_s']:.3f} | "
                       f"{min(r['dice']):.3f} | {r['boundary_px']:.2f} |")
        out.append("")
    if "scaling" in res:
        s = res["scaling"]
        out += ["## Scaling", "",
                f"Time grows as pixels^{s['slope_time_vs_pixels']:.2f} and peak memory as "
                f"pixels^{s['slope_memory_vs_pixels']:.2f} (least-squares log-log slopes, "
                f"default sites); at fixed size, time grows as sites^{s['slope_time_vs_sites']:.2f}.",
                "", "| image | sites | time s | peak MiB | Lloyd it. | Ward s | Lloyd s | "
                "triangle gray s | graph cut s |", "|---" * 9 + "|"]
        for r in s["sizes"]:
            st = r["stages_s"]
            out.append(f"| {r['size']}^2 | {r['n_sites']} | {r['time_s']:.2f} | {r['peak_mib']:.0f} | "
                       f"{r['lloyd_iterations']} | {st['initial_sites']:.3f} | {st['cvt']:.3f} | "
                       f"{st['triangle_gray']:.3f} | {st['graphcut']:.3f} |")
        for r in s["sites"]:
            st = r["stages_s"]
            out.append(f"| 1024^2 | {r['n_sites']} | {r['time_s']:.2f} | | {r['lloyd_iterations']} | "
                       f"{st['initial_sites']:.3f} | {st['cvt']:.3f} | {st['triangle_gray']:.3f} | "
                       f"{st['graphcut']:.3f} |")
        out.append("")
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", nargs="*", default=["stages", "graphcut", "init", "scaling"],
                    choices=["stages", "graphcut", "init", "scaling"])
    ap.add_argument("--quick", action="store_true",
                    help="fewer repeats and smaller scaling runs (a smoke test, not for quoting)")
    ap.add_argument("--out", default=os.path.join(HERE, "results"))
    ap.add_argument("--replot", action="store_true",
                    help="only rewrite the tables and plots from the saved benchmark.json")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child_main(json.loads(args.child))
        return
    saved = os.path.join(args.out, "benchmark.json")
    res = {}
    if os.path.exists(saved) and (args.replot or len(args.only) < 4):
        with open(saved) as fh:  # keep the sections not run this time
            res = json.load(fh)
    if not args.replot:
        res.update({"when": time.strftime("%Y-%m-%d %H:%M"),
                    "machine": f"{platform.machine()}, {os.cpu_count()} cores, "
                               f"Python {platform.python_version()}"})
        run_sections(res, args)
    os.makedirs(args.out, exist_ok=True)
    with open(saved, "w") as fh:  # first: the numbers outlive a failing plot
        json.dump(res, fh, indent=1)
    files = plots(res, args.out)
    md = markdown(res)
    with open(os.path.join(args.out, "benchmark.md"), "w") as fh:
        fh.write(md + "\n")
    print(md)
    print("wrote", ", ".join([os.path.join(args.out, f) for f in ("benchmark.md", "benchmark.json")]
                             + files))


def run_sections(res, args):
    repeats = 2 if args.quick else 5
    sizes = [256, 512] if args.quick else [256, 512, 1024, 2048]
    sites = [250, 1000] if args.quick else [250, 500, 1000, 2000, 4000, 8000, 16000]
    if "stages" in args.only:
        res["stages"] = bench_stages(repeats)
    if "graphcut" in args.only:
        res["graphcut"] = bench_graphcut(repeats)
    if "init" in args.only:
        res["init"] = bench_init(max(1, repeats // 2))
    if "scaling" in args.only:
        res["scaling"] = bench_scaling(max(1, repeats // 2), sizes, sites)


if __name__ == "__main__":
    main()
