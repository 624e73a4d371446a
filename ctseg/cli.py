"""The ``ctseg`` command line: ``ctseg mesh INPUT -o OUTPUT.vtp``."""
import argparse
import json
import os
import sys
import time

import numpy as np

from .errors import CTSegError, InputError
from .pipeline import PIXELS_PER_SITE

MESH_HELP = f"""\
Segment a 2D CT slice into a triangle mesh with one material per triangle.

Pipeline (Yang et al. 2014): gradient density map -> Ward-initialised centroidal Voronoi
tessellation -> Delaunay triangles -> area-weighted gray per triangle -> recursive graph
cut -> materials numbered 0..K-1 by ascending mean gray.

Inputs: .npy, .png, .tif/.tiff, a single DICOM file. Output: VTK XML PolyData (.vtp) in
world coordinates with cell arrays 'material' (int), 'gray' (input units) and 'slice'.

Defaults: the number of sites is one per {PIXELS_PER_SITE} pixels (2048 for 512 x 512);
the split and merge thresholds are derived from the noise measured on the image.
"""


def _progress_printer(enabled):
    if not enabled:
        return None
    t0 = time.perf_counter()

    def report(frac, stage):
        bar = "#" * int(round(frac * 30))
        sys.stderr.write(f"\r[{bar:<30}] {frac * 100:5.1f}%  {stage:<14} {time.perf_counter() - t0:6.1f} s")
        if frac >= 1.0:
            sys.stderr.write("\n")
        sys.stderr.flush()

    return report


def _mesh(args):
    from ctseg.filters import (boundary_to_polydata, mesh_to_polydata, read_image,
                               write_polydata)

    from .figure import segmentation_figure
    from .meshcheck import check_mesh
    from .metrics import evaluate
    from .pipeline import segment_image

    for out in [args.output, args.boundary]:
        if out and os.path.splitext(out)[1].lower() != ".vtp":
            raise InputError(f"{out}: unknown output format; ctseg writes .vtp (VTK XML PolyData)")
    image, geom = read_image(args.input)
    image = np.asarray(image)
    if image.ndim == 3 and image.shape[0] == 1:
        image = image[0]
    if image.ndim != 2:
        raise InputError(f"{args.input}: shape {image.shape} is not a 2D slice; "
                         "volumes are segmented slice by slice by the filter layer")
    show = sys.stderr.isatty() and not args.quiet
    seg = segment_image(image, n_sites=args.sites, seed=args.seed, n_materials=args.materials,
                        progress=_progress_printer(show))
    report = check_mesh(seg.points, seg.triangles, what=args.output)
    poly = mesh_to_polydata(seg.points, seg.triangles, seg.material, seg.gray, geom)
    write_polydata(poly, args.output)
    diag = dict(seg.diagnostics)
    diag["input"] = os.path.abspath(args.input)
    diag["output"] = os.path.abspath(args.output)
    diag["mesh_checks"] = report
    if args.boundary:
        lines, sides = seg.boundary_polylines()
        write_polydata(boundary_to_polydata(seg.points, lines, sides, geom), args.boundary)
        diag["boundary_output"] = os.path.abspath(args.boundary)
        diag["boundary_polylines"] = len(lines)
    if args.truth:
        truth, _ = read_image(args.truth)
        truth = np.asarray(truth)
        if truth.shape != image.shape:
            raise InputError(f"{args.truth}: truth shape {truth.shape} differs from the image's {image.shape}")
        diag["accuracy"] = evaluate(seg, truth.astype(np.int64))
    if args.figure:
        segmentation_figure(args.figure, image, seg)
        diag["figure"] = os.path.abspath(args.figure)
    if args.report:
        with open(args.report, "w") as fh:
            json.dump(diag, fh, indent=2)
    if not args.quiet:
        t = diag["times_s"]
        print(f"{args.input}: {image.shape[1]} x {image.shape[0]} px -> {diag['n_triangles']} "
              f"triangles, {diag['n_sites']} vertices, {diag['n_materials']} materials "
              f"(mean gray {', '.join(f'{g:.4g}' for g in diag['material_gray'])})")
        print("time: " + ", ".join(f"{k} {v:.2f} s" for k, v in t.items())
              + f"; total {diag['total_time_s']:.2f} s; Lloyd iterations {diag['lloyd_iterations']}, "
              f"graph cuts {diag['graphcut_calls']}")
        print(f"mesh checks: {'passed' if report['ok'] else 'FAILED'}; wrote {args.output}"
              + (f", {args.boundary}" if args.boundary else "")
              + (f", {args.report}" if args.report else "")
              + (f", {args.figure}" if args.figure else ""))
        if "accuracy" in diag:
            acc = diag["accuracy"]
            print("Dice per material: " + ", ".join(f"{d:.4f}" for d in acc["dice"])
                  + f" (min {acc['min_dice']:.4f}); boundary distance "
                  f"{acc['boundary_px']['mean']:.3f} px")
    return 0


def build_parser():
    parser = argparse.ArgumentParser(prog="ctseg", description="Segmented triangle meshes from CT images.")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", required=True)
    m = sub.add_parser("mesh", help="segment a 2D slice into a triangle mesh",
                       description=MESH_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    m.add_argument("input", help="image file (.npy, .png, .tif, .tiff, DICOM)")
    m.add_argument("-o", "--output", required=True, help="output mesh (.vtp)")
    m.add_argument("--boundary", help="also write the material boundary polylines (.vtp)")
    m.add_argument("--sites", type=int, default=None,
                   help=f"number of CVT sites (default: pixels / {PIXELS_PER_SITE})")
    m.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    m.add_argument("--materials", type=int, default=None, metavar="K",
                   help="exact number of materials (default: found from the data)")
    m.add_argument("--report", help="write all diagnostics as JSON")
    m.add_argument("--figure", help="write the six-panel figure (PNG)")
    m.add_argument("--truth", help="ground-truth labels (same shape) to report Dice against")
    m.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command == "mesh":
            return _mesh(args)
    except CTSegError as exc:
        if args.debug:
            raise
        print(f"ctseg: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("ctseg: interrupted; no partial output was left", file=sys.stderr)
        return 130
    return 1


if __name__ == "__main__":
    sys.exit(main())
