"""numpy <-> VTK conversions that keep world geometry (origin, spacing, direction).

The geometry itself is :class:`ctseg.geometry.ImageGeometry` (no VTK); this module moves it
onto and off vtkImageData and field data."""
import numpy as np
from vtkmodules.util import numpy_support
from vtkmodules.vtkCommonCore import vtkPoints
from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkImageData, vtkPolyData

from ctseg.errors import InputError
from ctseg.geometry import ImageGeometry, slice_to_volume_index


GEOMETRY_FIELD = "ctseg_geometry"
"""Name of the field-data array that carries an image's geometry downstream."""


def attach_geometry(data, geometry, shape):
    """Record ``geometry`` and the (rows, cols) ``shape`` of its slice in ``data``'s field
    data, so that a filter downstream (Delaunay on CVT sites) can work in index
    coordinates."""
    values = np.concatenate([geometry.origin, geometry.spacing, geometry.direction.ravel(),
                             shape])
    arr = numpy_support.numpy_to_vtk(values.astype(np.float64), deep=True)
    arr.SetName(GEOMETRY_FIELD)
    data.GetFieldData().AddArray(arr)


def geometry_from_field_data(data):
    """(ImageGeometry, (rows, cols)) recorded by :func:`attach_geometry`.

    Raises
    ------
    InputError
        ``data`` carries no recorded geometry.
    """
    arr = data.GetFieldData().GetArray(GEOMETRY_FIELD)
    if arr is None:
        raise InputError("polydata: no image geometry recorded (the input must come "
                         "from a ctseg filter such as CVTSitesFilter)")
    v = numpy_support.vtk_to_numpy(arr)
    return ImageGeometry(v[0:3], v[3:6], v[6:15].reshape(3, 3)), (int(v[15]), int(v[16]))


def gray_array(point_data, array_name=None):
    """The point array read as the gray values: ``array_name`` if given, else the active
    scalars (None where there is none)."""
    return point_data.GetArray(array_name) if array_name else point_data.GetScalars()


def image_to_array(image, array_name=None):
    """vtkImageData (one scalar component) -> (array, ImageGeometry).

    A 2D image (z dimension 1) gives an array of shape (rows=ny, cols=nx), row j = VTK j;
    a volume gives (nz, ny, nx). Array index 0 is the extent's first point (a cropped image,
    as vtkExtractVOI gives, starts elsewhere): the geometry's origin is that point's.
    The gray values are the point array ``array_name`` (what a filter's
    ``SetInputArrayToProcess`` chose), else the active point scalars. Multi-component
    arrays are refused here.
    """
    dims = image.GetDimensions()
    pd = image.GetPointData()
    scalars = gray_array(pd, array_name)
    if scalars is None:
        names = ", ".join(str(pd.GetArrayName(i)) for i in range(pd.GetNumberOfArrays()))
        if array_name:
            raise InputError(f"image: no point array named {array_name!r} (its point arrays: "
                             f"{names or 'none'})")
        raise InputError("image: the vtkImageData has no active point scalars"
                         + (f" (its point arrays: {names}; make one active)" if names else
                            " (cell data? convert with vtkCellDataToPointData)"
                            if image.GetCellData().GetNumberOfArrays() else ""))
    if scalars.GetNumberOfComponents() != 1:
        raise InputError(
            f"image: {scalars.GetNumberOfComponents()} components per pixel; ctseg needs one "
            "gray value per pixel (convert colour images to gray first)")
    arr = numpy_support.vtk_to_numpy(scalars).reshape(dims[2], dims[1], dims[0])
    if dims[2] == 1:
        arr = arr[0]
    direction = np.eye(3)
    if hasattr(image, "GetDirectionMatrix"):
        m = image.GetDirectionMatrix()
        direction = np.array([[m.GetElement(r, c) for c in range(3)] for r in range(3)])
    spacing = np.array(image.GetSpacing(), float)
    first = np.array(image.GetExtent()[::2], float)  # VTK's index of array index 0
    origin = np.array(image.GetOrigin(), float) + direction @ (first * spacing)
    return arr.copy(), ImageGeometry(origin, spacing, direction)


def array_to_image(array, geometry=None, name="scalars", components=1):
    """A numpy array -> vtkImageData with the given geometry: the one way ctseg builds
    an image.

    Parameters
    ----------
    array : array_like
        (rows, cols) or (nz, rows, cols); with ``components > 1`` one more trailing axis of
        that length (e.g. (rows, cols, 3) for RGB). Row j is VTK's j, slice k VTK's k.
    geometry : ImageGeometry, optional
        Origin, spacing and direction (default: the identity geometry).
    name : str
        Name of the point scalars.
    components : int
        Values per pixel.

    Returns
    -------
    vtkImageData

    Raises
    ------
    InputError
        An array of another shape.
    """
    arr = np.ascontiguousarray(array)
    spatial = arr.ndim - (1 if components > 1 else 0)
    if components > 1 and (arr.ndim < 3 or arr.shape[-1] != components):
        raise InputError(f"image: expected a trailing axis of {components} components, got "
                         f"shape {arr.shape}")
    if spatial == 2:
        arr = arr[None]
    if arr.ndim - (1 if components > 1 else 0) != 3:
        raise InputError(f"image: expected a 2D or 3D array, got shape {arr.shape}")
    geometry = geometry or ImageGeometry()
    img = vtkImageData()
    img.SetDimensions(arr.shape[2], arr.shape[1], arr.shape[0])
    img.SetOrigin(geometry.origin)
    img.SetSpacing(geometry.spacing)
    if hasattr(img, "SetDirectionMatrix"):
        img.SetDirectionMatrix(geometry.direction.ravel().tolist())
    flat = arr.reshape(-1, components) if components > 1 else arr.ravel()
    vtk_arr = numpy_support.numpy_to_vtk(flat, deep=True)
    vtk_arr.SetName(name)
    img.GetPointData().SetScalars(vtk_arr)
    return img


def _field_array(data, name, values):
    """Add ``values`` (a number or a 1D array) to ``data``'s field data as ``name``."""
    arr = numpy_support.numpy_to_vtk(np.atleast_1d(np.asarray(values, np.float64)), deep=True)
    arr.SetName(name)
    data.GetFieldData().AddArray(arr)


def _point_array(values, name):
    """A named VTK array of per-pixel values (ravelled in VTK's point order)."""
    arr = numpy_support.numpy_to_vtk(np.ascontiguousarray(values).ravel(), deep=True)
    arr.SetName(name)
    return arr


def _points(xyz):
    pts = vtkPoints()
    pts.SetData(numpy_support.numpy_to_vtk(np.ascontiguousarray(xyz, dtype=np.float64), deep=True))
    return pts


def _cells(conn, size):
    conn = np.asarray(conn, dtype=np.int64)
    ca = vtkCellArray()
    n = len(conn) // size if size else 0
    offsets = np.arange(0, n * size + 1, size, dtype=np.int64)
    ca.SetData(numpy_support.numpy_to_vtkIdTypeArray(offsets, deep=True),
               numpy_support.numpy_to_vtkIdTypeArray(conn.astype(np.int64), deep=True))
    return ca


def _add_cell_array(poly, values, name, vtk_type=None):
    arr = numpy_support.numpy_to_vtk(np.ascontiguousarray(values), deep=True,
                                     array_type=vtk_type)
    arr.SetName(name)
    poly.GetCellData().AddArray(arr)


def _world_points(points, geometry, axis, slice_index):
    return geometry.to_world(slice_to_volume_index(points, axis, slice_index))


def mesh_to_polydata(points, triangles, material, gray, geometry=None, slice_index=0, axis=0):
    """Triangle mesh of one slice, in its pixel-index coordinates -> vtkPolyData in world
    coordinates.

    The slice is number ``slice_index`` along ``axis`` ('z', 'y', 'x', or the numpy axis
    0, 1, 2; default 0, z) of the image the geometry belongs to (see
    :func:`ctseg.geometry.volume_slice` for the orientation of each axis); a 2D image is
    slice 0 along z. Cell arrays: ``material`` (int32), ``gray`` (float64, input units),
    ``slice`` (int32).
    """
    geometry = geometry or ImageGeometry()
    poly = vtkPolyData()
    poly.SetPoints(_points(_world_points(points, geometry, axis, slice_index)))
    poly.SetPolys(_cells(np.asarray(triangles).ravel(), 3))
    _add_cell_array(poly, np.asarray(material, np.int32), "material")
    _add_cell_array(poly, np.asarray(gray, np.float64), "gray")
    _add_cell_array(poly, np.full(len(triangles), slice_index, np.int32), "slice")
    poly.GetCellData().SetActiveScalars("material")
    return poly


def boundary_to_polydata(points, lines, sides, geometry=None, slice_index=0, axis=0):
    """Boundary polylines (lists of vertex indices) of one slice, in its pixel-index
    coordinates -> vtkPolyData with lines in world coordinates (see
    :func:`boundary_lines_to_polydata`)."""
    geometry = geometry or ImageGeometry()
    return boundary_lines_to_polydata(_world_points(points, geometry, axis, slice_index), lines,
                                      sides, np.full(len(lines), slice_index))


def boundary_lines_to_polydata(xyz, lines, sides, line_slice=None):
    """Polylines on world points -> vtkPolyData with cell arrays ``material_a`` and
    ``material_b`` (the materials on each side) and ``slice``."""
    poly = vtkPolyData()
    poly.SetPoints(_points(xyz))
    ca = vtkCellArray()
    if lines:
        offsets = np.concatenate([[0], np.cumsum([len(l) for l in lines])]).astype(np.int64)
        conn = np.concatenate(lines).astype(np.int64)
        ca.SetData(numpy_support.numpy_to_vtkIdTypeArray(offsets, deep=True),
                   numpy_support.numpy_to_vtkIdTypeArray(conn, deep=True))
    poly.SetLines(ca)
    sides = np.asarray(sides, np.int32).reshape(-1, 2)
    _add_cell_array(poly, np.ascontiguousarray(sides[:, 0]), "material_a")
    _add_cell_array(poly, np.ascontiguousarray(sides[:, 1]), "material_b")
    line_slice = np.zeros(len(sides)) if line_slice is None else line_slice
    _add_cell_array(poly, np.asarray(line_slice, np.int32), "slice")
    return poly


def mesh_index_coordinates(xyz, geometry, shape, tol_px=1e-6):
    """World points of a mesh over a one-slice image -> (x=col, y=row) index coordinates.

    Raises
    ------
    InputError
        Points off the slice's plane or outside its rectangle of pixel centres.
    """
    ijk = geometry.to_index(xyz)
    rows, cols = shape
    if len(ijk) and np.abs(ijk[:, 2]).max() > tol_px * max(rows, cols):
        raise InputError("mesh: its points are not in the image's plane")
    if len(ijk) and (ijk[:, 0].min() < -tol_px or ijk[:, 1].min() < -tol_px
                     or ijk[:, 0].max() > cols - 1 + tol_px or ijk[:, 1].max() > rows - 1 + tol_px):
        raise InputError("mesh: its points lie outside the image")
    return np.clip(ijk[:, :2], 0, [cols - 1, rows - 1])


def append_polydata(parts):
    """One vtkPolyData from several (the slices of a volume), cell arrays kept."""
    from vtkmodules.vtkFiltersCore import vtkAppendPolyData

    parts = list(parts)
    if len(parts) == 1:
        return parts[0]
    app = vtkAppendPolyData()
    for p in parts:
        app.AddInputData(p)
    app.Update()
    out = vtkPolyData()
    out.ShallowCopy(app.GetOutput())
    if out.GetCellData().GetArray("material") is not None:
        out.GetCellData().SetActiveScalars("material")
    return out


def segmentation_to_polydata(result, geometry=None):
    """A :class:`ctseg.SegmentedMesh` (2D image) or :class:`ctseg.volume.VolumeSegmentation`
    -> (mesh vtkPolyData, boundary vtkPolyData), all slices in one of each."""
    if hasattr(result, "tetrahedra"):
        raise InputError("segmentation_to_polydata: a 3D (tetrahedral) segmentation; use "
                         "ctseg.filters.tetra_segmentation_to_vtk")
    slices = getattr(result, "slices", None)
    axis = result.axis if slices is not None else 0  # numpy axis; a 2D image is along z
    slices = slices if slices is not None else [result]
    meshes, bounds = [], []
    for k, seg in enumerate(slices):
        meshes.append(mesh_to_polydata(seg.points, seg.triangles, seg.material, seg.gray,
                                       geometry, slice_index=k, axis=axis))
        lines, sides = seg.boundary_polylines()
        bounds.append(boundary_to_polydata(seg.points, lines, sides, geometry, slice_index=k,
                                           axis=axis))
    return append_polydata(meshes), append_polydata(bounds)


def polydata_to_arrays(poly):
    """vtkPolyData of triangles -> (points (n, 3), triangles (m, 3), {cell array name: values})."""
    pts = numpy_support.vtk_to_numpy(poly.GetPoints().GetData()) if poly.GetPoints() else np.zeros((0, 3))
    polys = poly.GetPolys()
    if polys.GetNumberOfCells():
        conn = numpy_support.vtk_to_numpy(polys.GetConnectivityArray())
        off = numpy_support.vtk_to_numpy(polys.GetOffsetsArray())
        if not np.all(np.diff(off) == 3):
            raise InputError("polydata: only triangle meshes are supported")
        tri = conn.reshape(-1, 3).astype(np.int64)
    else:
        tri = np.zeros((0, 3), np.int64)
    return np.array(pts), tri, cell_arrays(poly)


def cell_arrays(data):
    """{name: numpy array} of a data set's cell arrays."""
    cd = data.GetCellData()
    return {cd.GetArrayName(k): numpy_support.vtk_to_numpy(cd.GetArray(k))
            for k in range(cd.GetNumberOfArrays())}
