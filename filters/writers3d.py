"""Writers of the 3D mode: a :class:`ctseg.pipeline3d.TetraSegmentation` to files, in world
coordinates, checked first and written whole or not at all.

Before anything is written, :func:`check_tetra_segmentation` requires every tetrahedron
to have a positive world volume and every material's closed surface to pass
:func:`ctseg.meshcheck.check_closed_surface` (no boundary, non-manifold, duplicated,
degenerate or self-intersecting faces, consistent outward orientation, and the volume of
its tetrahedra enclosed to a relative 1e-9; world coordinates, but self-intersection
tested in the box's own frame, where its sides are exactly flat). Files are written under temporary names and
renamed at the end (:func:`ctseg.filters.writers.atomic_outputs`).

Formats, by extension: ``.vtu`` (VTK XML unstructured grid: the tetrahedra with cell
arrays ``material`` and ``gray``), ``.vtp`` (every material's closed surface in one VTK
XML PolyData with a ``material`` cell array), ``.stl`` (one closed binary STL per
material, ``NAME_material<k>.stl``), ``.ply`` (binary; the closed surfaces with the
material as face colour and face quality), ``.obj`` (one group and ``usemtl`` per
material, colours in ``NAME.mtl``); finite-element meshes ``.msh`` (Gmsh 4.1), ``.inp``
(Abaqus) and ``.xdmf`` with element sets per material and facet sets per interface and
box side (:mod:`ctseg.filters.fe_writers`). The interface triangles go to a ``.vtp`` of
their own (:func:`write_interfaces`).
"""
import os

import numpy as np

from ctseg.errors import MeshCheckError

from .convert3d import (material_surfaces_to_polydata, surfaces_to_arrays,
                        tetra_segmentation_to_vtk, world_surfaces, world_tetrahedra)
from .fe_writers import FE_FORMATS, write_fe_mesh
from .writers import (_vtk_write, _write_obj, _write_ply, _write_stl, atomic_outputs,
                      check_output_path)

TETRA_FORMATS = (".vtu", ".vtp", ".stl", ".ply", ".obj") + tuple(FE_FORMATS)
"""Output formats of a 3D segmentation."""


def check_tetra_output_path(path):
    """``(path, extension)`` of a 3D output, or InputError (one line) for an unknown
    extension or a missing or unwritable folder."""
    return check_output_path(path, TETRA_FORMATS)


def tetra_outputs(path):
    """The files :func:`write_tetra_mesh` writes for ``path`` (STL: a pattern with
    ``{material}``; OBJ: the .obj and its .mtl)."""
    stem, ext = os.path.splitext(os.fspath(path))
    if ext.lower() == ".stl":
        return [f"{stem}_material{{material}}.stl"]
    if ext.lower() == ".obj":
        return [os.fspath(path), stem + ".mtl"]
    return [os.fspath(path)]


def check_tetra_segmentation(result, geometry=None):
    """Check a TetraSegmentation in world coordinates before it is written.

    Returns
    -------
    report : dict
        ``tetrahedra``, ``min_tetra_volume``, ``world_volume`` (their sum), ``surfaces``
        (one :func:`ctseg.meshcheck.closed_surface_report` per material, with its
        ``material``) and ``ok``.

    Raises
    ------
    MeshCheckError
        A tetrahedron of volume <= 0, a material without a surface, or a surface failing
        a check (the message names the material and the checks).
    """
    from ctseg.meshcheck import check_closed_surface
    from ctseg.tetrahedra import tetra_volumes

    pts, tets = world_tetrahedra(result, geometry)
    vol = tetra_volumes(pts, tets)
    bad = np.flatnonzero(~(vol > 0))
    if len(bad):
        raise MeshCheckError(f"tetrahedra: {len(bad)} of {len(vol)} have volume <= 0 in world "
                             f"coordinates (first: tetrahedron {bad[0]}, volume "
                             f"{vol[bad[0]]:.3g}); nothing was written")
    material = np.asarray(result.material, np.int64)
    surfaces = world_surfaces(result, geometry)
    missing = sorted(set(np.unique(material).tolist()) - {k for k, _, _ in surfaces})
    if missing:
        raise MeshCheckError(f"surfaces: material(s) {missing} have tetrahedra but no closed "
                             "surface; nothing was written")
    reports = []
    for (k, spts, tris), own in zip(surfaces, result.surfaces):
        # self-intersection in the box's frame, where its sides are exactly flat
        rep = check_closed_surface(spts, tris, float(vol[material == k].sum()),
                                   what=f"material {k} surface", intersection_points=own.points)
        reports.append({"material": k, **rep})
    return {"tetrahedra": int(len(tets)), "min_tetra_volume": float(vol.min(initial=np.inf)),
            "world_volume": float(vol.sum()), "surfaces": reports, "ok": True}


def write_tetra_mesh(result, path, geometry=None, check=True):
    """Write a TetraSegmentation (see the module's docstring for the formats).

    Parameters
    ----------
    result : ctseg.pipeline3d.TetraSegmentation
    path : str or path-like
        The extension picks the format.
    geometry : ctseg.geometry.ImageGeometry, optional
        The image's origin, spacing and direction (default: the result's spacing alone).
    check : bool
        Run :func:`check_tetra_segmentation` first (on by default; only tests switch it
        off).

    Returns
    -------
    written : list of str
    checks : dict
        :func:`check_tetra_segmentation`'s report (empty when ``check`` is off).

    Raises
    ------
    InputError
        An unknown format, a missing or unwritable folder.
    MeshCheckError
        A check failed; nothing was written.
    """
    path, ext = check_tetra_output_path(path)
    checks = check_tetra_segmentation(result, geometry) if check else {}
    if ext in FE_FORMATS:
        return write_fe_mesh(result, path, geometry), checks
    if ext == ".vtu":
        from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridWriter

        grid, _ = tetra_segmentation_to_vtk(result, geometry)
        with atomic_outputs([path]) as (tmp,):
            _vtk_write(vtkXMLUnstructuredGridWriter(), grid, tmp, path)
        return [path], checks
    if ext == ".vtp":
        from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

        with atomic_outputs([path]) as (tmp,):
            _vtk_write(vtkXMLPolyDataWriter(), material_surfaces_to_polydata(result, geometry),
                       tmp, path)
        return [path], checks
    points, triangles, material = surfaces_to_arrays(result, geometry)
    if ext == ".ply":
        with atomic_outputs([path]) as (tmp,):
            _write_ply(points, triangles, material, tmp)
        return [path], checks
    if ext == ".stl":
        mats = np.unique(material)
        outs = [tetra_outputs(path)[0].replace("{material}", str(k)) for k in mats]
        with atomic_outputs(outs) as temps:
            for k, tmp in zip(mats, temps):
                _write_stl(points, triangles[material == k], tmp)
        return outs, checks
    obj, mtl = tetra_outputs(path)
    with atomic_outputs([obj, mtl]) as (tmp_obj, tmp_mtl):
        _write_obj(points, triangles, material, tmp_obj, tmp_mtl, os.path.basename(mtl))
    return [obj, mtl], checks


def write_interfaces(result, path, geometry=None):
    """Write the interface triangles of a TetraSegmentation as VTK XML PolyData (.vtp):
    world coordinates, cell arrays ``material_a`` < ``material_b``, each normal pointing
    from a into b. Returns the path written."""
    from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

    path, _ = check_output_path(path, (".vtp",))
    _, interfaces = tetra_segmentation_to_vtk(result, geometry)
    with atomic_outputs([path]) as (tmp,):
        _vtk_write(vtkXMLPolyDataWriter(), interfaces, tmp, path)
    return path


def read_unstructured_grid(path):
    """Read a .vtu file back as vtkUnstructuredGrid."""
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

    from .readers import _vtk_read

    return _vtk_read(vtkXMLUnstructuredGridReader, os.fspath(path),
                     "VTK XML UnstructuredGrid").GetOutput()
