"""The ``ctseg`` command line: ``ctseg mesh INPUT -o OUTPUT``."""
import argparse
import json
import os
import shutil
import sys
import time

import numpy as np

from ._validate import as_image, as_labels, as_volume, check_value_range
from .checkpoint import checkpoint_folder, resume_hint
from .errors import CTSegError, InputError, ParameterError, ResumeError
from .params import SPECS, SegmentParams, resolve_name

MESH_HELP = """\
Segment a CT slice into a triangle mesh with one material per triangle, and a volume
into tetrahedra with one material each and closed surfaces (--mode auto, the default,
where the memory allows; else, or with --mode slices, slice by slice in triangles).

Pipeline (Yang et al. 2014): gradient density map -> Ward-initialised centroidal Voronoi
tessellation -> Delaunay triangles -> area-weighted gray per triangle -> recursive graph
cut -> materials numbered 0..K-1 by ascending gray.

Inputs: .npy, .png, .tif/.tiff (single or multi-page), DICOM (a file, or a folder of one
series; --series picks one of several), .nrrd/.nhdr, .nii/.nii.gz, .mha/.mhd, .vti, or a
folder of TIFF slices. Slices mode segments a volume slice by slice along --axis with
one material numbering for the whole volume; its slices run in --jobs local processes or
on a Dask cluster (--dask ADDRESS). Mode auto takes slices mode where 3D would not fit in
memory and for the options only slices mode has (--boundary, --dask, a .mlp output,
--resume of a run that went slice by slice), and says so.

Outputs of a slice and of slices mode, by extension: .vtp (default; VTK XML PolyData, world coordinates, cell arrays
'material', 'gray' in the input's units, 'slice'), .vtu, .ply (material as face colour
and quality), .stl (one file per material: NAME_material<k>.stl), .obj (one group per
material, colours in NAME.mtl), .mlp (a MeshLab project with one layer per material,
each a coloured PLY NAME_material<k>.ply). Every mesh passes pymeshlab's checks before it is written,
and every file is written under a temporary name and renamed: an error or Ctrl-C leaves
no partial file.

3D mode (a volume only): the same method on the voxels, with the file's
spacing. Outputs: .vtu (tetrahedra with 'material' and 'gray'), .vtp (every material's
closed surface, with 'material'), .stl (one closed STL per material), .ply and .obj (the
closed surfaces coloured by material), and finite-element meshes .msh (Gmsh 4.1, physical
groups per material, interface and box side), .inp (Abaqus) and .xdmf; --surfaces OUT.vtp writes the interface triangles
('material_a', 'material_b', normals from a to b). Every closed surface is checked
(closed, manifold, outward, not self-intersecting, enclosing its tetrahedra's volume)
before anything is written.

Parameters: the common ones have options of their own (below); every other one is set
with --set NAME=VALUE (repeatable; 'auto' for the automatic value where allowed), or all
at once from a JSON file (--params, as in a report's "parameters"). `ctseg params` lists
them all with their defaults, ranges and units.
"""


def _progress_printer(enabled):
    if not enabled:
        return None
    t0 = time.perf_counter()

    def report(frac, stage):
        bar = "#" * int(round(frac * 30))
        sys.stderr.write(f"\r[{bar:<30}] {frac * 100:5.1f}%  {stage:<16} {time.perf_counter() - t0:6.1f} s")
        if frac >= 1.0:
            sys.stderr.write("\n")
        sys.stderr.flush()

    return report


def _check_outputs(args, mode):
    """Refuse bad output paths (and options of the other mode) before hours of work."""
    from ctseg.filters.figure import offscreen_window
    from ctseg.filters.writers import MESH_FORMATS, check_output_path
    from ctseg.filters.writers3d import check_tetra_output_path

    if mode == "3d":
        if args.boundary:
            raise ParameterError("--boundary: the boundary polylines are slices mode's; in 3D "
                                 "mode the interface triangles go to --surfaces OUT.vtp")
        check_tetra_output_path(args.output)
    else:
        if args.surfaces:
            raise ParameterError("--surfaces: the interface triangles are 3D mode's (--mode "
                                 "3d); slices mode writes boundary polylines with --boundary")
        check_output_path(args.output, MESH_FORMATS)
    seen = {os.path.realpath(args.output): "-o"}
    for flag, path, exts in (("--boundary", args.boundary, (".vtp",)),
                             ("--surfaces", args.surfaces, (".vtp",)),
                             ("--figure", args.figure, (".png",)), ("--report", args.report, (".json",))):
        if path:
            check_output_path(path, exts)
            other = seen.setdefault(os.path.realpath(path), flag)
            if other != flag:
                raise ParameterError(f"{flag} {path}: the same file as {other}; one would "
                                     "overwrite the other")
    if args.figure:
        offscreen_window()  # can this VTK draw here at all?


def _mesh(args):
    from ctseg.filters import read_image, segmentation_to_polydata, write_mesh, write_polydata
    from ctseg.filters.figure import render_figure

    from .geometry import slice_axis, volume_slice
    from .metrics import evaluate, evaluate_volume
    from .volume import segment_array, volume_mode, volume_slice_axis

    image, geom = read_image(args.input, series=args.series)
    image = _checked_input(np.asarray(image), args.input)
    params = args.params_obj
    # --resume counts where there is something to resume: a run that auto sent slice by slice
    resumable = args.resume and os.path.isdir(checkpoint_folder(args.output))
    slices_for = [option for option, given in (
        ("--resume", resumable), ("--dask", args.dask), ("--boundary", args.boundary),
        (".mlp output", args.output.lower().endswith(".mlp"))) if given]
    mode, mode_note = volume_mode(image.shape, params.mode, slices_for)
    args.mode_note = mode_note
    if image.ndim == 3:  # decided once, on this machine's memory now
        params = params.replace(mode=mode, axis=volume_slice_axis(image.shape, params.axis))
    try:
        _check_outputs(args, mode)
    except CTSegError as exc:
        if mode_note:  # an option of the other mode refused: say why this mode was chosen
            raise type(exc)(f"{exc} ({mode_note})") from None
        raise
    show = sys.stderr.isatty() and not args.quiet
    progress = _progress_printer(show)
    truth = _read_truth(args.truth, image.shape)
    if mode == "3d":
        from ctseg.filters.job3d import segment_and_write_3d

        if args.resume or args.dask:
            print("ctseg: note: --resume and --dask apply to slices mode (--mode slices); 3D "
                  "mode runs here, in one go", file=sys.stderr)
        diag, written = segment_and_write_3d(image, geom, params, args.output, args.surfaces,
                                             args.figure, truth, progress, name=args.input)
        diag["input"] = os.path.abspath(args.input)
        return _finish(args, image, diag, written)
    if image.ndim == 2:
        if args.resume or args.dask:
            print("ctseg: note: --resume and --dask apply to volumes (slice by slice); a single "
                  "slice is one step and runs here", file=sys.stderr)
        result = segment_array(image, params, progress=progress)
        fig_image, fig_seg, fig_name = image, result, os.path.basename(args.input)
        diag = dict(result.diagnostics)
    else:
        ax = slice_axis(params.axis)
        mid = image.shape[ax] // 2
        args.checkpoint = checkpoint_folder(args.output)
        if not args.resume and os.path.isdir(args.checkpoint):
            shutil.rmtree(args.checkpoint)
        result = segment_array(image, params, client=args.dask, progress=progress,
                               keep_maps=(mid,) if args.figure else (),
                               checkpoint=args.checkpoint)
        fig_image, fig_seg = volume_slice(image, ax, mid), result.slices[mid]
        fig_name = f"{os.path.basename(args.input.rstrip(os.sep))} slice {mid} ({params.axis})"
        diag = dict(result.diagnostics)
        diag["slices"] = [{"n_triangles": s.diagnostics["n_triangles"],
                           "lloyd_iterations": s.diagnostics["lloyd_iterations"],
                           "total_time_s": s.diagnostics["total_time_s"]} for s in result.slices]
    if mode_note:
        diag["mode_note"] = mode_note
    mesh, boundary = segmentation_to_polydata(result, geom)
    written, checks = write_mesh(mesh, args.output)
    diag["input"] = os.path.abspath(args.input)
    diag["outputs"] = [os.path.abspath(w) for w in written]
    diag["mesh_checks"] = checks
    if args.boundary:
        write_polydata(boundary, args.boundary)
        diag["boundary_output"] = os.path.abspath(args.boundary)
        diag["boundary_polylines"] = boundary.GetNumberOfLines()
    if truth is not None:
        diag["accuracy"] = evaluate(result, truth) if image.ndim == 2 else evaluate_volume(result, truth)
    if args.figure:
        render_figure(args.figure, fig_image, fig_seg, title=fig_name)
        diag["figure"] = os.path.abspath(args.figure)
    return _finish(args, image, diag, written)


def _finish(args, image, diag, written):
    """The report, the checkpoint's removal and the summary, once every output is written."""
    if args.report:
        from ctseg.filters.writers import atomic_outputs

        with atomic_outputs([args.report]) as (tmp,):
            with open(tmp, "w") as fh:
                json.dump(diag, fh, indent=2, default=_json_value)
    if args.checkpoint:
        shutil.rmtree(args.checkpoint, ignore_errors=True)  # everything is written
    if not args.quiet:
        if diag.get("mode_note"):  # after the work: a refusal stays one line
            print(f"ctseg: note: {diag['mode_note']}", file=sys.stderr)
        if diag.get("mode") == "3d":
            from ctseg.filters.job3d import summary_lines_3d

            outs = written + [p for p in (args.surfaces, args.report, args.figure) if p]
            print("\n".join(summary_lines_3d(args.input, diag, outs) + _stale_notes(outs)))
        else:
            _summary(args, image, diag, written)
    return 0


def _json_value(value):
    """numpy scalars and arrays in a report, as JSON numbers and lists."""
    return value.tolist() if hasattr(value, "tolist") else str(value)


def _read_truth(path, shape):
    """The truth labels (int64) for --truth, checked against the image's shape first."""
    if not path:
        return None
    from ctseg.filters import read_image

    truth, _ = read_image(path)
    truth = np.asarray(truth)
    if truth.shape != tuple(shape):
        raise InputError(f"{path}: truth shape {truth.shape} differs from the image's {tuple(shape)}")
    return as_labels(truth, path)


def _checked_input(image, path):
    """The input as a slice or a volume, or an InputError naming the file."""
    if image.ndim == 3 and image.shape[0] == 1:
        image = image[0]
    if image.ndim == 3 and image.shape[2] in (3, 4) and min(image.shape[:2]) > 4:
        raise InputError(f"{path}: shape {image.shape} looks like a colour image ({image.shape[2]} "
                         "channels last); convert it to gray first (ctseg converts colour PNG "
                         "and TIFF files itself), or give a volume as (slices, rows, cols)")
    if image.ndim == 2:
        as_image(image, name=path)
    elif image.ndim == 3:
        as_volume(image, name=path)
    else:
        raise InputError(f"{path}: shape {image.shape} is neither a slice nor a volume")
    check_value_range(image, path)
    return image


def _stale_notes(outs):
    from ctseg.filters.writers import stale_siblings
    return [f"note: {p} is from an earlier run, not this one" for p in stale_siblings(outs)]


def _summary(args, image, diag, written):
    shape = " x ".join(str(n) for n in image.shape[::-1])
    print(f"{args.input}: {shape} -> {diag['n_triangles']} triangles, "
          f"{diag['n_materials']} materials (gray {', '.join(f'{g:.4g}' for g in diag['material_gray'])})")
    if image.ndim == 2:
        t = diag["times_s"]
        print("time: " + ", ".join(f"{k} {v:.2f} s" for k, v in t.items())
              + f"; total {diag['total_time_s']:.2f} s; Lloyd iterations "
              f"{diag['lloyd_iterations']}, graph cuts {diag['graphcut_calls']}")
    else:
        print(f"time: {diag['wall_time_s']:.2f} s for {diag['n_slices']} slices along "
              f"{diag['axis']} ({diag['executor']}); summed over slices: "
              + ", ".join(f"{k} {v:.2f} s" for k, v in diag["slice_times_s"].items()))
    outs = written + [p for p in (args.boundary, args.report, args.figure) if p]
    print(f"mesh checks: {'passed' if diag['mesh_checks']['ok'] else 'FAILED'}; wrote {', '.join(outs)}")
    for note in _stale_notes(outs):
        print(note)
    if "accuracy" in diag:
        acc = diag["accuracy"]
        print("Dice per material: " + ", ".join(f"{d:.4f}" for d in acc["dice"])
              + f" (min {acc['min_dice']:.4f}); boundary distance "
              f"{acc['boundary_px']['mean']:.3f} px")


def _option_help(spec):
    default = spec.default if spec.kind != "bool" else ("on" if spec.default else "off")
    unit = f", {spec.unit}" if spec.unit else ""
    return f"{spec.doc} (parameter {spec.name}; default {default}{unit}; {spec.range_text()})"


def _add_parameter_options(m):
    """The common parameters' own options and --set/--params for all, from the spec."""
    for spec in SPECS.values():
        if not spec.cli:
            continue
        if spec.kind == "bool":
            # only switches that turn a default-on step off
            m.add_argument(spec.cli, dest=spec.name, action="store_const", const=False,
                           default=None, help=_option_help(spec))
        else:
            m.add_argument(spec.cli, dest=spec.name, default=None, metavar=spec.name.upper()
                           if spec.kind != "choice" else None,
                           choices=spec.choices or None, help=_option_help(spec))
    m.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="set any parameter by name (repeatable; `ctseg params` lists them)")
    m.add_argument("--params", metavar="JSON",
                   help="start from the parameters in this JSON file (the report's "
                        "\"parameters\", or a flat {name: value})")


def params_from_args(args):
    """The SegmentParams a ``ctseg mesh`` command line asks for: --params first, then
    --set, then the named options; each value checked by the spec."""
    base = SegmentParams()
    if args.params:
        try:
            with open(args.params) as fh:
                data = json.load(fh)
        except (OSError, ValueError) as exc:
            raise ParameterError(f"--params {args.params}: cannot read it as JSON ({exc})") from None
        data = data.get("parameters", data) if isinstance(data, dict) else data
        if not isinstance(data, dict):
            raise ParameterError(f"--params {args.params}: expected a JSON object of name: value "
                                 f"(as a report's \"parameters\"), got {type(data).__name__}")
        base = SegmentParams.from_dict(data)
    changes = {}
    for item in args.set:
        name, sep, text = item.partition("=")
        if not sep:
            raise ParameterError(f"--set {item!r}: expected NAME=VALUE")
        for key in resolve_name(name.strip()):
            changes[key] = SPECS[key].parse(text)
    for spec in SPECS.values():
        value = getattr(args, spec.name, None) if spec.cli else None
        if value is not None:
            changes[spec.name] = value if spec.kind == "bool" else spec.parse(value)
    return base.replace(**changes)


def _print_params(args):
    defaults = SegmentParams()
    if args.json:
        print(json.dumps(defaults.to_dict(), indent=2))
        return 0
    rows = [("name", "default", "valid", "unit", "option", "meaning")]
    for spec in SPECS.values():
        rows.append((spec.name, str(spec.default), spec.range_text(), spec.unit,
                     spec.cli or f"--set {spec.name}=", spec.doc))
    widths = [max(len(r[k]) for r in rows) for k in range(5)]
    group = None
    for k, row in enumerate(rows):
        if k and SPECS[row[0]].group != group:
            group = SPECS[row[0]].group
            print(f"\n[{group}]")
        print("  ".join(cell.ljust(w) for cell, w in zip(row[:5], widths)) + "  " + row[5])
    return 0


def build_parser():
    parser = argparse.ArgumentParser(prog="ctseg", description="Segmented meshes from CT images: triangles from "
                                     "a slice, tetrahedra from a volume.")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", required=True)
    m = sub.add_parser("mesh", help="segment a slice or a volume into a mesh",
                       description=MESH_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    m.add_argument("input", help="image file or folder (see above)")
    m.add_argument("-o", "--output", required=True,
                   help="output mesh: .vtp, .vtu, .ply, .stl, .obj or .mlp (3D mode: .vtu, "
                        ".vtp, .stl, .ply, .obj, or FE: .msh, .inp, .xdmf)")
    m.add_argument("--boundary", help="slices: also write the material boundary polylines (.vtp)")
    m.add_argument("--surfaces", help="3D mode: also write the interface triangles (.vtp)")
    _add_parameter_options(m)
    m.add_argument("--dask", metavar="ADDRESS",
                   help="slices mode: run a volume's slices on this Dask scheduler (e.g. tcp://host:8786)")
    m.add_argument("--resume", action="store_true",
                   help="go on with a slices-mode volume run that was interrupted or failed: "
                        "the slices it finished (kept in OUTPUT.ctseg-partial) are not computed again")
    m.add_argument("--series", metavar="UID",
                   help="DICOM SeriesInstanceUID, for a folder holding several series")
    m.add_argument("--report", help="write all diagnostics as JSON (with every parameter used)")
    m.add_argument("--figure", help="write the six-panel figure (PNG; a volume's middle slice; "
                   "3D mode: three slices and the surfaces)")
    m.add_argument("--truth", help="ground-truth labels (same shape) to report Dice against")
    m.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    p = sub.add_parser("params", help="list every parameter: default, valid range, unit, meaning")
    p.add_argument("--json", action="store_true", help="print the defaults as JSON instead")
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    args.checkpoint = None  # a volume run's, once it has one
    try:
        if args.command == "params":
            return _print_params(args)
        if args.command == "mesh":
            args.params_obj = params_from_args(args)
            return _mesh(args)
    except CTSegError as exc:
        if args.debug:
            raise
        hint = "" if isinstance(exc, ResumeError) else resume_hint(args.checkpoint)
        print(f"ctseg: error: {exc}{hint}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        note = f" ({args.mode_note})" if getattr(args, "mode_note", "") else ""
        print(f"ctseg: interrupted; no partial output was left{resume_hint(args.checkpoint)}{note}",
              file=sys.stderr)
        return 130
    return 1


if __name__ == "__main__":
    sys.exit(main())
