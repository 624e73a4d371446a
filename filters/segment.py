"""The composite filter: vtkImageData (a slice or a volume) -> segmented mesh: triangles
(slices mode) or tetrahedra (3D mode).

``segment_array`` (the one slice-or-volume dispatch of :mod:`ctseg.volume`) is offered here
too, so that the application plugins reach ctseg through the VTK layer only."""
from vtkmodules.vtkCommonDataModel import vtkDataObject, vtkPolyData, vtkUnstructuredGrid
from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline

from ctseg.errors import InputError
from ctseg.params import SPECS
from ctseg.volume import segment_array, volume_mode

from .base import CTSegAlgorithm
from .convert import image_to_array, segmentation_to_polydata
from .convert3d import tetra_segmentation_to_vtk


class CTSegmentFilter(CTSegAlgorithm):
    """Segment a vtkImageData into a mesh with one material per element (Yang et al.
    2014): :func:`ctseg.segment_image` for one slice, :func:`ctseg.volume.segment_volume`
    for a volume, in tetrahedra (:func:`ctseg.pipeline3d.segment_volume_3d`, with the
    image's spacing) or, with Mode 'slices', slice by slice.

    Slices mode: output 0 the triangle mesh (vtkPolyData) in world coordinates (the
    image's origin, spacing and direction) with cell arrays ``material`` (0..K-1, one
    numbering for the whole volume), ``gray`` (input units) and ``slice``; output 1 the
    material boundaries as polylines with ``material_a``, ``material_b`` and ``slice``.

    Mode 'auto' (the default) meshes a volume in 3D where the memory allows it and no Dask
    client is set (:func:`ctseg.volume.volume_mode`), else slice by slice, and a single
    slice in triangles.

    3D mode: output 0 the tetrahedra (vtkUnstructuredGrid) in world coordinates with
    ``material`` and ``gray``; output 1 the interface triangles (vtkPolyData) with
    ``material_a`` < ``material_b``, normals from a to b. Mode '3d' refuses a single slice.

    Parameters: every parameter of :mod:`ctseg.params` (``ctseg params`` lists them), each
    as Set/Get of its VTK name (SetNumberOfSites, SetLambda, SetSliceAxis, SetMode,
    SetNumberOfJobs, ...) and through SetParameter(name, value) by its spec name; and
    SetDaskClient (a ``distributed.Client`` or a scheduler address: a volume's slices then
    run on that cluster).
    """

    PARAMETERS = tuple(SPECS)

    def __init__(self):
        super().__init__(input_type="vtkImageData", n_outputs=2, output_type="vtkPolyData")
        self._client = None
        self.result = None  # the last SegmentedMesh, VolumeSegmentation or TetraSegmentation
        self._mode = None  # 'slices' or '3d', decided with the output's type

    def SetDaskClient(self, client):
        """A distributed.Client or a scheduler address ('tcp://host:8786'); None = local."""
        if client is not self._client:
            self._client = client
            self.Modified()

    def GetDaskClient(self):
        """The Dask client or scheduler address set, or None."""
        return self._client

    # output 0 is a vtkPolyData or a vtkUnstructuredGrid by Mode: declared as any data
    # object, made concrete in RequestDataObject (VTK fixes the type per port otherwise)
    def FillOutputPortInformation(self, port, info):
        info.Set(vtkDataObject.DATA_TYPE_NAME(), "vtkDataObject" if port == 0 else "vtkPolyData")
        return 1

    def RequestDataObject(self, request, in_info, out_info):
        # Mode 'auto' needs the input's shape, which upstream tells only in its information
        # pass: run it now (the pipeline runs it next anyway), so the shape is never stale
        ext = None
        if self.GetNumberOfInputConnections(0):
            self.GetInputAlgorithm(0, 0).UpdateInformation()
            ext = in_info[0].GetInformationObject(0).Get(vtkStreamingDemandDrivenPipeline.WHOLE_EXTENT())
        dims = [ext[2 * a + 1] - ext[2 * a] + 1 for a in range(3)] if ext else [1, 1, 1]
        shape = tuple(dims[::-1]) if dims[2] > 1 else (dims[1], dims[0])
        self._mode = volume_mode(shape, self.params.mode, ["DaskClient"] if self._client else [])[0]
        types = (vtkUnstructuredGrid if self._mode == "3d" else vtkPolyData, vtkPolyData)
        for port, cls in enumerate(types):
            info = out_info.GetInformationObject(port)
            current = info.Get(vtkDataObject.DATA_OBJECT())
            if current is None or current.GetClassName() != cls.__name__:
                info.Set(vtkDataObject.DATA_OBJECT(), cls())
        return 1

    def _request(self, request, in_info, out_info):
        arr, geom = image_to_array(self._input(in_info), self.gray_array_name())
        three_d = self._mode == "3d"  # as the output's type was chosen
        if three_d and arr.ndim != 3:
            raise InputError(f"image: shape {arr.shape} is one slice; Mode '3d' needs a volume "
                             "of at least 2 voxels along every axis (use Mode 'slices')")
        self.UpdateProgress(0.0)
        params = self.params.replace(mode=self._mode) if arr.ndim == 3 else self.params
        result = segment_array(arr, params, spacing=geom.spacing, client=self._client,
                               progress=self._progress())
        self.result = result
        if three_d:
            mesh, second = tetra_segmentation_to_vtk(result, geom)
        else:
            mesh, second = segmentation_to_polydata(result, geom)
        vtkDataObject.GetData(out_info, 0).ShallowCopy(mesh)
        self._output_poly(out_info, 1).ShallowCopy(second)
        self.UpdateProgress(1.0)
