"""The metal streak correction as a VTK filter: vtkImageData -> the corrected vtkImageData."""
from vtkmodules.util import numpy_support
from vtkmodules.vtkCommonDataModel import vtkImageData

from ctseg.pipeline import correct_streaks

from .base import CTSegAlgorithm, parameter


class MetalStreakFilter(CTSegAlgorithm):
    """Remove the beam-hardening streaks of the densest material from a one-slice image
    (:func:`ctseg.pipeline.correct_streaks`, the first stage of :func:`ctseg.segment_image`).

    Output: the image with the corrected values as its point scalars (named as the input's,
    float64), the input's values kept as an ``original`` point array, and field data
    ``streak_weight``, ``streak_explained`` (share of within-material variance removed)
    and ``streak_max_change`` (0 when nothing was corrected). Connect the output where the
    later stages (density map, triangle gray, graph cut) take the image.
    Parameter: Sigma (px, 1; the smoothing before pixels are classified).
    """

    def __init__(self):
        super().__init__(input_type="vtkImageData", output_type="vtkImageData")
        self._sigma = 1.0

    SetSigma, GetSigma = parameter("_sigma", float, "Gaussian smoothing before classifying, px")

    def _request(self, request, in_info, out_info):
        arr, _, image = self._input_slice(in_info)
        self.UpdateProgress(0.0)
        fix = correct_streaks(arr, sigma=self._sigma)
        out = vtkImageData.GetData(out_info, 0)
        out.ShallowCopy(image)
        scalars = image.GetPointData().GetScalars()
        corrected = numpy_support.numpy_to_vtk(fix.image.ravel(), deep=True)
        corrected.SetName(scalars.GetName() or "scalars")
        original = numpy_support.numpy_to_vtk(arr.ravel(), deep=True)
        original.SetName("original")
        pd = out.GetPointData()
        if scalars.GetName():
            pd.RemoveArray(scalars.GetName())
        pd.AddArray(original)
        pd.SetScalars(corrected)
        for name, value in (("streak_weight", fix.weight), ("streak_explained", fix.explained),
                            ("streak_max_change", fix.max_change)):
            a = numpy_support.numpy_to_vtk([float(value)], deep=True)
            a.SetName(name)
            out.GetFieldData().AddArray(a)
        self.UpdateProgress(1.0)
