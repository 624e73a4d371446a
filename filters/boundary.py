"""Material boundaries as a VTK filter: labelled mesh -> polylines between materials."""
import numpy as np

from ctseg.boundary import chain_polylines, material_boundary
from ctseg.errors import InputError
from ctseg.triangulation import triangle_mesh

from .base import CTSegAlgorithm
from .convert import boundary_lines_to_polydata, polydata_to_arrays


class MaterialBoundaryFilter(CTSegAlgorithm):
    """The edges between triangles of different materials, chained into polylines
    (:func:`ctseg.boundary.material_boundary`, SPEC 8).

    Input: a triangle mesh with a ``material`` cell array (any slice count: slices share no
    points). Output: vtkPolyData of polylines on the mesh's points, cell arrays
    ``material_a`` < ``material_b`` (the materials each side).
    """

    def __init__(self):
        super().__init__(input_type="vtkPolyData", output_type="vtkPolyData")

    def _request(self, request, in_info, out_info):
        xyz, tri, arrays = polydata_to_arrays(self._input(in_info))
        if "material" not in arrays:
            raise InputError("mesh: no 'material' cell array; connect a GraphCutSegmentFilter "
                             "or CTSegmentFilter first")
        mesh = triangle_mesh(xyz, tri)
        edges, sides = material_boundary(mesh.shared_edges, mesh.adjacency,
                                         np.asarray(arrays["material"], np.int64))
        lines, line_sides = chain_polylines(edges, sides)
        line_slice = None
        if "slice" in arrays:  # every point belongs to one slice
            point_slice = np.zeros(len(xyz), np.int64)
            point_slice[tri.ravel()] = np.repeat(arrays["slice"], 3)
            line_slice = point_slice[[line[0] for line in lines]] if lines else np.zeros(0, int)
        self._output_poly(out_info).ShallowCopy(
            boundary_lines_to_polydata(xyz, lines, line_sides, line_slice))
        self.UpdateProgress(1.0)
