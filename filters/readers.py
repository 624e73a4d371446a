"""Image readers behind one function, :func:`read_image`, used by the CLI and the plugins.

Every reader returns ``(array, ImageGeometry)``: a (rows, cols) slice or an (nz, ny, nx)
volume in VTK's index order (array[k, j, i] is VTK point (i, j, k)) and the index-to-world
map of the file. Which library reads what, and why:

- VTK: PNG, VTK XML image (.vti), NIfTI (.nii/.nii.gz; its sform or qform becomes the
  direction and origin), MetaImage voxels (.mha/.mhd; the geometry is read from the
  header here, see :func:`_read_metaimage`).
- pydicom: DICOM files and series. vtkDICOMImageReader mixes the files of several series
  found in one folder and ignores the image orientation (tilted or sagittal stacks come
  out with wrong world coordinates); pydicom lets us group by series and place every slice
  by its position.
- pynrrd: NRRD. vtkNrrdReader (VTK 9.7) misreads gzip-encoded 3D files (a 6 x 5 x 4 file
  came back as 5 x 4 x 1), and gzip is what 3D Slicer writes by default.
- tifffile: TIFF, single and multi-page, and folders of TIFF slices. vtkTIFFReader reports
  one slice for a multi-page file whose pages it has read.
- numpy: .npy (unit spacing).

Pictures without geometry (PNG, TIFF) are read with their first row at the largest j
(y up), as VTK's PNG reader and ParaView show them. Formats with geometry (DICOM, NRRD,
NIfTI, MetaImage, VTI) keep their stored row order and carry the direction matrix, so
world coordinates are the file's own (DICOM, NRRD, MetaImage: as stored, usually LPS;
NIfTI: RAS).
"""
import os
import re

import numpy as np

from ctseg.errors import InputError

from .convert import ImageGeometry
from .scan_readers import (_dicom_series, _is_dicom, _read_metaimage, _read_nifti,
                           _read_nrrd, _read_vtk_image, _vtk_read)

SUPPORTED_INPUTS = (".npy", ".png", ".tif", ".tiff", ".dcm", ".nrrd", ".nhdr", ".nii",
                    ".nii.gz", ".mha", ".mhd", ".vti")
"""File extensions :func:`read_image` knows; folders of DICOM or TIFF slices too, and DICOM
files of any name (recognised by their preamble)."""


def _ext(path):
    low = path.lower()
    return ".nii.gz" if low.endswith(".nii.gz") else os.path.splitext(low)[1]


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


def _to_gray(arr, path):
    """(..., rows, cols, c) colour -> luminance (ITU-R BT.601); alpha dropped; gray stored
    as RGB stays exact."""
    if arr.shape[-1] in (2, 4):
        arr = arr[..., :-1]
    if arr.shape[-1] == 1:
        return arr[..., 0]
    if arr.shape[-1] != 3:
        raise InputError(f"{path}: {arr.shape[-1]} channels per pixel; expected gray or RGB")
    r, g, b = arr[..., 0], arr[..., 1], arr[..., 2]
    if np.array_equal(r, g) and np.array_equal(r, b):
        return r
    return 0.299 * r.astype(np.float64) + 0.587 * g + 0.114 * b


def _read_png(path):
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkIOImage import vtkPNGReader

    _check_png(path)
    img = _vtk_read(vtkPNGReader, path, "PNG").GetOutput()
    scal = img.GetPointData().GetScalars()
    dims = img.GetDimensions()
    arr = numpy_support.vtk_to_numpy(scal).reshape(dims[1], dims[0], scal.GetNumberOfComponents())
    return np.ascontiguousarray(_to_gray(arr, path)), ImageGeometry(img.GetOrigin(), img.GetSpacing())


def _tiff_pages(path):
    import tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            arr = tif.asarray()
            n_pages = len(tif.pages)
    except Exception as exc:  # tifffile raises many types on corrupt input
        raise InputError(f"{path}: not a readable TIFF file ({type(exc).__name__}: {exc})") from None
    if n_pages > 1 and arr.ndim >= 3 and arr.shape[-1] in (3, 4) and arr.ndim == 4:
        arr = _to_gray(arr, path)
    elif n_pages == 1 and arr.ndim == 3 and arr.shape[-1] in (2, 3, 4):
        arr = _to_gray(arr, path)
    if arr.ndim not in (2, 3):
        raise InputError(f"{path}: TIFF of shape {arr.shape}; expected one gray image or a "
                         "stack of gray pages")
    return arr


def _read_tiff(path):
    arr = _tiff_pages(path)
    # first stored row at the largest j (y up), as VTK's PNG reader does
    return np.ascontiguousarray(arr[..., ::-1, :]), ImageGeometry()


def _natural_key(name):
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def _read_tiff_folder(path, files):
    pages = [_tiff_pages(f) for f in files]
    shapes = {p.shape for p in pages}
    if len(shapes) != 1 or pages[0].ndim != 2:
        raise InputError(f"{path}: the TIFF slices differ in shape or are not single gray "
                         f"images ({sorted(shapes)})")
    vol = np.stack(pages)
    return np.ascontiguousarray(vol[:, ::-1, :]), ImageGeometry()


def _read_folder(path, series=None):
    entries = sorted((os.path.join(path, f) for f in os.listdir(path)
                      if not f.startswith(".") and os.path.isfile(os.path.join(path, f))),
                     key=lambda p: _natural_key(os.path.basename(p)))
    tiffs = [f for f in entries if _ext(f) in (".tif", ".tiff")]
    dicoms = [f for f in entries if _ext(f) == ".dcm" or _is_dicom(f)]
    if dicoms:
        return _dicom_series(path, dicoms, series)
    if tiffs:
        _no_series(path, series)
        return _read_tiff_folder(path, tiffs)
    raise InputError(f"{path}: a folder with no DICOM or TIFF slices in it")


def _no_series(path, series):
    if series is not None:
        raise InputError(f"{path}: series {series} asked for, but only DICOM data have series")


def read_image(path, series=None):
    """Read a 2D image or a 3D volume with its geometry.

    Parameters
    ----------
    path : str or path-like
        A file (.npy, .png, .tif/.tiff single or multi-page, .dcm or any DICOM file,
        .nrrd/.nhdr, .nii/.nii.gz, .mha/.mhd, .vti) or a folder of DICOM files (one series)
        or of TIFF slices (in natural name order).
    series : str, optional
        SeriesInstanceUID to read from a folder holding several DICOM series.

    Returns
    -------
    array : (rows, cols) or (nz, ny, nx) ndarray
        DICOM values with rescale slope and intercept applied (Hounsfield units where the
        file says so); NIfTI values with its scaling applied.
    geometry : ImageGeometry

    Raises
    ------
    InputError
        Missing file, unknown format, corrupt or truncated file, mixed DICOM series without
        ``series``, uneven slice spacing, colour or multi-component data that are not one
        gray value per voxel.
    """
    path = os.fspath(path)
    try:
        return _read_any(path, series)
    except InputError as exc:
        if path in str(exc):
            raise
        raise InputError(f"{path}: {exc}") from None  # e.g. a geometry the file gives


def _read_any(path, series):
    if not os.path.exists(path):
        raise InputError(f"{path}: no such file or folder")
    if os.path.isdir(path):
        return _read_folder(path, series)
    ext = _ext(path)
    if series is not None and not (ext == ".dcm" or _is_dicom(path)):
        _no_series(path, series)
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
    if ext in (".nrrd", ".nhdr"):
        return _read_nrrd(path)
    if ext in (".nii", ".nii.gz"):
        return _read_nifti(path)
    if ext in (".mha", ".mhd"):
        return _read_metaimage(path)
    if ext == ".vti":
        from vtkmodules.vtkIOXML import vtkXMLImageDataReader

        return _read_vtk_image(vtkXMLImageDataReader, path, "VTK XML image")
    if ext == ".dcm" or _is_dicom(path):
        return _dicom_series(path, [path], series)
    raise InputError(
        f"{path}: unknown image format {ext or '(no extension)'}; supported: "
        + ", ".join(SUPPORTED_INPUTS) + ", DICOM files of any name, and folders of DICOM or "
        "TIFF slices")
