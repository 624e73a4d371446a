"""Stage 5 as a VTK filter: mesh + image -> the mesh with each triangle's mean gray."""
from vtkmodules.vtkCommonDataModel import vtkPolyData

from ctseg.triangle_gray import triangle_gray

from .base import CTSegAlgorithm
from .convert import _add_cell_array, mesh_index_coordinates, polydata_to_arrays


class TriangleGrayFilter(CTSegAlgorithm):
    """Exact area-weighted mean gray of every triangle (:func:`ctseg.triangle_gray`, SPEC 5).

    Input 0: a triangle mesh over the slice (DelaunayMeshFilter's output, or any mesh in the
    image's plane); input 1: the one-slice vtkImageData. Output: the mesh with a ``gray``
    cell array in the image's units.
    """

    def __init__(self):
        super().__init__(n_inputs=2, input_type="vtkDataObject", output_type="vtkPolyData")

    def FillInputPortInformation(self, port, info):
        info.Set(self.INPUT_REQUIRED_DATA_TYPE(), "vtkPolyData" if port == 0 else "vtkImageData")
        return 1

    def _request(self, request, in_info, out_info):
        mesh_in = vtkPolyData.GetData(in_info[0], 0)
        arr, geom, _ = self._input_slice(in_info, port=1)
        xyz, tri, _ = polydata_to_arrays(mesh_in)
        gray = triangle_gray(arr, mesh_index_coordinates(xyz, geom, arr.shape), tri)
        out = self._output_poly(out_info)
        out.ShallowCopy(mesh_in)
        _add_cell_array(out, gray, "gray")
        self.UpdateProgress(1.0)
