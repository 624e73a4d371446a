"""Stages 6-7 as a VTK filter: mesh with ``gray`` + image -> one material per triangle."""
from vtkmodules.vtkCommonDataModel import vtkPolyData

from ctseg.errors import InputError
from ctseg.labelling import label_mesh
from ctseg.triangulation import triangle_mesh

from .base import CTSegAlgorithm, spec_names
from .convert import _add_cell_array, _field_array, mesh_index_coordinates, polydata_to_arrays


class GraphCutSegmentFilter(CTSegAlgorithm):
    """Recursive graph cut of the triangles into materials (:func:`ctseg.label_mesh`,
    SPEC 6-7).

    Input 0: the mesh with a ``gray`` cell array (TriangleGrayFilter's output); input 1:
    the one-slice vtkImageData, whose flat pixels give the material gray levels. Output: the
    mesh with a ``material`` cell array (0..K-1 by ascending mean gray) and field data
    ``material_gray``. Parameters: what ``label_mesh`` reads (``ctseg params``): the
    levels, graphcut and recursion groups (NumberOfMaterials, Lambda, Beta, ...),
    DensityFloor and DensitySaturation (which find the flat pixels), and the blur
    correction (BlurCorrection, BlurMinSelfWeight, BlurMax).
    """

    PARAMETERS = spec_names("levels", "graphcut", "recursion", names=(
        "density_floor", "density_saturation", "blur_correction", "blur_min_self_weight",
        "blur_max_px"))

    def __init__(self):
        super().__init__(n_inputs=2, input_type="vtkDataObject", output_type="vtkPolyData")

    def FillInputPortInformation(self, port, info):
        info.Set(self.INPUT_REQUIRED_DATA_TYPE(), "vtkPolyData" if port == 0 else "vtkImageData")
        return 1

    def _request(self, request, in_info, out_info):
        mesh_in = vtkPolyData.GetData(in_info[0], 0)
        arr, geom, _ = self._input_slice(in_info, port=1)
        xyz, tri, arrays = polydata_to_arrays(mesh_in)
        if "gray" not in arrays:
            raise InputError("mesh: no 'gray' cell array; connect a TriangleGrayFilter first")
        mesh = triangle_mesh(mesh_index_coordinates(xyz, geom, arr.shape), tri)
        self.UpdateProgress(0.0)
        labels = label_mesh(arr, mesh, arrays["gray"], self.params)
        out = self._output_poly(out_info)
        out.ShallowCopy(mesh_in)
        _add_cell_array(out, labels.material.astype("int32"), "material")
        out.GetCellData().SetActiveScalars("material")
        _field_array(out, "material_gray", labels.material_gray)
        self.UpdateProgress(1.0)
