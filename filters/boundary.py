"""Material boundaries as a VTK filter: labelled mesh -> the boundaries between materials
(polylines of a triangle mesh, interface triangles of tetrahedra)."""
import numpy as np

from ctseg.boundary import chain_polylines, material_boundary
from ctseg.errors import InputError
from ctseg.stages3d import tetra_mesh
from ctseg.surfaces import material_interfaces
from ctseg.triangulation import triangle_mesh

from .base import CTSegAlgorithm
from .convert import boundary_lines_to_polydata, polydata_to_arrays
from .convert3d import grid_to_arrays, triangles_polydata


class MaterialBoundaryFilter(CTSegAlgorithm):
    """The boundaries between materials of a labelled mesh (SPEC 8 and 9.7).

    Input: a mesh with a ``material`` cell array. Triangles (vtkPolyData, any slice
    count: slices share no points): the edges between triangles of different materials
    (:func:`ctseg.boundary.material_boundary`), chained into polylines on the mesh's
    points, cell arrays ``material_a`` < ``material_b`` (the materials each side) and
    ``slice``. Tetrahedra (vtkUnstructuredGrid, GraphCutSegmentFilter's or
    CTSegmentFilter's Mode '3d' output): the faces between tetrahedra of different
    materials (:func:`ctseg.surfaces.material_interfaces`) as triangles on the grid's
    points, cell arrays ``material_a`` < ``material_b``, each normal pointing from a to b
    (computed in the grid's own coordinates, tetrahedra taken positively oriented there),
    as CTSegmentFilter's output 1. Output: vtkPolyData.
    """

    def __init__(self):
        super().__init__(input_type="vtkPointSet", output_type="vtkPolyData")

    def _request(self, request, in_info, out_info):
        data = self._input(in_info)
        if data.IsA("vtkUnstructuredGrid"):
            xyz, tets, arrays = grid_to_arrays(data)
        elif data.IsA("vtkPolyData"):
            xyz, tri, arrays = polydata_to_arrays(data)
        else:
            raise InputError(f"mesh: a {data.GetClassName()}; expected vtkPolyData triangles "
                             "or a vtkUnstructuredGrid of tetrahedra")
        if "material" not in arrays:
            raise InputError("mesh: no 'material' cell array; connect a GraphCutSegmentFilter "
                             "or CTSegmentFilter first")
        material = np.asarray(arrays["material"], np.int64)
        out = self._output_poly(out_info)
        if data.IsA("vtkUnstructuredGrid"):
            faces, mat_a, mat_b = material_interfaces(tetra_mesh(xyz, tets), material)
            out.ShallowCopy(triangles_polydata(xyz, faces, {"material_a": mat_a.astype(np.int32),
                                                            "material_b": mat_b.astype(np.int32)}))
            self.UpdateProgress(1.0)
            return
        mesh = triangle_mesh(xyz, tri)
        edges, sides = material_boundary(mesh.shared_edges, mesh.adjacency, material)
        lines, line_sides = chain_polylines(edges, sides)
        line_slice = None
        if "slice" in arrays:  # every point belongs to one slice
            point_slice = np.zeros(len(xyz), np.int64)
            point_slice[tri.ravel()] = np.repeat(arrays["slice"], 3)
            line_slice = point_slice[[line[0] for line in lines]] if lines else np.zeros(0, int)
        out.ShallowCopy(boundary_lines_to_polydata(xyz, lines, line_sides, line_slice))
        self.UpdateProgress(1.0)
