"""The composite filter: vtkImageData (one 2D slice) -> segmented vtkPolyData."""
from vtkmodules.vtkCommonDataModel import vtkImageData, vtkPolyData

from ctseg.errors import InputError
from ctseg.pipeline import segment_image

from .base import CTSegAlgorithm
from .convert import image_to_array, mesh_to_polydata


class CTSegmentFilter(CTSegAlgorithm):
    """Segment a one-slice vtkImageData into a triangle mesh (Yang et al. 2014).

    Output: vtkPolyData in world coordinates (the image's origin, spacing and direction)
    with cell arrays ``material``, ``gray`` and ``slice``. Parameters: NumberOfSites (0 =
    default, one per 128 pixels), Seed, NumberOfMaterials (0 = found from the data).
    Volumes (more than one slice) come with the slice-by-slice filter.
    """

    def __init__(self):
        super().__init__(input_type="vtkImageData", output_type="vtkPolyData")
        self._n_sites = 0
        self._seed = 0
        self._n_materials = 0
        self.result = None  # the last SegmentedMesh, diagnostics included

    def SetNumberOfSites(self, n):
        self._set("_n_sites", int(n))

    def GetNumberOfSites(self):
        return self._n_sites

    def SetSeed(self, seed):
        self._set("_seed", int(seed))

    def GetSeed(self):
        return self._seed

    def SetNumberOfMaterials(self, k):
        self._set("_n_materials", int(k))

    def GetNumberOfMaterials(self):
        return self._n_materials

    def _request(self, request, in_info, out_info):
        image = vtkImageData.GetData(in_info[0], 0)
        output = vtkPolyData.GetData(out_info, 0)
        arr, geom = image_to_array(image)
        if arr.ndim != 2:
            raise InputError(f"image: {arr.shape[0]} slices; this filter takes one slice")
        self.UpdateProgress(0.0)
        seg = segment_image(arr, n_sites=self._n_sites or None, seed=self._seed,
                            n_materials=self._n_materials or None,
                            progress=lambda frac, stage: self.UpdateProgress(frac))
        self.result = seg
        output.ShallowCopy(mesh_to_polydata(seg.points, seg.triangles, seg.material, seg.gray,
                                            geom))
