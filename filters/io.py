"""Readers and writers behind one function each, used by the CLI and the filters.

Readers return ``(array, ImageGeometry)``; 2D files give (rows, cols) arrays where row j is
VTK's j (VTK's image readers put the file's first row at the top, i.e. the largest j).
"""
import os
import tempfile

import numpy as np

from ctseg.errors import InputError

from .convert import ImageGeometry, image_to_array

SUPPORTED_INPUTS = (".npy", ".png", ".tif", ".tiff", ".dcm")


def _is_dicom(path):
    try:
        with open(path, "rb") as fh:
            head = fh.read(132)
    except OSError:
        return False
    return len(head) == 132 and head[128:132] == b"DICM"


def _vtk_read(reader_cls, path, what):
    from vtkmodules.vtkCommonCore import vtkObject

    reader = reader_cls()
    if hasattr(reader, "CanReadFile") and not reader.CanReadFile(path):
        raise InputError(f"{path}: not a readable {what} file (corrupt or wrong extension?)")
    reader.SetFileName(path)
    prev = vtkObject.GetGlobalWarningDisplay()
    vtkObject.GlobalWarningDisplayOff()  # VTK reports failures on stderr; we raise instead
    try:
        reader.Update()
    finally:
        vtkObject.SetGlobalWarningDisplay(prev)
    if reader.GetErrorCode() or reader.GetOutput().GetNumberOfPoints() == 0:
        raise InputError(f"{path}: could not read the {what} data (corrupt or truncated file?)")
    return reader


def _read_png(path):
    from vtkmodules.vtkIOImage import vtkPNGReader
    from vtkmodules.util import numpy_support

    reader = _vtk_read(vtkPNGReader, path, "PNG")
    img = reader.GetOutput()
    scal = img.GetPointData().GetScalars()
    ncomp = scal.GetNumberOfComponents()
    dims = img.GetDimensions()
    arr = numpy_support.vtk_to_numpy(scal).reshape(dims[1], dims[0], ncomp).astype(np.float64)
    if ncomp in (2, 4):  # drop alpha
        arr = arr[:, :, :-1]
    if arr.shape[2] == 3:  # colour: luminance (ITU-R BT.601); gray stored as RGB stays exact
        if np.array_equal(arr[:, :, 0], arr[:, :, 1]) and np.array_equal(arr[:, :, 0], arr[:, :, 2]):
            arr = arr[:, :, :1]
        else:
            arr = (0.299 * arr[:, :, 0] + 0.587 * arr[:, :, 1] + 0.114 * arr[:, :, 2])[:, :, None]
    return arr[:, :, 0], ImageGeometry(img.GetOrigin(), img.GetSpacing())


def _read_tiff(path):
    from vtkmodules.vtkIOImage import vtkTIFFReader

    reader = _vtk_read(vtkTIFFReader, path, "TIFF")
    arr, geom = image_to_array(reader.GetOutput())
    return arr, geom


def _read_dicom(path):
    from vtkmodules.vtkIOImage import vtkDICOMImageReader

    reader = _vtk_read(vtkDICOMImageReader, path, "DICOM")
    arr, geom = image_to_array(reader.GetOutput())
    slope = reader.GetRescaleSlope() or 1.0
    intercept = reader.GetRescaleOffset()
    arr = arr.astype(np.float64) * slope + intercept
    return arr, geom


def read_image(path):
    """Read a 2D image (or a volume, for formats that hold one) with its geometry.

    Supported: .npy (numpy array, unit spacing), .png (gray, or colour converted to
    luminance), .tif/.tiff (VTK's reader: 8/16-bit and float), a single DICOM file
    (.dcm or any name starting with the DICOM preamble; rescale slope and intercept
    applied, so CT values come out in Hounsfield units where the file says so).

    Raises
    ------
    InputError
        Missing file, unknown format, corrupt or truncated file.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise InputError(f"{path}: no such file")
    if os.path.isdir(path):
        raise InputError(f"{path}: is a directory; give one image file")
    ext = os.path.splitext(path)[1].lower()
    if ext == ".npy":
        try:
            arr = np.load(path, allow_pickle=False)
        except Exception as exc:
            raise InputError(f"{path}: not a readable .npy file ({exc})") from None
        return arr, ImageGeometry()
    if ext == ".png":
        return _read_png(path)
    if ext in (".tif", ".tiff"):
        return _read_tiff(path)
    if ext == ".dcm" or _is_dicom(path):
        return _read_dicom(path)
    raise InputError(
        f"{path}: unknown image format {ext or '(no extension)'}; supported: "
        + ", ".join(SUPPORTED_INPUTS) + " and DICOM files")


def write_polydata(poly, path):
    """Write vtkPolyData as VTK XML (.vtp), through a temporary name renamed at the end,
    so an interrupted or failed write never leaves a partial file at ``path``."""
    from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext != ".vtp":
        raise InputError(f"{path}: unknown output format {ext or '(no extension)'}; use .vtp")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise InputError(f"{path}: the folder {folder} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=".ctseg-", suffix=ext, dir=folder)
    os.close(fd)
    try:
        writer = vtkXMLPolyDataWriter()
        writer.SetFileName(tmp)
        writer.SetInputData(poly)
        writer.SetDataModeToBinary()
        if writer.Write() != 1:
            raise InputError(f"{path}: VTK could not write the file")
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def read_polydata(path):
    """Read a .vtp file written by ctseg (or anyone) back as vtkPolyData."""
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    reader = _vtk_read(vtkXMLPolyDataReader, os.fspath(path), "VTK XML PolyData")
    return reader.GetOutput()
