"""Stage 5 as a VTK filter: mesh + image -> the mesh with each element's mean gray
(triangles over a slice, or tetrahedra over a volume)."""
import numpy as np
from vtkmodules.vtkCommonDataModel import vtkDataObject, vtkPolyData, vtkUnstructuredGrid

from ctseg.errors import InputError
from ctseg.tetra_gray import tetra_gray
from ctseg.triangle_gray import triangle_gray

from .base import CTSegAlgorithm
from .convert import _add_cell_array, _field_array, _points, mesh_index_coordinates, polydata_to_arrays
from .convert3d import grid_to_arrays
from .density import image_input
from .sites import add_box_points, box_points


def tetra_box_coordinates(grid, tetrahedra, geometry, shape):
    """A tetrahedral grid over a volume -> the physical box coordinates of its points
    (:func:`ctseg.filters.sites.box_points`) and its tetrahedra oriented there (two
    vertices swapped back where the direction flips; the inverse of
    :func:`ctseg.filters.convert3d.world_tetrahedra`).

    Raises
    ------
    InputError
        Points outside the volume's box of voxel centres.
    """
    tets = np.asarray(tetrahedra, np.int64)
    if np.linalg.det(geometry.direction) < 0:
        tets = tets[:, [0, 2, 1, 3]]
    return box_points(grid, geometry, shape), tets


class MeshAndImageFilter(CTSegAlgorithm):
    """Base of the filters on a mesh (input 0) over an image (input 1): triangles
    (vtkPolyData) over a slice or tetrahedra (vtkUnstructuredGrid) over a volume. The
    output is of input 0's type; ``_slice`` or ``_volume`` handles each."""

    def __init__(self):
        super().__init__(n_inputs=2, input_type="vtkDataObject", output_type="vtkPointSet")

    def FillInputPortInformation(self, port, info):
        info.Set(self.INPUT_REQUIRED_DATA_TYPE(), "vtkPointSet" if port == 0 else "vtkImageData")
        return 1

    def FillOutputPortInformation(self, port, info):
        info.Set(vtkDataObject.DATA_TYPE_NAME(), "vtkPointSet")
        return 1

    def RequestDataObject(self, request, in_info, out_info):
        mesh = vtkDataObject.GetData(in_info[0], 0)
        grid = mesh is not None and mesh.IsA("vtkUnstructuredGrid")
        cls = vtkUnstructuredGrid if grid else vtkPolyData
        info = out_info.GetInformationObject(0)
        current = info.Get(vtkDataObject.DATA_OBJECT())
        if current is None or current.GetClassName() != cls.__name__:
            info.Set(vtkDataObject.DATA_OBJECT(), cls())
        return 1

    def _request(self, request, in_info, out_info):
        mesh_in = vtkDataObject.GetData(in_info[0], 0)
        arr, geom, _ = image_input(in_info, port=1, array_name=self.gray_array_name())
        grid = mesh_in is not None and mesh_in.IsA("vtkUnstructuredGrid")
        if not (grid or (mesh_in is not None and mesh_in.IsA("vtkPolyData"))):
            got = mesh_in.GetClassName() if mesh_in is not None else "nothing"
            raise InputError(f"input 0: {got}; expected vtkPolyData triangles or a "
                             "vtkUnstructuredGrid of tetrahedra")
        if grid != (arr.ndim == 3):
            raise InputError(
                f"image: shape {arr.shape} with a {mesh_in.GetClassName()} mesh; "
                f"{type(self).__name__} takes tetrahedra (vtkUnstructuredGrid) over a volume "
                "or triangles (vtkPolyData) over one slice")
        self.UpdateProgress(0.0)
        if grid:
            _, tets, arrays = grid_to_arrays(mesh_in)
            box, tets = tetra_box_coordinates(mesh_in, tets, geom, arr.shape)
            cells, fields, *moved = self._volume(np.asarray(arr, np.float64), geom.spacing,
                                                 box, tets, arrays)
        else:
            xyz, tri, arrays = polydata_to_arrays(mesh_in)
            cells, fields, *moved = self._slice(arr, geom, xyz, tri, arrays)
        out = vtkDataObject.GetData(out_info, 0)
        out.ShallowCopy(mesh_in)
        if grid and moved:  # new box coordinates of the volume's points, recorded exactly
            out.SetPoints(_points(geom.to_world(moved[0] / np.asarray(geom.spacing, float))))
            add_box_points(out, moved[0])
        elif moved:  # new (x, y) index points of the slice
            ijk = np.column_stack([moved[0], np.zeros(len(moved[0]))])
            out.SetPoints(_points(geom.to_world(ijk)))
        for name, values in cells.items():
            _add_cell_array(out, values, name)
        for name, values in fields.items():
            _field_array(out, name, values)
        if "material" in cells:
            out.GetCellData().SetActiveScalars("material")
        self.UpdateProgress(1.0)

    def _slice(self, image, geometry, xyz, triangles, arrays):
        """({cell array: values}, {field array: values}) of triangles over a slice, and
        optionally the moved points in (x, y) index coordinates."""
        raise NotImplementedError

    def _volume(self, volume, spacing, points, tetrahedra, arrays):
        """The same for tetrahedra (box coordinates) over a volume; the moved points in box
        coordinates."""
        raise NotImplementedError


class TriangleGrayFilter(MeshAndImageFilter):
    """Exact mean gray of every element over the image (SPEC 5 and 9.5).

    Input 0: a triangle mesh over a slice (DelaunayMeshFilter's output, or any mesh in the
    image's plane), or tetrahedra over a volume (a vtkUnstructuredGrid:
    DelaunayTetraFilter's output, or any tetrahedra inside the volume's box of voxel
    centres); input 1: the vtkImageData, the slice or the volume. Triangles get
    :func:`ctseg.triangle_gray` (area-weighted), tetrahedra
    :func:`ctseg.tetra_gray.tetra_gray` (volume-weighted, with the image's spacing), as
    CTSegmentFilter computes them. Output: the mesh (of input 0's type) with a ``gray``
    cell array in the image's units.
    """

    def _slice(self, image, geometry, xyz, triangles, arrays):
        points = mesh_index_coordinates(xyz, geometry, image.shape)
        return {"gray": triangle_gray(image, points, triangles)}, {}

    def _volume(self, volume, spacing, points, tetrahedra, arrays):
        return {"gray": tetra_gray(volume, points, tetrahedra, spacing)}, {}
