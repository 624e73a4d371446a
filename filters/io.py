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


def _check_png(path):
    """Walk a PNG's chunks (CRC, IHDR, IDAT, IEND) and inflate its image data.

    vtkPNGReader crashes the Python process (segmentation fault) on some corrupt or
    truncated files, so nothing reaches it before this check passes.
    """
    import struct
    import zlib

    with open(path, "rb") as fh:
        data = fh.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise InputError(f"{path}: not a PNG file (bad signature)")
    pos, idat, ihdr, seen_end = 8, [], None, False
    while pos + 8 <= len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        tag = data[pos + 4:pos + 8]
        body = data[pos + 8:pos + 8 + length]
        crc = data[pos + 8 + length:pos + 12 + length]
        if len(body) != length or len(crc) != 4:
            raise InputError(f"{path}: truncated PNG file (chunk {tag!r} cut short)")
        if struct.unpack(">I", crc)[0] != zlib.crc32(tag + body) & 0xFFFFFFFF:
            raise InputError(f"{path}: corrupt PNG file (bad checksum in chunk {tag!r})")
        if tag == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif tag == b"IDAT":
            idat.append(body)
        elif tag == b"IEND":
            seen_end = True
            break
        pos += 12 + length
    if ihdr is None or not idat or not seen_end:
        raise InputError(f"{path}: truncated or corrupt PNG file (missing IHDR, IDAT or IEND)")
    try:
        raw = zlib.decompress(b"".join(idat))
    except zlib.error as exc:
        raise InputError(f"{path}: corrupt PNG image data ({exc})") from None
    width, height, depth, colour, _, _, interlace = ihdr
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}.get(colour)
    if channels is None or width == 0 or height == 0:
        raise InputError(f"{path}: unsupported PNG header (colour type {colour})")
    if not interlace and len(raw) != height * (1 + (width * channels * depth + 7) // 8):
        raise InputError(f"{path}: corrupt PNG image data (wrong size)")


def _read_png(path):
    from vtkmodules.vtkIOImage import vtkPNGReader
    from vtkmodules.util import numpy_support

    _check_png(path)
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
    # vtkTIFFReader keeps the file's first row at j = 0; the PNG and DICOM readers put it at
    # the largest j (y up, as the picture is seen). One convention for all: flip.
    return np.ascontiguousarray(arr[..., ::-1, :]), geom


def _read_dicom(path):
    from vtkmodules.vtkIOImage import vtkDICOMImageReader

    # vtkDICOMImageReader applies rescale slope and intercept itself (checked by
    # tests/test_io.py on a file with slope 2, intercept -1024) and puts the first stored
    # row at the top (largest j), like VTK's other image readers.
    reader = _vtk_read(vtkDICOMImageReader, path, "DICOM")
    return image_to_array(reader.GetOutput())


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
