"""A whole 3D-mode job on a volume read from a file: segment with the file's spacing, check
and write the outputs in its world geometry, measure against truth, draw the figure, and
say what came out (the ``ctseg`` command's 3D mode; usable from any script)."""
import os


def segment_and_write_3d(image, geometry, params, output, surfaces=None, figure=None,
                         truth=None, progress=None, name="volume"):
    """Segment ``image`` in 3D and write everything asked for.

    Parameters
    ----------
    image : (nz, ny, nx) ndarray
    geometry : ctseg.geometry.ImageGeometry
        The file's origin, spacing and direction: the spacing goes to the segmentation,
        all of it to the outputs.
    params : ctseg.params.SegmentParams
    output : str
        Mesh file (:data:`ctseg.filters.writers3d.TETRA_FORMATS`).
    surfaces, figure : str, optional
        Interface triangles (.vtp) and the four-panel figure (.png).
    truth : (nz, ny, nx) int ndarray, optional
        Labels to report Dice per material against.
    progress : callable, optional
        ``progress(fraction, stage)``.
    name : str
        The input's name, for messages and the figure's title.

    Returns
    -------
    diag : dict
        The segmentation's diagnostics, plus the outputs, the mesh checks and the accuracy.
    written : list of str
        The mesh files written.

    Raises
    ------
    InputError
        Not a volume of at least 2 voxels along every axis
        (:func:`ctseg.pipeline3d.check_shape_3d`). Any error once writing has begun removes
        the files this call wrote before it is raised again.
    """
    from ctseg.pipeline3d import check_shape_3d
    from ctseg.volume import segment_array

    from .figure3d import render_volume_figure
    from ctseg.metrics import evaluate_tetra
    from .writers3d import write_interfaces, write_tetra_mesh

    check_shape_3d(image.shape, name)
    result = segment_array(image, params, spacing=geometry.spacing, progress=progress)
    done = []  # all the outputs or none: a failure after the first removes those written
    try:
        written, checks = write_tetra_mesh(result, output, geometry)
        done += written
        diag = dict(result.diagnostics, outputs=[os.path.abspath(w) for w in written],
                    mesh_checks=checks)
        if surfaces:
            write_interfaces(result, surfaces, geometry)
            done.append(surfaces)
            diag["surfaces_output"] = os.path.abspath(surfaces)
        if truth is not None:
            diag["accuracy"] = evaluate_tetra(result, truth)
        if figure:
            render_volume_figure(figure, image, result, title=os.path.basename(name.rstrip(os.sep)))
            diag["figure"] = os.path.abspath(figure)
    except BaseException:
        for path in done:
            if os.path.exists(path):
                os.unlink(path)
        raise
    return diag, written


def _levels_line(report, levels_255):
    """How the material levels were found (:func:`ctseg.levels3d.checked_levels`)."""
    source = {"given": "given", "flat_voxels": "the flat voxels", "tetrahedra":
              "the tetrahedra (the flat voxels hold partial volume)", "homogeneous_tetrahedra":
              "the count asked for, with the homogeneous tetrahedra's"}.get(report.get("method"),
                                                                          "the flat voxels")
    added = report.get("homogeneous_added_255") or []
    return (f"levels (0-255): {', '.join(f'{v:.1f}' for v in levels_255)} from {source}"
            + (f"; {', '.join(f'{v:.1f}' for v in added)} shown only by the homogeneous "
               "tetrahedra" if added else ""))


def summary_lines_3d(name, diag, outputs):
    """The lines that sum up a 3D job: tetrahedra, materials, surfaces, quality, the files
    written and, with truth, Dice per material."""
    q = diag["element_quality"]
    shape = " x ".join(str(n) for n in diag["volume_shape"][::-1])
    lines = [
        f"{name}: {shape} -> {diag['n_tetrahedra']} tetrahedra, {diag['n_materials']} "
        f"materials (gray {', '.join(f'{g:.4g}' for g in diag['material_gray'])}), "
        f"{diag['n_interface_triangles']} interface triangles",
        _levels_line(diag.get("levels", {}), diag.get("material_levels_255", [])),
        "surfaces: " + "; ".join(f"material {s['material']} {s['triangles']} triangles, volume "
                                 f"{s['enclosed_volume']:.6g}" for s in diag["surfaces"]),
        f"quality: min dihedral {q['min_dihedral_deg']:.1f} deg, min radius ratio "
        f"{q['min_radius_ratio']:.3f} (mean {q['mean_radius_ratio']:.3f}); time "
        f"{diag['total_time_s']:.2f} s, Lloyd iterations {diag['lloyd_iterations']}",
        f"mesh checks: {'passed' if diag['mesh_checks'].get('ok') else 'not run'}; wrote "
        f"{', '.join(outputs)}",
    ]
    if "accuracy" in diag:
        acc = diag["accuracy"]
        found, true = acc["n_materials_found"], acc["n_materials_true"]
        lines.append("Dice per material: " + ", ".join(f"{d:.4f}" for d in acc["dice"])
                     + f" (min {acc['min_dice']:.4f})"
                     + (f"; {found} materials found, {true} in the truth (material k is "
                        "compared with label k)" if found != true else ""))
    return lines
