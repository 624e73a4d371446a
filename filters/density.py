"""Stage 1 as a VTK filter: vtkImageData (a slice or a volume) -> the same image with a
``density`` point array."""
import numpy as np
from vtkmodules.vtkCommonDataModel import vtkImageData

from ctseg.density import density_map
from ctseg.errors import InputError
from ctseg.stages3d import density_3d

from .base import CTSegAlgorithm, spec_names
from .convert import _point_array, image_to_array


def image_input(in_info, port=0, array_name=None):
    """The vtkImageData on ``port`` as (array, ImageGeometry, image): a (rows, cols) slice
    (z dimension 1) or an (nz, ny, nx) volume of at least 2 voxels along every axis (the
    3D stages' input).

    Raises
    ------
    InputError
        No image, or a volume with a side of one voxel (a slice not in the z plane).
    """
    image = vtkImageData.GetData(in_info[port], 0)
    if image is None:
        raise InputError(f"input {port}: expected a vtkImageData")
    arr, geom = image_to_array(image, array_name)
    if arr.ndim == 3 and min(arr.shape) < 2:
        raise InputError(f"image: shape {arr.shape} (z, y, x); a volume needs at least 2 "
                         "voxels along every axis, and a single slice must lie in the z plane")
    return arr, geom, image


class DensityMapFilter(CTSegAlgorithm):
    """Gradient density map of a slice or a volume (SPEC 1 and 9.1).

    Input: a vtkImageData. One slice (z dimension 1): :func:`ctseg.density_map` in pixel
    units, as the slices mode makes it. A volume (at least 2 voxels along every axis):
    :func:`ctseg.stages3d.density_3d` (:func:`ctseg.density.density_volume` with the
    image's spacing); the 3D mode then raises it below the densest material's level
    (:func:`ctseg.density_capped.capped_density_volume`), which needs the material levels
    that only the labelling stage finds, so this stage's density is the unraised one.
    Output: the input image (shallow copy) with a ``density`` point array (float64), for
    CVTSitesFilter.
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
        arr, geom, image = image_input(in_info, array_name=self.gray_array_name())
        self.UpdateProgress(0.0)
        if arr.ndim == 2:
            rho = density_map(arr, **self.density_kwargs())
        else:
            rho = density_3d(np.asarray(arr, np.float64), self.params, geom.spacing)
        out = vtkImageData.GetData(out_info, 0)
        out.ShallowCopy(image)
        out.GetPointData().AddArray(_point_array(rho, "density"))
        self.UpdateProgress(1.0)
