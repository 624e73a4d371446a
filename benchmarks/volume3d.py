"""The 3D mode against slice-by-slice ctseg and two voxel baselines, on true 3D phantoms.

    python benchmarks/volume3d.py [--sizes 64 96 160] [--repeats 1] [--seeds 0] [--seeds96 0 1]
                                  [--methods ctseg_3d ctseg_slices otsu graphcut cgal cleaver]
                                  [--cleaver-python PATH]

Phantoms: :func:`ctseg.phantoms3d.make_part_3d` (a tilted aluminium housing with a polymer
bushing and layer 4 noise sd above air, a steel shaft and ball, a 2.5-voxel fin, gas pores;
partial volume at 2x2x2 supersampling, 0.9-voxel blur, Gaussian noise). Methods, each run
alone in a fresh process (after a warm-up on a small phantom) so that its peak resident
memory is its own:

- ``ctseg_3d``: ``ctseg.segment_volume(img, mode="3d")``, defaults;
- ``ctseg_slices``: ``ctseg.segment_volume(img, mode="slices")``, defaults (one worker
  process per core);
- ``otsu``: multi-level Otsu on the voxels (benchmarks/baselines.py), given the true
  number of materials;
- ``graphcut``: the same recursive graph cut as ctseg (SPEC 6-7 energy, the volume's
  material levels and the same rules, :func:`ctseg.recursive_cut.segment_triangles`) on the
  6-connected voxel grid (PyMaxflow, Boykov-Kolmogorov).

- ``cgal``, ``cleaver``: CGAL Mesh_3 (pygalmesh) and Cleaver (itk-cleaver, in its own
  environment, ``--cleaver-python``) on the voxel graph cut's label map, the best of the
  two baselines (benchmarks/tet_baselines.py says how to install them; not ctseg
  dependencies). Their time is the meshing alone, after the label map.

The two voxel baselines are followed, within their timed job, by vtkSurfaceNets3D on their label
map (benchmarks/surface_nets.py: every material's closed surface, the box padded with a
background voxel), whose surfaces are measured as ctseg's: non-manifold edges, distance of
their vertices to the true interfaces.

Measured: Dice per material against the voxel truth (ctseg 3D's tetrahedra rasterised with
:func:`ctseg.tetra_gray.voxel_overlaps`: each voxel takes the material with the largest
overlap), where the errors lie (within a voxel of a true boundary or not; false positives
away from the material), the recall of each feature (fin, pores, air gap...), and for
ctseg 3D the distance from the interface vertices to the true interfaces
(:func:`ctseg.phantoms3d.interface_distance`), tetrahedra per voxel, element quality,
non-manifold edges of each closed surface (:func:`ctseg.meshcheck.mesh_check_report`), the
per-stage times; wall time (median of ``--repeats``) and peak memory of every method.
Writes benchmarks/results/volume3d.json and volume3d.md after every case.
"""
import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np
from scipy import ndimage

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from ctseg.resources import peak_rss_mib, reset_peak_rss, rss_mib  # noqa: E402

METHODS = ("ctseg_3d", "ctseg_slices", "otsu", "graphcut", "cgal", "cleaver")
GOALS = {"min_dice": 0.95, "interface_mean_vox": 0.5, "interface_p95_vox": 1.5,
         "tets_per_voxel": 1 / 20, "min_dihedral_deg": 5.0, "p1_dihedral_deg": 13.0,
         "non_manifold_edges": 0, "wall_s_at_160": 15.0, "wall_s_at_256": 60.0}
EDGE_VOX = 1.8  # an error this close to a true boundary is a partial-volume (edge) error


# ------------------------------------------------------------------ the jobs (in a child)
def run_ctseg_3d(img, sp, spec):
    import ctseg
    return ctseg.segment_volume(img, mode="3d", spacing=sp)


def run_ctseg_slices(img, sp, spec):
    import ctseg
    return ctseg.segment_volume(img, mode="slices", spacing=sp)


def run_otsu(img, sp, spec):
    from baselines import otsu_labels
    from surface_nets import surface_nets

    labels = otsu_labels(img, spec["k_true"])
    return labels, surface_nets(labels, sp)


def run_graphcut(img, sp, spec):
    from ctseg.labelling import CUT_KEYS
    from ctseg.levels import volume_levels
    from ctseg.params import resolve
    from ctseg.recursive_cut import segment_triangles

    p = resolve(None)
    image = img.astype(np.float64)
    (offset, factor), levels, _, _ = volume_levels(image, p, 0)
    g255 = np.clip((image - offset) * factor, 0.0, 255.0).ravel()
    nz, ny, nx = img.shape
    ids = np.arange(img.size).reshape(img.shape)
    adj = np.concatenate([np.column_stack([ids[:, :, :-1].ravel(), ids[:, :, 1:].ravel()]),
                          np.column_stack([ids[:, :-1].ravel(), ids[:, 1:].ravel()]),
                          np.column_stack([ids[:-1].ravel(), ids[1:].ravel()])])
    k, j, i = np.indices(img.shape).reshape(3, -1)
    cent = np.column_stack([i, j, k]) * np.asarray(sp, float)
    del ids, k, j, i
    seg = segment_triangles(g255, np.ones(img.size), adj, cent, levels=levels,
                            **{key: getattr(p, key) for key in CUT_KEYS})
    labels = np.searchsorted(levels, seg.mode_gray)[seg.material].reshape(img.shape)
    from surface_nets import surface_nets

    return labels, surface_nets(labels, sp)


def run_cgal(img, sp, spec):
    from tet_baselines import cgal_mesh
    with np.load(spec["labels"]) as z:
        return cgal_mesh(z["labels"], sp)


def run_cleaver(img, sp, spec):
    from tet_baselines import cleaver_mesh
    with np.load(spec["labels"]) as z:
        return cleaver_mesh(z["labels"], sp, spec["cleaver_python"])


def rasterise(seg):
    """Per voxel, the material of ctseg 3D's tetrahedra covering most of it (as the
    baselines' tetrahedra: benchmarks/tet_baselines.py; ctseg's reach every voxel)."""
    from tet_baselines import label_voxels

    return label_voxels(seg.points, seg.tetrahedra, seg.material, seg.shape, seg.spacing, outside=-1)


def class_gray(img, labels):
    n = int(labels.max()) + 1
    return [float(np.median(img[labels == c])) if np.any(labels == c) else float("nan")
            for c in range(n)]


def post(method, out, img, sp):
    """Labels, class grays and the method's own numbers, after the timing."""
    extra, arrays = {}, {}
    if method in ("cgal", "cleaver"):  # tetrahedra on the voxel graph cut's labels
        from ctseg.tetrahedra import tetra_quality
        from tet_baselines import label_voxels, tet_surface_report

        pts, tets, lab = out[:3]
        # voxels no tetrahedron reaches: a class of their own, counted as the darkest material
        labels = label_voxels(pts, tets, lab, img.shape, sp, outside=int(lab.max()) + 1)
        gray = class_gray(img, labels)
        if np.any(labels > lab.max()):
            gray[-1] = float("nan")
        extra["voxels_outside_mesh"] = int(np.sum(labels > lab.max()))
        report, pairs = tet_surface_report(tets, lab)
        extra.update({"n_tetrahedra": int(len(tets)), "element_quality": tetra_quality(pts, tets),
                      "surface_checks": list(report.values())})
        if method == "cleaver":  # its own process: the meshing call's time and memory
            extra.update(mesh_wall_s=out[3], mesh_peak_mib=out[4])
        arrays = {f"iface_{a}_{b}": pts[v] for (a, b), v in pairs.items()}
    elif method == "ctseg_3d":
        from ctseg.meshcheck import mesh_check_report

        labels, gray = rasterise(out), [float(g) for g in out.material_gray]
        d = out.diagnostics
        checks = [mesh_check_report(s.points, s.triangles) for s in out.surfaces]
        extra = {k: d[k] for k in ("n_sites", "n_vertices", "n_tetrahedra", "n_materials",
                                   "material_levels_255", "material_noise_255", "times_s",
                                   "peak_memory_mib", "lloyd_iterations", "lloyd_converged",
                                   "relabelled_for_manifold", "element_quality", "blur_px",
                                   "n_interface_triangles")}
        extra["surface_checks"] = [{k: c[k] for k in ("faces", "non_manifold_edges",
                                                       "non_manifold_vertices", "ok")} for c in checks]
        pairs = np.unique(out.interface_materials, axis=0)
        for a, b in pairs:
            rows = np.all(out.interface_materials == (a, b), axis=1)
            arrays[f"iface_{a}_{b}"] = out.points[np.unique(out.interfaces[rows])]
    elif method == "ctseg_slices":
        from ctseg.raster import volume_labels

        labels, gray = volume_labels(out, img.shape), [float(g) for g in out.material_gray]
        d = out.diagnostics
        extra = {"n_triangles": d["n_triangles"], "n_materials": d["n_materials"],
                 "executor": d["executor"], "slice_times_s": d["slice_times_s"],
                 "material_levels_255": d["material_levels_255"]}
    else:  # a label map and its vtkSurfaceNets3D surfaces
        from surface_nets import PAD, closed_surface_report

        labels, (pts, tri, pair) = out
        labels = np.asarray(labels)
        gray = class_gray(img, labels)
        extra = {"n_surface_triangles": int(len(tri)),
                 "surface_checks": list(closed_surface_report(tri, pair).values())}
        for a, b in np.unique(pair[np.all(pair != PAD, axis=1)], axis=0):
            rows = np.all(pair == (a, b), axis=1)
            arrays[f"iface_{a}_{b}"] = pts[np.unique(tri[rows])]
    return labels.astype(np.uint8), gray, extra, arrays


def child_main(spec):
    from ctseg.phantoms3d import make_part_3d

    job = globals()["run_" + spec["method"]]
    sp = tuple(spec["spacing"])
    if "labels" not in spec:  # the meshers of a label map have no kernels to compile
        job(make_part_3d(24, seed=1, porosity=False).image, sp, spec)  # warm-up: imports, kernels
    img = np.load(spec["image"])
    exact = reset_peak_rss()
    before = rss_mib()
    walls = []
    for _ in range(spec["repeats"]):
        t0 = time.perf_counter()
        out = job(img, sp, spec)
        walls.append(time.perf_counter() - t0)
    peak = peak_rss_mib()
    workers = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    labels, gray, extra, arrays = post(spec["method"], out, img, sp)
    if "mesh_wall_s" in extra:  # Cleaver ran in a process of its own: its numbers
        walls, peak = [extra["mesh_wall_s"]], extra["mesh_peak_mib"]
    np.savez(spec["out"], labels=labels, **arrays)
    print(json.dumps({"wall_s": float(np.median(walls)), "walls_s": walls, "peak_mib": peak,
                      "before_mib": before, "peak_reset": exact, "worker_peak_mib": workers,
                      "class_gray": gray, **extra}))


def in_child(spec):
    out = subprocess.run([sys.executable, __file__, "--child", json.dumps(spec)],
                         capture_output=True, text=True)
    if out.returncode:
        return {"error": out.stderr.strip()[-800:]}
    # the last JSON line (CGAL's C++ stdout may flush its progress after it, at exit)
    return json.loads([line for line in out.stdout.splitlines() if line.startswith("{")][-1])


# ------------------------------------------------------------------------ evaluation
def shape_masks(ph):
    """Voxels deep (> 1/2 voxel) inside each named feature and of its material."""
    from ctseg.phantoms3d import _sdf

    sc = ph.scene
    k, j, i = np.indices(ph.truth.shape).reshape(3, -1)
    local = (np.column_stack([i, j, k]) * ph.spacing - sc.centre) @ sc.rotation
    truth = ph.truth.ravel()
    masks = {}
    for name, (label, kind, prm) in zip(ph.features["shapes"], sc.shapes):
        if name == "housing":
            continue
        name = {"bore": "air gap", "pore": "pores"}.get(name, name)
        m = (_sdf(kind, prm, local) < -0.5 * ph.voxel) & (truth == label)
        masks[name] = ((masks[name][0] | m) if name in masks else m, int(label))
    return masks


def evaluate(ph, res, arrays, aux):
    from ctseg.metrics import dice_per_label
    from ctseg.phantoms3d import interface_distance, interface_points

    K = len(ph.names)
    gray = np.array([g if np.isfinite(g) else -1e30 for g in res["class_gray"]])
    lut = np.argmin(np.abs(gray[:, None] - ph.gray[None, :]), axis=1)
    pred = lut[arrays["labels"].astype(np.int64)]
    truth = ph.truth.astype(np.int64)
    ev = {"class_to_material": [ph.names[m] for m in lut],
          "dice": [float(d) for d in dice_per_label(pred, truth, K)]}
    ev["min_dice"] = float(np.nanmin(ev["dice"]))
    ev["confusion"] = np.bincount(truth.ravel() * K + pred.ravel(), minlength=K * K).reshape(K, K).tolist()
    wrong = pred != truth
    ev["errors"] = {}
    for m in range(K):
        miss = wrong & (truth == m)
        false = wrong & (pred == m)
        ev["errors"][ph.names[m]] = {
            "missed": int(miss.sum()), "missed_at_edge": int((miss & (aux["to_boundary"] <= EDGE_VOX)).sum()),
            "false": int(false.sum()), "false_far": int((false & (aux["to_material"][m] > 2.0)).sum())}
    ev["feature_recall"] = {n: float(np.mean(pred.ravel()[mask] == lab)) if mask.any() else None
                            for n, (mask, lab) in aux["features"].items()}
    if res.get("n_tetrahedra") or res.get("n_surface_triangles"):
        if res.get("n_tetrahedra"):
            ev["tets_per_voxel"] = res["n_tetrahedra"] / ph.truth.size
        ev["non_manifold_edges"] = int(sum(c["non_manifold_edges"] for c in res["surface_checks"]))
        present = [(a, b) for a in range(K) for b in range(a + 1, K) if len(interface_points(ph, a, b))]
        groups = {}  # true pair name -> (own, any) distances; two classes may map to one material
        for key in arrays:
            if not key.startswith("iface_"):
                continue
            a, b = (int(v) for v in key.split("_")[1:])
            A, B = sorted((int(lut[a]), int(lut[b])))
            pts = arrays[key]
            if A == B:
                continue
            # to the nearest true interface of any pair: where the surface lies, whatever its labels
            d_any = np.min([interface_distance(ph, pts, *p) for p in present], axis=0)
            # to the true interface of the same pair (that of any pair where the truth has none)
            d = interface_distance(ph, pts, A, B) if (A, B) in present else d_any
            name = f"{ph.names[A]}|{ph.names[B]}" + ("" if (A, B) in present else " (not in truth)")
            g = groups.setdefault(name, ([], []))
            g[0].append(d)
            g[1].append(d_any)

        def stats(d, d_any):
            return {"vertices": int(len(d)), "mean": float(d.mean()), "median": float(np.median(d)),
                    "p95": float(np.percentile(d, 95)), "max": float(d.max()),
                    "within_1": float(np.mean(d <= 1.0)), "any_pair_mean": float(d_any.mean()),
                    "any_pair_p95": float(np.percentile(d_any, 95))}

        if groups:  # none where a single material was found
            per_pair = {n: stats(np.concatenate(o), np.concatenate(x)) for n, (o, x) in groups.items()}
            ev["interface_vox"] = dict(stats(np.concatenate([np.concatenate(o) for o, _ in groups.values()]),
                                             np.concatenate([np.concatenate(x) for _, x in groups.values()])),
                                       per_pair=per_pair)
    return ev


def aux_maps(ph):
    K = len(ph.names)
    to_boundary = np.zeros(ph.truth.shape)
    to_material = []
    for m in range(K):
        inside = ph.truth == m
        to_boundary[inside] = ndimage.distance_transform_edt(inside)[inside]
        to_material.append(ndimage.distance_transform_edt(~inside) if inside.any()
                           else np.full(ph.truth.shape, np.inf))
    return {"to_boundary": to_boundary, "to_material": to_material, "features": shape_masks(ph)}


# -------------------------------------------------------------------------- reporting
def fmt(v, d=3):
    return "-" if v is None else f"{v:.{d}f}"


def markdown(res):
    from ctseg.phantoms3d import GRAY

    g = res["goals"]
    out = ["# 3D mode on true 3D phantoms (benchmarks/volume3d.py)", "",
           f"{res['when']}, {res['cpu_count']} cores, {res['platform']}; wall time median of "
           f"{res['repeats']}; peak = the process's peak resident memory during the job "
           "(input included; + the largest worker for slices mode). Phantoms: make_part_3d, "
           f"polymer {GRAY['polymer'] / res['cases'][0]['noise_sd']:.1f} noise sd above air, steel "
           f"{GRAY['steel'] / GRAY['polymer']:.0f}x the polymer's contrast, 0.9-voxel blur, 2x2x2 "
           "partial volume." if res["cases"] else "", "",
           f"Goals (our issue): min Dice >= {g['min_dice']}, interface distance mean <= "
           f"{g['interface_mean_vox']} voxel and p95 <= {g['interface_p95_vox']}, <= 1 tetrahedron "
           f"per 20 voxels, min dihedral >= {g['min_dihedral_deg']:g} deg and 1st percentile >= "
           f"{g['p1_dihedral_deg']:g} deg, {g['non_manifold_edges']} non-manifold edges, 160^3 in "
           f"<= {g['wall_s_at_160']:g} s, 256^3 in <= {g.get('wall_s_at_256', GOALS['wall_s_at_256']):g} s; after each "
           "number, yes = goal met, **NO** = missed.", ""]
    out += ["| volume | method | materials found | Dice air, polymer, Al, steel | min Dice | "
            "interface mean / p95 vox | tets/voxel | min / p1 dihedral deg | non-manifold edges | "
            "wall s | peak MiB |", "|---|---|---|---|---|---|---|---|---|---|---|"]

    def ok(flag):
        return "" if flag is None else (" yes" if flag else " **NO**")

    for case in res["cases"]:
        vol = f"{case['size']}^3 seed {case['seed']} ({case['housing']}, {case['pores']} pores)"
        for name, m in case["methods"].items():
            if "error" in m:
                out.append(f"| {vol} | {name} | failed: {m['error'][-120:]!r} | | | | | | | | |")
                continue
            ev = m["eval"]
            iv, q = ev.get("interface_vox"), m.get("element_quality")
            # the time goals are ctseg 3D's own; results written before the 256^3 one lack it
            wall_goal = {160: g["wall_s_at_160"], 256: g.get("wall_s_at_256", GOALS["wall_s_at_256"])}.get(case["size"])
            timed_goal = wall_goal is not None and name == "ctseg_3d"
            peak = m["peak_mib"] + (m["worker_peak_mib"] if name == "ctseg_slices" else 0)
            out.append(
                f"| {vol} | {name} | {len(set(ev['class_to_material']))} | "
                f"{', '.join(fmt(d) for d in ev['dice'])} | {fmt(ev['min_dice'])}"
                f"{ok(ev['min_dice'] >= g['min_dice'])} | "
                + (f"{iv['mean']:.2f}{ok(iv['mean'] <= g['interface_mean_vox'])} / {iv['p95']:.2f}"
                   f"{ok(iv['p95'] <= g['interface_p95_vox'])}" if iv else "-") + " | "
                + (f"{ev['tets_per_voxel']:.4f}{ok(ev['tets_per_voxel'] <= g['tets_per_voxel'])}"
                   if "tets_per_voxel" in ev else "-") + " | "
                + (f"{q['min_dihedral_deg']:.1f}{ok(q['min_dihedral_deg'] >= g['min_dihedral_deg'])} / "
                   f"{q['p1_dihedral_deg']:.1f}{ok(q['p1_dihedral_deg'] >= g['p1_dihedral_deg'])}"
                   if q else "-") + " | "
                + (f"{ev['non_manifold_edges']}{ok(ev['non_manifold_edges'] == 0)}"
                   if "non_manifold_edges" in ev else "-") + " | "
                + f"{m['wall_s']:.2f}{ok(m['wall_s'] <= wall_goal) if timed_goal else ''} | {peak:.0f} |")
    out += ["", "## ctseg 3D: stages (s) and mesh", ""]
    stages = []
    for case in res["cases"]:
        m = case["methods"].get("ctseg_3d", {})
        stages += [s for s in m.get("times_s", {}) if s not in stages]
    out += ["| volume | " + " | ".join(stages) + " | sites | tetrahedra | Lloyd iterations | "
            "relabelled for manifold |", "|---" * (len(stages) + 5) + "|"]
    for case in res["cases"]:
        m = case["methods"].get("ctseg_3d", {})
        if "times_s" in m:
            out.append(f"| {case['size']}^3 seed {case['seed']} | "
                       + " | ".join(fmt(m["times_s"].get(s), 2) for s in stages)
                       + f" | {m['n_sites']} | {m['n_tetrahedra']} | {m['lloyd_iterations']} | "
                       f"{m['relabelled_for_manifold']} |")
    out += ["", "## Interface vertices to the true interfaces (voxels)", "",
            "Each vertex of a method's interface a|b (ctseg 3D's interface triangles; the baselines' "
            "vtkSurfaceNets3D surfaces of their label maps) against the true a|b interface (the goals' measure; "
            "a vertex between the right materials in the wrong place, or between wrongly labelled "
            "materials, is far from it), and against the nearest true interface of any pair (where "
            "the surfaces lie, whatever their labels).", "",
            "| volume | method | pair | vertices | mean | median | p95 | max | share <= 1 | any pair: mean | p95 |",
            "|---|---|---|---|---|---|---|---|---|---|---|"]
    for case, name in ((c, n) for c in res["cases"] for n in c["methods"]):
        iv = case["methods"][name].get("eval", {}).get("interface_vox")
        if iv:
            rows = list(iv["per_pair"].items()) + [("**all**", iv)]
            out += [f"| {case['size']}^3 seed {case['seed']} | {name} | {p.replace('|', '/')} | {v['vertices']} | "
                    f"{v['mean']:.2f} | "
                    f"{v['median']:.2f} | {v['p95']:.2f} | {v['max']:.1f} | {v['within_1']:.2f} | "
                    f"{v['any_pair_mean']:.2f} | {v['any_pair_p95']:.2f} |" for p, v in rows]
    out += ["", "## Where the errors are (voxels)", "",
            f"Per material: missed (of them within {EDGE_VOX} voxel of a true boundary, i.e. "
            "partial-volume edge errors); false (of them more than 2 voxels from any true voxel "
            "of the material: false layers and false regions). Feature recall: share of the "
            "voxels deep inside each feature given its material.", ""]
    for case in res["cases"]:
        for name, m in case["methods"].items():
            if "eval" not in m:
                continue
            ev = m["eval"]
            errs = "; ".join(f"{k} missed {e['missed']} ({e['missed_at_edge']} edge), false {e['false']} "
                             f"({e['false_far']} far)" for k, e in ev["errors"].items())
            rec = ", ".join(f"{k} {fmt(v, 2)}" for k, v in ev["feature_recall"].items())
            out.append(f"- {case['size']}^3 seed {case['seed']}, {name}: {errs}. Recall: {rec}.")
    return "\n".join(out) + "\n"


def write(res, out):
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    with open(out + ".json", "w") as fh:
        json.dump(res, fh, indent=1)
    with open(out + ".md", "w") as fh:
        fh.write(markdown(res))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[64, 96, 160])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--seeds96", type=int, nargs="+", default=[0, 1], help="seeds at size 96")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    ap.add_argument("--graphcut-max-voxels", type=int, default=5_000_000)
    ap.add_argument("--cleaver-python", default=".venv-cleaver/bin/python",
                    help="the Python of Cleaver's own environment (benchmarks/tet_baselines.py)")
    ap.add_argument("--noise-sd", type=float, default=None, help="phantom noise (default: its own)")
    ap.add_argument("--out", default=os.path.join(HERE, "results", "volume3d"),
                    help="output path without .json / .md")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child_main(json.loads(args.child))
    from ctseg.phantoms3d import make_part_3d

    res = {"when": time.strftime("%Y-%m-%d"), "cpu_count": os.cpu_count(),
           "platform": f"{platform.machine()}, Python {platform.python_version()}",
           "repeats": args.repeats, "goals": GOALS, "cases": []}
    with tempfile.TemporaryDirectory() as tmp:
        for size in args.sizes:
            for seed in (args.seeds96 if size == 96 else args.seeds):
                t0 = time.perf_counter()
                ph = make_part_3d(size, seed=seed, noise_sd=args.noise_sd)
                t_ph = time.perf_counter() - t0
                path = os.path.join(tmp, "image.npy")
                np.save(path, ph.image)
                aux = aux_maps(ph)
                case = {"size": size, "seed": seed, "shape": list(ph.image.shape),
                        "housing": ph.features["housing"], "phantom_s": t_ph,
                        "material_fraction": (np.bincount(ph.truth.ravel(), minlength=len(ph.names))
                                              / ph.truth.size).tolist(),
                        "pores": len(ph.features["pores"]), "noise_sd": ph.noise_sd, "methods": {}}
                for method in sorted(args.methods, key=METHODS.index):  # the graph cut before its meshers
                    if method == "graphcut" and ph.image.size > args.graphcut_max_voxels:
                        case["methods"][method] = {"error": f"skipped: over {args.graphcut_max_voxels} voxels"}
                        continue
                    out = os.path.join(tmp, f"{method}.npz")
                    spec = {"method": method, "image": path, "out": out, "repeats": args.repeats,
                            "spacing": ph.spacing.tolist(), "k_true": len(ph.names)}
                    if method in ("cgal", "cleaver"):
                        if "eval" not in case["methods"].get("graphcut", {}):
                            case["methods"][method] = {"error": "skipped: needs the graphcut method's labels"}
                            continue
                        spec.update(labels=os.path.join(tmp, "graphcut.npz"), cleaver_python=args.cleaver_python)
                    r = in_child(spec)
                    if "error" not in r:
                        with np.load(out) as z:
                            r["eval"] = evaluate(ph, r, dict(z), aux)
                    case["methods"][method] = r
                    ev = r.get("eval", {})
                    print(f"{size}^3 seed {seed} {method}: {r.get('wall_s', float('nan')):.2f} s, "
                          f"Dice {[round(d, 3) for d in ev.get('dice', [])]}"
                          + (f", interface {ev['interface_vox']['mean']:.2f}/{ev['interface_vox']['p95']:.2f}"
                             if "interface_vox" in ev else "") + (f" {r['error']}" if "error" in r else ""),
                          flush=True)
                res["cases"].append(case)
                write(res, args.out)
    print(markdown(res))


if __name__ == "__main__":
    main()
