"""The composite filter: vtkImageData (a slice or a volume) -> segmented vtkPolyData."""
from ctseg.pipeline import SEGMENT_DEFAULTS, segment_image
from ctseg.errors import ParameterError
from ctseg.volume import segment_volume, slice_axis

from .base import CTSegAlgorithm, parameter
from .convert import image_to_array, segmentation_to_polydata


def _axis_name(axis):
    return "zyx"[slice_axis(axis)]


class CTSegmentFilter(CTSegAlgorithm):
    """Segment a vtkImageData into a triangle mesh with one material per triangle
    (Yang et al. 2014): :func:`ctseg.segment_image` for one slice,
    :func:`ctseg.volume.segment_volume` slice by slice for a volume.

    Output 0: the mesh in world coordinates (the image's origin, spacing and direction) with
    cell arrays ``material`` (0..K-1, one numbering for the whole volume), ``gray`` (input
    units) and ``slice``. Output 1: the material boundaries as polylines with
    ``material_a``, ``material_b`` and ``slice``.

    Parameters: NumberOfSites (per slice; 0 = one per 128 pixels), Seed,
    NumberOfMaterials (0 = found from the data), SliceAxis ('z', 'y' or 'x'),
    NumberOfJobs (local worker processes for volumes; 1 = this process, 0 = one per core),
    DaskClient (a ``distributed.Client`` or a scheduler address; slices then run on that
    cluster), and SetParameter(name, value) for any other keyword of
    :func:`ctseg.segment_image`.
    """

    def __init__(self):
        super().__init__(input_type="vtkImageData", n_outputs=2, output_type="vtkPolyData")
        self._n_sites, self._seed, self._n_materials = 0, 0, 0
        self._axis, self._n_jobs, self._client = "z", 1, None
        self._extra = {}
        self.result = None  # the last SegmentedMesh or VolumeSegmentation

    SetNumberOfSites, GetNumberOfSites = parameter("_n_sites", int, "per slice; 0 = one per 128 pixels")
    SetSeed, GetSeed = parameter("_seed", int, "seed of the random initialisations")
    SetNumberOfMaterials, GetNumberOfMaterials = parameter("_n_materials", int,
                                                           "0 = found from the data")
    SetSliceAxis, GetSliceAxis = parameter("_axis", _axis_name, "'z', 'y' or 'x'")
    SetNumberOfJobs, GetNumberOfJobs = parameter("_n_jobs", int,
                                                 "worker processes (1 = this one, 0 = all cores)")

    def SetDaskClient(self, client):
        """A distributed.Client or a scheduler address ('tcp://host:8786'); None = local."""
        if client is not self._client:
            self._client = client
            self.Modified()

    def GetDaskClient(self):
        return self._client

    def SetParameter(self, name, value):
        """Any other keyword of :func:`ctseg.segment_image` (e.g. 'lam', 'density_ridge')."""
        if name not in SEGMENT_DEFAULTS or name == "n_materials":
            raise ParameterError(f"{name}: not a parameter of ctseg.segment_image; valid: "
                                 f"{', '.join(sorted(set(SEGMENT_DEFAULTS) - {'n_materials'}))}")
        if self._extra.get(name, object()) != value:
            self._extra = {**self._extra, name: value}
            self.Modified()

    def GetParameter(self, name):
        return self._extra.get(name, SEGMENT_DEFAULTS.get(name))

    def _request(self, request, in_info, out_info):
        arr, geom = image_to_array(self._input(in_info))
        self.UpdateProgress(0.0)
        kwargs = dict(n_sites=self._n_sites or None, seed=self._seed,
                      n_materials=self._n_materials or None, **self._extra)
        progress = lambda frac, stage: self.UpdateProgress(frac)
        if arr.ndim == 2:
            result = segment_image(arr, progress=progress, **kwargs)
        else:
            result = segment_volume(arr, axis=self._axis, n_jobs=self._n_jobs,
                                    client=self._client, progress=progress, **kwargs)
        self.result = result
        mesh, boundary = segmentation_to_polydata(result, geom)
        self._output_poly(out_info, 0).ShallowCopy(mesh)
        self._output_poly(out_info, 1).ShallowCopy(boundary)
