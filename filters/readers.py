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

from .convert import ImageGeometry, image_to_array

SUPPORTED_INPUTS = (".npy", ".png", ".tif", ".tiff", ".dcm", ".nrrd", ".nhdr", ".nii",
                    ".nii.gz", ".mha", ".mhd", ".vti")
"""File extensions :func:`read_image` knows; folders of DICOM or TIFF slices too, and DICOM
files of any name (recognised by their preamble)."""


def _ext(path):
    low = path.lower()
    return ".nii.gz" if low.endswith(".nii.gz") else os.path.splitext(low)[1]


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
    out = reader.GetOutput()
    if reader.GetErrorCode() or out.GetNumberOfPoints() == 0:
        raise InputError(f"{path}: could not read the {what} data (corrupt or truncated file?)")
    if hasattr(out, "GetPointData") and out.GetPointData().GetScalars() is not None:
        expected = out.GetNumberOfPoints() * out.GetPointData().GetScalars().GetNumberOfComponents()
        if out.GetPointData().GetScalars().GetNumberOfValues() != expected:
            raise InputError(f"{path}: the {what} data are incomplete (truncated file?)")
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


def _dicom_headers(files, path):
    import pydicom
    from pydicom.errors import InvalidDicomError

    headers = []
    for f in files:
        try:
            ds = pydicom.dcmread(f, stop_before_pixels=True)
        except (InvalidDicomError, OSError, EOFError, ValueError, KeyError, TypeError) as exc:
            if len(files) == 1:
                raise InputError(f"{f}: not a readable DICOM file ({type(exc).__name__}: {exc})") from None
            continue  # a folder may hold a DICOMDIR, notes, thumbnails
        if "Rows" in ds and "Columns" in ds:
            headers.append((f, ds))
    if not headers:
        raise InputError(f"{path}: no DICOM image files found")
    return headers


def _dicom_series(path, files, series=None):
    """Read one DICOM series (a list of files, one file or several) as a volume."""
    import pydicom

    headers = _dicom_headers(files, path)
    groups = {}
    for f, ds in headers:
        groups.setdefault(str(ds.get("SeriesInstanceUID", "")), []).append((f, ds))
    if series is not None:
        if series not in groups:
            raise InputError(f"{path}: no DICOM series {series}; found {', '.join(sorted(groups))}")
        members = groups[series]
    elif len(groups) > 1:
        listing = "; ".join(f"{uid} ({len(m)} files, {m[0][1].get('SeriesDescription', 'no description')})"
                            for uid, m in sorted(groups.items()))
        raise InputError(f"{path}: holds {len(groups)} DICOM series; choose one with "
                         f"--series UID: {listing}")
    else:
        members = next(iter(groups.values()))
    iop = np.array([float(v) for v in members[0][1].get("ImageOrientationPatient", [1, 0, 0, 0, 1, 0])])
    row_dir, col_dir = iop[:3], iop[3:]
    normal = np.cross(row_dir, col_dir)
    shapes = {(int(ds.Rows), int(ds.Columns)) for _, ds in members}
    if len(shapes) != 1:
        raise InputError(f"{path}: the DICOM slices differ in size ({sorted(shapes)})")

    def position(ds):
        return np.array([float(v) for v in ds.get("ImagePositionPatient", [0, 0, 0])])

    has_pos = all("ImagePositionPatient" in ds for _, ds in members)
    if has_pos:
        members = sorted(members, key=lambda m: float(position(m[1]) @ normal))
    else:
        members = sorted(members, key=lambda m: int(m[1].get("InstanceNumber", 0) or 0))
    first = members[0][1]
    slices = []
    for f, _ in members:
        try:
            ds = pydicom.dcmread(f)
        except Exception as exc:
            raise InputError(f"{f}: not a readable DICOM file ({type(exc).__name__}: {exc})") from None
        try:
            px = ds.pixel_array
        except Exception as exc:  # no decoder for the transfer syntax, truncated pixel data
            syntax = getattr(ds.get("file_meta", None) or ds.file_meta, "TransferSyntaxUID", "?")
            raise InputError(f"{f}: cannot decode the DICOM pixel data (transfer syntax "
                             f"{syntax}; {type(exc).__name__}: {exc})") from None
        slope = float(ds.get("RescaleSlope", 1) or 1)
        intercept = float(ds.get("RescaleIntercept", 0) or 0)
        px = px.astype(np.float64) * slope + intercept if (slope, intercept) != (1.0, 0.0) else px
        slices.append(px)
    vol = np.stack(slices) if slices[0].ndim == 2 else slices[0]
    if len(slices) > 1 and slices[0].ndim != 2:
        raise InputError(f"{path}: several multi-frame DICOM files in one series are not supported")
    spacing_rc = [float(v) for v in first.get("PixelSpacing", [1, 1])]
    if len(members) > 1 and has_pos:
        z = np.array([position(ds) @ normal for _, ds in members])
        gaps = np.diff(z)
        if np.any(gaps <= 0):
            raise InputError(f"{path}: two DICOM slices share a position; is it one series?")
        if np.ptp(gaps) > 0.01 * gaps.mean():
            raise InputError(f"{path}: slice spacing varies from {gaps.min():g} to "
                             f"{gaps.max():g}; ctseg needs evenly spaced slices")
        dz = float(gaps.mean())
    else:
        dz = float(first.get("SpacingBetweenSlices", first.get("SliceThickness", 1.0)) or 1.0)
    direction = np.column_stack([row_dir, col_dir, normal])
    geom = ImageGeometry(origin=position(first), spacing=(spacing_rc[1], spacing_rc[0], dz),
                         direction=direction)
    if vol.shape[0] == 1:
        vol = vol[0]
    return np.ascontiguousarray(vol), geom


def _read_nrrd(path):
    import nrrd

    try:
        data, header = nrrd.read(path, index_order="C")
    except Exception as exc:  # pynrrd raises NRRDError, ValueError, OSError, zlib errors...
        raise InputError(f"{path}: not a readable NRRD file ({type(exc).__name__}: {exc})") from None
    kinds = header.get("kinds")
    ndim = int(header.get("dimension", data.ndim))
    if kinds is not None and any(k not in ("domain", "space", "time") for k in kinds):
        raise InputError(f"{path}: NRRD axes of kinds {kinds}; ctseg needs one gray value per voxel")
    if data.ndim not in (2, 3) or ndim != data.ndim:
        raise InputError(f"{path}: NRRD of shape {data.shape}; expected a 2D or 3D gray image")
    n = data.ndim
    origin = np.zeros(3)
    direction = np.eye(3)
    spacing = np.ones(3)
    dirs = header.get("space directions")
    if dirs is not None:
        dirs = np.array([[np.nan] * 3 if d is None else d for d in np.asarray(dirs, dtype=object)], float)
        if dirs.shape[0] != n or np.isnan(dirs).any():
            raise InputError(f"{path}: NRRD 'space directions' do not match its {n} axes")
        dim_space = dirs.shape[1]
        for a in range(n):  # axis a is the a-th fastest (x first)
            vec = np.zeros(3)
            vec[:dim_space] = dirs[a]
            spacing[a] = np.linalg.norm(vec)
            if spacing[a] == 0:
                raise InputError(f"{path}: NRRD axis {a} has a zero space direction")
            direction[:, a] = vec / spacing[a]
        if n == 2:
            direction[:, 2] = np.cross(direction[:, 0], direction[:, 1])
    elif header.get("spacings") is not None:
        spacing[:n] = [float(s) if np.isfinite(s) else 1.0 for s in header["spacings"]]
    if header.get("space origin") is not None:
        so = np.asarray(header["space origin"], float)
        origin[:len(so)] = so
    return np.ascontiguousarray(data), ImageGeometry(origin, spacing, direction)


def _read_nifti(path):
    from vtkmodules.vtkIOImage import vtkNIFTIImageReader

    reader = _vtk_read(vtkNIFTIImageReader, path, "NIfTI")
    arr, geom = image_to_array(reader.GetOutput())
    matrix = reader.GetSFormMatrix() or reader.GetQFormMatrix()
    if matrix is not None:
        m = np.array([[matrix.GetElement(r, c) for c in range(4)] for r in range(4)])
        # the matrix maps VTK's data coordinates (origin + index * spacing) to NIfTI world
        origin = m[:3, :3] @ np.asarray(geom.origin) + m[:3, 3]
        geom = ImageGeometry(origin, geom.spacing, m[:3, :3])
    slope, inter = reader.GetRescaleSlope(), reader.GetRescaleIntercept()
    if slope not in (0.0, 1.0) or inter != 0.0:
        arr = arr.astype(np.float64) * (slope or 1.0) + inter
    return arr, geom


_MET_BYTES = {"MET_CHAR": 1, "MET_UCHAR": 1, "MET_SHORT": 2, "MET_USHORT": 2, "MET_INT": 4,
              "MET_UINT": 4, "MET_LONG": 4, "MET_ULONG": 4, "MET_LONG_LONG": 8,
              "MET_ULONG_LONG": 8, "MET_FLOAT": 4, "MET_DOUBLE": 8}


def _read_metaimage(path):
    """MetaImage: voxels by VTK, geometry from the header by MetaIO's own convention.

    ``TransformMatrix`` lists the direction of each index axis in turn (ITK's reading, the
    reference implementation); vtkMetaImageReader 9.7 reads it transposed (a rotated file
    written by SimpleITK came back rotated the other way) and VTK 9.2 ignores it, so the
    header is parsed here. The header is also checked against the data size first:
    vtkMetaImageReader fills a truncated file's missing voxels with zeros without a word.
    """
    import zlib

    from vtkmodules.vtkIOImage import vtkMetaImageReader

    with open(path, "rb") as fh:
        raw = fh.read()
    fields, pos = {}, 0
    while pos < len(raw):
        end = raw.find(b"\n", pos)
        end = len(raw) if end < 0 else end
        key, _, value = raw[pos:end].decode("latin-1").partition("=")
        pos = end + 1
        fields[key.strip()] = value.strip()
        if key.strip() == "ElementDataFile":
            break
    try:
        dims = [int(v) for v in fields["DimSize"].split()]
        elem = _MET_BYTES[fields["ElementType"]] * int(fields.get("ElementNumberOfChannels", 1))
        source = fields["ElementDataFile"]
        n = len(dims)

        def numbers(keys, default):
            for k in keys:
                if k in fields:
                    return [float(v) for v in fields[k].split()]
            return default

        offset = numbers(("Offset", "Position", "Origin"), [0.0] * n)[:n]
        spacing = numbers(("ElementSpacing", "ElementSize"), [1.0] * n)[:n]
        matrix = numbers(("TransformMatrix", "Rotation", "Orientation"), list(np.eye(n).ravel()))
        axes = np.array(matrix[:n * n]).reshape(n, n)  # row a: the direction of index axis a
    except (KeyError, ValueError):
        raise InputError(f"{path}: not a readable MetaImage file (DimSize, ElementType or "
                         "ElementDataFile missing or malformed)") from None
    if source == "LOCAL":
        data = raw[pos:]
    elif source.startswith("LIST") or "%" in source:
        data = None  # slices in several files: VTK checks those
    else:
        data_path = os.path.join(os.path.dirname(path), source)
        if not os.path.isfile(data_path):
            raise InputError(f"{path}: its data file {data_path} does not exist")
        with open(data_path, "rb") as fh:
            data = fh.read()
    if data is not None:
        need = int(np.prod(dims)) * elem
        if fields.get("CompressedData", "False").lower() == "true":
            try:
                have = len(zlib.decompressobj().decompress(data))
            except zlib.error as exc:
                raise InputError(f"{path}: corrupt MetaImage data ({exc})") from None
        else:
            have = len(data)
        if have < need:
            raise InputError(f"{path}: truncated MetaImage data ({have} of {need} bytes)")
    arr, _ = _read_vtk_image(vtkMetaImageReader, path, "MetaImage")
    direction = np.eye(3)
    direction[:n, :n] = axes.T
    if n == 2:
        direction[:, 2] = np.cross(direction[:, 0], direction[:, 1])
    geom = ImageGeometry(np.pad(offset, (0, 3 - n)), np.pad(spacing, (0, 3 - n), constant_values=1.0),
                         direction)
    return arr, geom


def _read_vtk_image(reader_cls, path, what):
    reader = _vtk_read(reader_cls, path, what)
    img = reader.GetOutput()
    pd = img.GetPointData()
    if pd.GetScalars() is None and pd.GetNumberOfArrays():
        pd.SetActiveScalars(pd.GetArrayName(0))
    return image_to_array(img)


def _read_folder(path, series=None):
    entries = sorted((os.path.join(path, f) for f in os.listdir(path)
                      if not f.startswith(".") and os.path.isfile(os.path.join(path, f))),
                     key=lambda p: _natural_key(os.path.basename(p)))
    tiffs = [f for f in entries if _ext(f) in (".tif", ".tiff")]
    dicoms = [f for f in entries if _ext(f) == ".dcm" or _is_dicom(f)]
    if dicoms:
        return _dicom_series(path, dicoms, series)
    if tiffs:
        return _read_tiff_folder(path, tiffs)
    raise InputError(f"{path}: a folder with no DICOM or TIFF slices in it")


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
