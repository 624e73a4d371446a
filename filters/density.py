"""Stage 1 as a VTK filter: vtkImageData -> the same image with a ``density`` point array."""
from vtkmodules.util import numpy_support
from vtkmodules.vtkCommonDataModel import vtkImageData

from ctseg.density import density_map

from .base import CTSegAlgorithm, parameter


def _saturation(value):
    """'auto', 'max' (the paper's normalisation by the largest gradient) or a fraction."""
    if value in ("auto", "max"):
        return value
    return float(value)


class DensityMapFilter(CTSegAlgorithm):
    """Gradient density map of a one-slice image (:func:`ctseg.density_map`, SPEC 1).

    Output: the input image (shallow copy) with a ``density`` point array (float64).
    Parameters: Sigma (px, 1), Floor (0.02), Saturation ('auto', 'max' or a fraction of the
    largest gradient), Ridge (2; 0 = the paper's map).
    """

    def __init__(self):
        super().__init__(input_type="vtkImageData", output_type="vtkImageData")
        self._sigma, self._floor, self._saturation, self._ridge = 1.0, 0.02, "auto", 2.0

    SetSigma, GetSigma = parameter("_sigma", float, "Gaussian pre-smoothing, px")
    SetFloor, GetFloor = parameter("_floor", float, "density added everywhere (> 0)")
    SetSaturation, GetSaturation = parameter("_saturation", _saturation,
                                             "'auto', 'max' or a fraction of the largest gradient")
    SetRidge, GetRidge = parameter("_ridge", float, "ridge sharpening exponent (0 = off)")

    def density_kwargs(self):
        """The keywords of :func:`ctseg.density_map` this filter passes."""
        sat = None if self._saturation == "max" else self._saturation
        return dict(sigma=self._sigma, floor=self._floor, saturation=sat, ridge=self._ridge)

    def _request(self, request, in_info, out_info):
        arr, _, image = self._input_slice(in_info)
        self.UpdateProgress(0.0)
        rho = density_map(arr, **self.density_kwargs())
        out = vtkImageData.GetData(out_info, 0)
        out.ShallowCopy(image)
        vtk_rho = numpy_support.numpy_to_vtk(rho.ravel(), deep=True)
        vtk_rho.SetName("density")
        out.GetPointData().AddArray(vtk_rho)
        self.UpdateProgress(1.0)
