"""Readers of the scan formats that carry a geometry (DICOM, NRRD, NIfTI, MetaImage) and
the VTK reader helpers; :func:`ctseg.filters.read_image` dispatches to them (see
:mod:`ctseg.filters.readers` for which library reads what, and why). Each returns
``(array, ImageGeometry)`` in VTK's index order."""
import os

import numpy as np

from ctseg.errors import InputError

from .convert import ImageGeometry, image_to_array


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


def _dicom_numbers(ds, tag, n, default, where):
    """A numeric DICOM attribute of ``n`` values (``default`` where absent); an InputError
    naming the file and the tag where it holds another count or no numbers."""
    value = ds.get(tag, default)
    several = hasattr(value, "__iter__") and not isinstance(value, (str, bytes))
    values = list(value) if several else [value]  # pydicom gives one value unwrapped
    try:
        out = np.array([float(v) for v in values])
    except (TypeError, ValueError):
        out = np.zeros(0)
    if out.shape != (n,) or not np.all(np.isfinite(out)):
        raise InputError(f"{where}: DICOM {tag} is {value!r}; expected {n} numbers")
    return out


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
    iop = _dicom_numbers(members[0][1], "ImageOrientationPatient", 6, [1, 0, 0, 0, 1, 0],
                         members[0][0])
    row_dir, col_dir = iop[:3], iop[3:]
    normal = np.cross(row_dir, col_dir)
    if not np.linalg.norm(normal) > 1e-6:
        raise InputError(f"{members[0][0]}: DICOM ImageOrientationPatient {list(iop)} gives "
                         "parallel row and column directions")
    shapes = {(int(ds.Rows), int(ds.Columns)) for _, ds in members}
    if len(shapes) != 1:
        raise InputError(f"{path}: the DICOM slices differ in size ({sorted(shapes)})")

    def position(ds):
        return _dicom_numbers(ds, "ImagePositionPatient", 3, [0, 0, 0], path)

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
    spacing_rc = _dicom_numbers(first, "PixelSpacing", 2, [1, 1], members[0][0])
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
    # checked here: vtkMetaImageReader crashes the process on some of these headers, and
    # on others returns memory it never filled
    if n not in (2, 3) or fields.get("NDims", str(n)).strip() != str(n) or min(dims) < 1:
        raise InputError(f"{path}: MetaImage DimSize {fields['DimSize']!r} (NDims "
                         f"{fields.get('NDims', '?')}): need 2 or 3 sizes >= 1, as many as NDims")
    compressed = fields.get("CompressedData", "False").lower() == "true"
    if compressed and "CompressedDataSize" not in fields:
        raise InputError(f"{path}: compressed MetaImage data without CompressedDataSize "
                         "(VTK's reader needs it; ITK and SimpleITK write it)")
    if source.startswith("LIST") or "%" in source:
        raise InputError(f"{path}: MetaImage slices in several files (ElementDataFile = "
                         f"{source.split()[0]}) are not supported; save the volume as one "
                         ".mha file (e.g. SimpleITK.WriteImage)")
    if source == "LOCAL":
        data = raw[pos:]
    else:
        data_path = os.path.join(os.path.dirname(path), source)
        if not os.path.isfile(data_path):
            raise InputError(f"{path}: its data file {data_path} does not exist")
        with open(data_path, "rb") as fh:
            data = fh.read()
    need = int(np.prod(dims)) * elem
    if compressed:
        try:
            size = int(fields["CompressedDataSize"])
            have = len(zlib.decompressobj().decompress(data[:size])) if 0 < size <= len(data) else -1
        except (ValueError, zlib.error) as exc:
            raise InputError(f"{path}: corrupt MetaImage data ({exc})") from None
        if have < 0:
            raise InputError(f"{path}: CompressedDataSize {fields['CompressedDataSize']} does not "
                             f"fit the {len(data)} bytes of data")
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
