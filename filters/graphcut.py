"""Stages 6-7 as a VTK filter: mesh with ``gray`` + image -> one material per triangle."""
from vtkmodules.util import numpy_support
from vtkmodules.vtkCommonDataModel import vtkPolyData

from ctseg.errors import InputError
from ctseg.pipeline import label_mesh
from ctseg.triangulation import triangle_mesh

from .base import CTSegAlgorithm, parameter
from .convert import _add_cell_array, mesh_index_coordinates, polydata_to_arrays


def _optional_int(value):
    return int(value) if value else 0


class GraphCutSegmentFilter(CTSegAlgorithm):
    """Recursive graph cut of the triangles into materials (:func:`ctseg.pipeline.label_mesh`,
    SPEC 6-7).

    Input 0: the mesh with a ``gray`` cell array (TriangleGrayFilter's output); input 1:
    the one-slice vtkImageData, whose flat pixels give the material gray levels. Output: the
    mesh with a ``material`` cell array (0..K-1 by ascending mean gray) and field data
    ``material_gray``. Parameters: NumberOfMaterials (0 = found from the data), Lambda (70),
    Beta (0.286), and SetParameter(name, value) for any other keyword of
    :func:`ctseg.pipeline.label_mesh`.
    """

    def __init__(self):
        super().__init__(n_inputs=2, input_type="vtkDataObject", output_type="vtkPolyData")
        self._n_materials, self._lam, self._beta = 0, 70.0, 0.286
        self._extra = {}

    def FillInputPortInformation(self, port, info):
        info.Set(self.INPUT_REQUIRED_DATA_TYPE(), "vtkPolyData" if port == 0 else "vtkImageData")
        return 1

    SetNumberOfMaterials, GetNumberOfMaterials = parameter("_n_materials", _optional_int,
                                                           "0 = found from the data")
    SetLambda, GetLambda = parameter("_lam", float, "n-link weight (paper: 70)")
    SetBeta, GetBeta = parameter("_beta", float, "distance term weight (paper: 0.286)")

    def SetParameter(self, name, value):
        """Any other keyword of :func:`ctseg.pipeline.label_mesh` (e.g. 'theta')."""
        if self._extra.get(name, object()) != value:
            self._extra = {**self._extra, name: value}
            self.Modified()

    def _request(self, request, in_info, out_info):
        mesh_in = vtkPolyData.GetData(in_info[0], 0)
        arr, geom, _ = self._input_slice(in_info, port=1)
        xyz, tri, arrays = polydata_to_arrays(mesh_in)
        if "gray" not in arrays:
            raise InputError("mesh: no 'gray' cell array; connect a TriangleGrayFilter first")
        mesh = triangle_mesh(mesh_index_coordinates(xyz, geom, arr.shape), tri)
        self.UpdateProgress(0.0)
        labels = label_mesh(arr, mesh, arrays["gray"], n_materials=self._n_materials or None,
                            lam=self._lam, beta=self._beta, **self._extra)
        out = self._output_poly(out_info)
        out.ShallowCopy(mesh_in)
        _add_cell_array(out, labels.material.astype("int32"), "material")
        out.GetCellData().SetActiveScalars("material")
        mg = numpy_support.numpy_to_vtk(labels.material_gray, deep=True)
        mg.SetName("material_gray")
        out.GetFieldData().AddArray(mg)
        self.UpdateProgress(1.0)
