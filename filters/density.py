"""Stage 1 as a VTK filter: vtkImageData -> the same image with a ``density`` point array."""
from vtkmodules.vtkCommonDataModel import vtkImageData

from ctseg.density import density_map

from .base import CTSegAlgorithm, spec_names
from .convert import _point_array


class DensityMapFilter(CTSegAlgorithm):
    """Gradient density map of a one-slice image (:func:`ctseg.density_map`, SPEC 1).

    Output: the input image (shallow copy) with a ``density`` point array (float64).
    Parameters: the spec's density group (``ctseg params``): DensitySigma, DensityFloor,
    DensitySaturation, DensityRidge, each with Set/Get and through
    SetParameter(name, value).
    """

    PARAMETERS = spec_names("density")

    def __init__(self):
        super().__init__(input_type="vtkImageData", output_type="vtkImageData")

    def density_kwargs(self):
        """The keywords of :func:`ctseg.density_map` this filter passes."""
        return self.GetParameters()

    def _request(self, request, in_info, out_info):
        arr, _, image = self._input_slice(in_info)
        self.UpdateProgress(0.0)
        rho = density_map(arr, **self.density_kwargs())
        out = vtkImageData.GetData(out_info, 0)
        out.ShallowCopy(image)
        out.GetPointData().AddArray(_point_array(rho, "density"))
        self.UpdateProgress(1.0)
