"""Stage 4 as VTK filters: CVT sites -> their Delaunay triangles (a slice's sites) or
tetrahedra (a volume's sites)."""
import numpy as np
from vtkmodules.util import numpy_support
from vtkmodules.vtkCommonDataModel import VTK_TETRA, vtkUnstructuredGrid

from ctseg.errors import InputError
from ctseg.stages3d import tetrahedra_3d
from ctseg.triangulation import delaunay_mesh

from .base import CTSegAlgorithm, spec_names
from .convert3d import tetrahedra_to_world
from .convert import (GEOMETRY_FIELD, _cells, _field_array, _points, attach_geometry,
                      geometry_from_field_data)
from .sites import add_box_points, box_points


def recorded_geometry(data):
    """(ImageGeometry, shape) recorded on CVTSitesFilter's output: shape (rows, cols) for
    a slice's sites, (nz, ny, nx) for a volume's.

    Raises
    ------
    InputError
        No geometry recorded.
    """
    geom, _ = geometry_from_field_data(data)
    values = numpy_support.vtk_to_numpy(data.GetFieldData().GetArray(GEOMETRY_FIELD))
    return geom, tuple(int(v) for v in values[15:])


def _site_points(sites):
    if sites.GetPoints() is None or sites.GetNumberOfPoints() == 0:
        raise InputError("sites: the polydata has no points")
    return np.array(numpy_support.vtk_to_numpy(sites.GetPoints().GetData()), np.float64)


def _on_the_border(index_xy, shape):
    """Sites mapped back from world to index coordinates, those within 1e-6 px of the
    image's border lines put back on them: a rotated, anisotropic geometry leaves them
    1e-15 off, and border sites no longer exactly in line give Qhull a sliver."""
    xy = np.array(index_xy, float)
    for axis, last in ((0, shape[1] - 1), (1, shape[0] - 1)):
        for line in (0.0, float(last)):
            xy[np.abs(xy[:, axis] - line) < 1e-6, axis] = line
    return xy


class DelaunayMeshFilter(CTSegAlgorithm):
    """Delaunay triangulation of a slice's CVT sites (:func:`ctseg.delaunay_mesh`, SPEC 4).

    The triangulation is made in the image's index coordinates, as the method defines it
    (with anisotropic spacing a Delaunay mesh in world units would differ).
    Input: CVTSitesFilter's output for one slice (a volume's sites go to
    DelaunayTetraFilter). Output: vtkPolyData of counter-clockwise triangles in world
    coordinates, the image geometry carried on.
    """

    def __init__(self):
        super().__init__(input_type="vtkPolyData", output_type="vtkPolyData")

    def _request(self, request, in_info, out_info):
        sites = self._input(in_info)
        geom, shape = recorded_geometry(sites)
        if len(shape) != 2:
            raise InputError(f"sites: of a volume {shape}; DelaunayTetraFilter makes their "
                             "tetrahedra (DelaunayMeshFilter triangulates a slice's sites)")
        pts = _site_points(sites)
        mesh = delaunay_mesh(_on_the_border(geom.to_index(pts)[:, :2], shape))
        out = self._output_poly(out_info)
        out.SetPoints(_points(geom.to_world(np.column_stack([mesh.points, np.zeros(len(pts))]))))
        out.SetPolys(_cells(mesh.triangles.ravel(), 3))
        attach_geometry(out, geom, shape)
        self.UpdateProgress(1.0)


class DelaunayTetraFilter(CTSegAlgorithm):
    """Delaunay tetrahedra of a volume's CVT sites, slivers perturbed away
    (:func:`ctseg.stages3d.tetrahedra_3d`: :func:`ctseg.tetrahedra.perturb_slivers`,
    SPEC 9.4), as the 3D mode makes them.

    The tetrahedra are made in the volume's physical box coordinates (index x spacing), as
    the 3D mode defines them. Input: CVTSitesFilter's output for a volume (a slice's sites
    go to DelaunayMeshFilter). Output: vtkUnstructuredGrid of tetrahedra in world
    coordinates, positively oriented in world space (two vertices swapped where the
    image's direction flips), with the exact box coordinates of its points
    (:data:`ctseg.filters.sites.BOX_POINTS`, for TriangleGrayFilter and
    GraphCutSegmentFilter), field data ``slivers_left`` and the image geometry.
    Parameters (``ctseg params``): the tetrahedra group (SliverMinDihedral,
    SliverRounds) and Seed (of the sliver moves; CTSegmentFilter uses one Seed for the
    sites and the slivers, so set CVTSitesFilter's and this one's alike to compare).
    """

    PARAMETERS = spec_names("tetrahedra", names=("seed",))

    def __init__(self):
        super().__init__(input_type="vtkPolyData", output_type="vtkUnstructuredGrid")

    def _request(self, request, in_info, out_info):
        sites = self._input(in_info)
        geom, shape = recorded_geometry(sites)
        if len(shape) != 3:
            raise InputError(f"sites: of one slice {shape}; DelaunayMeshFilter triangulates "
                             "them (DelaunayTetraFilter takes a volume's sites)")
        spacing = np.asarray(geom.spacing, float)
        box = box_points(sites, geom, shape, name="sites")
        self.UpdateProgress(0.0)
        mesh, slivers = tetrahedra_3d(box, shape, self.params, spacing)
        world, tets = tetrahedra_to_world(mesh.points, mesh.tetrahedra, spacing, geom)
        out = vtkUnstructuredGrid.GetData(out_info, 0)
        out.SetPoints(_points(world))
        out.SetCells(VTK_TETRA, _cells(tets.ravel(), 4))
        add_box_points(out, mesh.points)
        attach_geometry(out, geom, shape)
        _field_array(out, "slivers_left", float(slivers))
        self.UpdateProgress(1.0)
