"""Mesh writers behind one function, :func:`write_mesh`, used by the CLI and the plugins.

Every mesh passes :func:`ctseg.meshcheck.check_mesh` (pymeshlab) before anything is written,
and every file is written under a temporary name in the target folder and renamed at the
end, so a failed check, an error or an interrupt never leaves a partial file.

Formats: ``.vtp`` (VTK XML PolyData, the default: every cell array), ``.vtu`` (VTK XML
unstructured grid, same arrays), ``.ply`` (binary; material as face colour and as face
quality, which MeshLab shows and filters on), ``.stl`` (binary, one file per material:
``NAME_material<k>.stl``, as STL has no per-face data), ``.obj`` (one group and one
``usemtl`` per material, colours in a ``.mtl`` beside it), ``.mlp`` (a MeshLab project:
one layer per material, each a coloured binary PLY ``NAME_material<k>.ply`` beside it).
"""
import contextlib
import os
import tempfile

import numpy as np

from ctseg.errors import InputError

from .convert import polydata_to_arrays

MESH_FORMATS = (".vtp", ".vtu", ".ply", ".stl", ".obj", ".mlp")

# Material colours: colour-blind-safe (Okabe-Ito), air first; shared with the figure.
PALETTE = np.array([
    [40, 40, 40], [230, 159, 0], [86, 180, 233], [0, 158, 115], [240, 228, 66],
    [0, 114, 178], [213, 94, 0], [204, 121, 167], [150, 150, 150],
], np.uint8)


def material_colors(material):
    """RGB (uint8) colour of each material number."""
    return PALETTE[np.asarray(material, np.int64) % len(PALETTE)]


def check_output_path(path, ext_expected=None):
    """``(path, lower-case extension)`` of an output file, or InputError (one line): a
    folder, an extension not in ``ext_expected``, a missing or unwritable folder."""
    path = os.fspath(path)
    if os.path.isdir(path):
        raise InputError(f"{path}: is a folder; give a file name")
    ext = os.path.splitext(path)[1].lower()
    if ext_expected is not None and ext not in ext_expected:
        raise InputError(f"{path}: unknown output format {ext or '(no extension)'}; "
                         f"use one of {', '.join(ext_expected)}")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise InputError(f"{path}: the folder {folder} does not exist")
    if not os.access(folder, os.W_OK):
        raise InputError(f"{path}: the folder {folder} is not writable")
    # os.access says yes to root on a read-only or virtual file system: try for real
    try:
        fd, probe = tempfile.mkstemp(prefix=".ctseg-probe-", dir=folder)
    except OSError as exc:
        raise InputError(f"{path}: the folder {folder} is not writable ({exc.strerror})") from None
    os.close(fd)
    os.unlink(probe)
    return path, ext


def _file_mode():
    """The permissions a new file gets from open(): 0666 less the umask."""
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


@contextlib.contextmanager
def atomic_outputs(paths):
    """Yield temporary names beside ``paths``; rename them all onto ``paths`` on success,
    delete them on any failure."""
    temps = []
    try:
        for p in paths:
            folder = os.path.dirname(os.path.abspath(p))
            try:
                fd, tmp = tempfile.mkstemp(prefix=".ctseg-", suffix=os.path.splitext(p)[1],
                                           dir=folder)
            except OSError as exc:
                raise InputError(f"{p}: cannot write in {folder} ({exc.strerror})") from None
            os.close(fd)
            temps.append(tmp)
        yield temps
        for p in paths:  # a folder in the way would stop the renames half-way
            if os.path.isdir(p):
                raise InputError(f"{p}: is a folder; cannot write the file there")
        mode = _file_mode()
        done = []
        try:
            for tmp, p in zip(temps, paths):
                os.chmod(tmp, mode)  # mkstemp's 0600 -> what open() would have given
                os.replace(tmp, p)
                done.append(p)
        except OSError as exc:
            for p_done in done:  # the files of one output are all there or none
                os.unlink(p_done)
            raise InputError(f"{p}: cannot write it ({exc.strerror})") from None
        temps = []
    finally:
        for tmp in temps:
            if os.path.exists(tmp):
                os.unlink(tmp)


def _vtk_write(writer, data, tmp, path):
    writer.SetFileName(tmp)
    writer.SetInputData(data)
    writer.SetDataModeToBinary()
    if writer.Write() != 1:
        raise InputError(f"{path}: VTK could not write the file")


def _write_ply(points, triangles, material, tmp):
    import pymeshlab

    rgba = np.column_stack([material_colors(material) / 255.0, np.ones(len(material))])
    mesh = pymeshlab.Mesh(vertex_matrix=points, face_matrix=triangles.astype(np.int32),
                          f_scalar_array=material.astype(np.float64), f_color_matrix=rgba)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(mesh)
    ms.save_current_mesh(tmp, binary=True, save_face_color=True, save_face_quality=True,
                         save_vertex_color=False, save_vertex_quality=False)


def _submesh(points, triangles):
    """The points the triangles use, and the triangles renumbered onto them."""
    used = np.unique(triangles)
    remap = np.full(len(points), -1, np.int64)
    remap[used] = np.arange(len(used))
    return points[used], remap[triangles]


def _write_stl(points, triangles, tmp):
    import pymeshlab

    pts, tri = _submesh(points, triangles)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=pts, face_matrix=tri.astype(np.int32)))
    ms.save_current_mesh(tmp, binary=True)


def _write_mlp(names, labels, tmp):
    """A MeshLab project: one layer per file (MeshLab's own project writer records no file
    names for meshes it did not load, so the XML is written here)."""
    from xml.sax.saxutils import quoteattr

    layers = "".join(
        f'  <MLMesh label={quoteattr(label)} filename={quoteattr(name)} visible="1">\n'
        "   <MLMatrix44>\n1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 \n</MLMatrix44>\n  </MLMesh>\n"
        for name, label in zip(names, labels))
    with open(tmp, "w") as fh:
        fh.write("<!DOCTYPE MeshLabDocument>\n<MeshLabProject>\n <MeshGroup>\n" + layers
                 + " </MeshGroup>\n <RasterGroup/>\n</MeshLabProject>\n")


def _write_obj(points, triangles, material, tmp_obj, tmp_mtl, mtl_name):
    mats = np.unique(material)
    with open(tmp_mtl, "w") as fh:
        fh.write("# ctseg materials\n")
        for k, rgb in zip(mats, material_colors(mats)):
            fh.write(f"newmtl material_{k}\nKd {rgb[0] / 255:.4f} {rgb[1] / 255:.4f} "
                     f"{rgb[2] / 255:.4f}\n")
    with open(tmp_obj, "w") as fh:
        fh.write(f"# ctseg segmented mesh: one group per material\nmtllib {mtl_name}\n")
        np.savetxt(fh, points, fmt="v %.9g %.9g %.9g")
        for k in mats:
            fh.write(f"g material_{k}\nusemtl material_{k}\n")
            np.savetxt(fh, triangles[material == k] + 1, fmt="f %d %d %d")


def mesh_outputs(path):
    """The files :func:`write_mesh` writes for ``path`` (all but STL: ``path`` itself, plus
    the .mtl for OBJ; STL: a pattern with ``{material}``)."""
    stem, ext = os.path.splitext(os.fspath(path))
    if ext.lower() == ".stl":
        return [f"{stem}_material{{material}}.stl"]
    if ext.lower() == ".mlp":
        return [os.fspath(path), f"{stem}_material{{material}}.ply"]
    if ext.lower() == ".obj":
        return [os.fspath(path), stem + ".mtl"]
    return [os.fspath(path)]


def write_mesh(poly, path, check=True):
    """Write a segmented triangle mesh (vtkPolyData with a ``material`` cell array).

    Parameters
    ----------
    poly : vtkPolyData
        Triangles in world coordinates, cell arrays ``material`` (and ``gray``, ``slice``).
    path : str or path-like
        Output file; the extension picks the format (see the module's docstring).
    check : bool
        Run the pymeshlab checks first (on by default; only tests switch it off).

    Returns
    -------
    written : list of str
        The files written.
    checks : dict
        The mesh checks' report (:func:`ctseg.meshcheck.mesh_check_report`; empty when
        ``check`` is off).

    Raises
    ------
    InputError
        Unknown extension, missing or unwritable folder, no ``material`` array.
    MeshCheckError
        The mesh failed a check; nothing was written.
    """
    from ctseg.meshcheck import check_mesh

    path, ext = check_output_path(path, MESH_FORMATS)
    points, triangles, arrays = polydata_to_arrays(poly)
    checks = check_mesh(points, triangles, what=path) if check else {}
    return _write(poly, path, ext, points, triangles, arrays), checks


def _write(poly, path, ext, points, triangles, arrays):
    if ext == ".vtp":
        from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

        with atomic_outputs([path]) as (tmp,):
            _vtk_write(vtkXMLPolyDataWriter(), poly, tmp, path)
        return [path]
    if ext == ".vtu":
        from vtkmodules.vtkFiltersCore import vtkAppendFilter
        from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridWriter

        grid = vtkAppendFilter()
        grid.AddInputData(poly)
        grid.Update()
        with atomic_outputs([path]) as (tmp,):
            _vtk_write(vtkXMLUnstructuredGridWriter(), grid.GetOutput(), tmp, path)
        return [path]
    if "material" not in arrays:
        raise InputError(f"{path}: the mesh has no 'material' cell array to write")
    material = np.asarray(arrays["material"], np.int64)
    if ext == ".ply":
        with atomic_outputs([path]) as (tmp,):
            _write_ply(points, triangles, material, tmp)
        return [path]
    if ext == ".stl":
        pattern = mesh_outputs(path)[0]
        mats = np.unique(material)
        outs = [pattern.replace("{material}", str(k)) for k in mats]
        with atomic_outputs(outs) as temps:
            for k, tmp in zip(mats, temps):
                _write_stl(points, triangles[material == k], tmp)
        return outs
    if ext == ".mlp":
        project, pattern = mesh_outputs(path)
        mats = np.unique(material)
        plys = [pattern.replace("{material}", str(k)) for k in mats]
        with atomic_outputs([project] + plys) as temps:
            for k, tmp in zip(mats, temps[1:]):
                pts, tri = _submesh(points, triangles[material == k])
                _write_ply(pts, tri, np.full(len(tri), k), tmp)
            _write_mlp([os.path.basename(p) for p in plys], [f"material {k}" for k in mats],
                       temps[0])
        return [project] + plys
    obj, mtl = mesh_outputs(path)
    with atomic_outputs([obj, mtl]) as (tmp_obj, tmp_mtl):
        _write_obj(points, triangles, material, tmp_obj, tmp_mtl, os.path.basename(mtl))
    return [obj, mtl]


def stale_siblings(written):
    """Files beside the per-material files just written (``NAME_material<k>.stl`` or
    ``.ply``) that follow the same pattern but were not written now: left by an earlier run
    with more materials. They are not removed (they are the user's files); the CLI names
    them so that nobody takes them for part of this result."""
    import glob
    import re

    written = {os.fspath(p) for p in written}
    groups = {m.groups() for m in (re.fullmatch(r"(.*_material)\d+(\.(?:stl|ply))", p, re.IGNORECASE)
                                   for p in written) if m}
    stale = set()
    for stem, ext in groups:  # one listing per output, not per material
        ours = re.compile(re.escape(stem) + r"\d+" + re.escape(ext))
        stale |= {p for p in glob.glob(glob.escape(stem) + "*" + glob.escape(ext)) if ours.fullmatch(p)}
    return sorted(stale - written)


def write_polydata(poly, path):
    """Write any vtkPolyData (e.g. boundary polylines) as VTK XML (.vtp), through a
    temporary name renamed at the end. No mesh checks: use :func:`write_mesh` for meshes."""
    from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

    path, _ = check_output_path(path, (".vtp",))
    with atomic_outputs([path]) as (tmp,):
        _vtk_write(vtkXMLPolyDataWriter(), poly, tmp, path)
    return path


def read_polydata(path):
    """Read a .vtp file (written by ctseg or anyone) back as vtkPolyData."""
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    from .readers import _vtk_read

    return _vtk_read(vtkXMLPolyDataReader, os.fspath(path), "VTK XML PolyData").GetOutput()
