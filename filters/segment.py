"""The composite filter: vtkImageData (a slice or a volume) -> segmented vtkPolyData.

``segment_array`` (the one slice-or-volume dispatch of :mod:`ctseg.volume`) is offered here
too, so that the application plugins reach ctseg through the VTK layer only."""
from ctseg.params import SPECS
from ctseg.volume import segment_array

from .base import CTSegAlgorithm
from .convert import image_to_array, segmentation_to_polydata


class CTSegmentFilter(CTSegAlgorithm):
    """Segment a vtkImageData into a triangle mesh with one material per triangle
    (Yang et al. 2014): :func:`ctseg.segment_image` for one slice,
    :func:`ctseg.volume.segment_volume` slice by slice for a volume.

    Output 0: the mesh in world coordinates (the image's origin, spacing and direction) with
    cell arrays ``material`` (0..K-1, one numbering for the whole volume), ``gray`` (input
    units) and ``slice``. Output 1: the material boundaries as polylines with
    ``material_a``, ``material_b`` and ``slice``.

    Parameters: every parameter of :mod:`ctseg.params` (``ctseg params`` lists them), each
    as Set/Get of its VTK name (SetNumberOfSites, SetLambda, SetSliceAxis,
    SetNumberOfJobs, ...) and through SetParameter(name, value) by its spec name; and
    SetDaskClient (a ``distributed.Client`` or a scheduler address: a volume's slices then
    run on that cluster).
    """

    PARAMETERS = tuple(SPECS)

    def __init__(self):
        super().__init__(input_type="vtkImageData", n_outputs=2, output_type="vtkPolyData")
        self._client = None
        self.result = None  # the last SegmentedMesh or VolumeSegmentation

    def SetDaskClient(self, client):
        """A distributed.Client or a scheduler address ('tcp://host:8786'); None = local."""
        if client is not self._client:
            self._client = client
            self.Modified()

    def GetDaskClient(self):
        """The Dask client or scheduler address set, or None."""
        return self._client

    def _request(self, request, in_info, out_info):
        arr, geom = image_to_array(self._input(in_info))
        self.UpdateProgress(0.0)
        result = segment_array(arr, self.params, client=self._client,
                               progress=self._progress())
        self.result = result
        mesh, boundary = segmentation_to_polydata(result, geom)
        self._output_poly(out_info, 0).ShallowCopy(mesh)
        self._output_poly(out_info, 1).ShallowCopy(boundary)
