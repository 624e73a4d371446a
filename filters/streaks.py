"""The metal streak correction as a VTK filter: vtkImageData -> the corrected vtkImageData."""
from vtkmodules.vtkCommonDataModel import vtkImageData

from ctseg.beam_hardening import correct_streaks

from .base import CTSegAlgorithm, spec_names
from .convert import _field_array, _point_array, gray_array


class MetalStreakFilter(CTSegAlgorithm):
    """Remove the beam-hardening streaks of the densest material from a one-slice image
    (:func:`ctseg.beam_hardening.correct_streaks`, the first stage of
    :func:`ctseg.segment_image`).

    Output: the image with the corrected values as its point scalars (named as the input's,
    float64), the input's values kept as an ``original`` point array, and field data
    ``streak_weight``, ``streak_explained`` (share of within-material variance removed)
    ``streak_max_change`` (0 when nothing was corrected) and ``streak_halo_px``, the width
    of the glow taken off (0 when none). Connect the output where the
    later stages (density map, triangle gray, graph cut) take the image.
    Parameters: what ``correct_streaks`` reads (``ctseg params``): the levels group
    (which tells the materials apart), DensityFloor and DensitySaturation (which find the
    flat pixels), StreakSigma, StreakMargin, StreakRounds, StreakMinExplained, StreakModel,
    StreakMinGain.
    """

    PARAMETERS = spec_names("levels", names=(
        "density_floor", "density_saturation", "streak_sigma_px", "streak_margin_px",
        "streak_rounds", "streak_min_explained", "streak_model", "streak_min_gain"))

    def __init__(self):
        super().__init__(input_type="vtkImageData", output_type="vtkImageData")

    def _request(self, request, in_info, out_info):
        arr, _, image = self._input_slice(in_info)
        self.UpdateProgress(0.0)
        fix = correct_streaks(arr, self.params)
        out = vtkImageData.GetData(out_info, 0)
        out.ShallowCopy(image)
        scalars = gray_array(image.GetPointData(), self.gray_array_name())
        pd = out.GetPointData()
        if scalars.GetName():
            pd.RemoveArray(scalars.GetName())
        pd.AddArray(_point_array(arr, "original"))
        active = pd.GetScalars()  # another array than the one corrected: SetScalars drops it
        pd.SetScalars(_point_array(fix.image, scalars.GetName() or "scalars"))
        if active is not None:
            pd.AddArray(active)
        for name, value in (("streak_weight", fix.weight), ("streak_explained", fix.explained),
                            ("streak_max_change", fix.max_change),
                            ("streak_halo_px", fix.halo_px)):
            _field_array(out, name, float(value))
        self.UpdateProgress(1.0)
