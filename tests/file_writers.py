"""Minimal DICOM (explicit VR little endian) and baseline TIFF writers, for tests only."""
import struct

import numpy as np

CT_STORAGE = "1.2.840.10008.5.1.4.1.1.2"
EXPLICIT_LE = "1.2.840.10008.1.2.1"


def _elem(group, element, vr, value):
    if isinstance(value, str):
        pad = b"\0" if vr == "UI" else b" "
        data = value.encode("ascii")
        if len(data) % 2:
            data += pad
    else:
        data = value
    head = struct.pack("<HH", group, element) + vr.encode("ascii")
    if vr in ("OB", "OW", "OF", "SQ", "UT", "UN"):
        return head + b"\0\0" + struct.pack("<I", len(data)) + data
    return head + struct.pack("<H", len(data)) + data


def write_ct_dicom(path, pixels, slope=1.0, intercept=0.0, spacing=(1.0, 1.0),
                   position=(0.0, 0.0, 0.0), orientation=(1, 0, 0, 0, 1, 0), instance=1,
                   series_uid="1.2.826.0.1.3680043.2.1125.2.1", description="test series"):
    """Write a uint16 (rows, cols) array as a single-frame CT DICOM file.

    ``spacing`` is DICOM's PixelSpacing: (between rows, between columns)."""
    pixels = np.ascontiguousarray(pixels, dtype="<u2")
    rows, cols = pixels.shape
    uid = f"1.2.826.0.1.3680043.2.1125.1.{instance}"
    ds = lambda vals: "\\".join(f"{v:g}" for v in vals)
    meta_body = (_elem(0x0002, 0x0001, "OB", b"\0\1") + _elem(0x0002, 0x0002, "UI", CT_STORAGE)
                 + _elem(0x0002, 0x0003, "UI", uid) + _elem(0x0002, 0x0010, "UI", EXPLICIT_LE))
    meta = _elem(0x0002, 0x0000, "UL", struct.pack("<I", len(meta_body))) + meta_body
    us = lambda v: struct.pack("<H", v)
    body = b"".join([
        _elem(0x0008, 0x0016, "UI", CT_STORAGE), _elem(0x0008, 0x0018, "UI", uid),
        _elem(0x0008, 0x0060, "CS", "CT"), _elem(0x0008, 0x103E, "LO", description),
        _elem(0x0020, 0x000E, "UI", series_uid), _elem(0x0020, 0x0013, "IS", str(instance)),
        _elem(0x0020, 0x0032, "DS", ds(position)), _elem(0x0020, 0x0037, "DS", ds(orientation)),
        _elem(0x0028, 0x0002, "US", us(1)), _elem(0x0028, 0x0004, "CS", "MONOCHROME2"),
        _elem(0x0028, 0x0010, "US", us(rows)), _elem(0x0028, 0x0011, "US", us(cols)),
        _elem(0x0028, 0x0030, "DS", f"{spacing[0]:g}\\{spacing[1]:g}"),
        _elem(0x0028, 0x0100, "US", us(16)), _elem(0x0028, 0x0101, "US", us(16)),
        _elem(0x0028, 0x0102, "US", us(15)), _elem(0x0028, 0x0103, "US", us(0)),
        _elem(0x0028, 0x1052, "DS", f"{intercept:g}"), _elem(0x0028, 0x1053, "DS", f"{slope:g}"),
        _elem(0x7FE0, 0x0010, "OW", pixels.tobytes()),
    ])
    with open(path, "wb") as fh:
        fh.write(b"\0" * 128 + b"DICM" + meta + body)


def write_tiff16(path, pixels):
    """Write a uint16 (rows, cols) array as a baseline uncompressed TIFF, first row first."""
    pixels = np.ascontiguousarray(pixels, dtype="<u2")
    rows, cols = pixels.shape
    data = pixels.tobytes()
    entries = [(256, 3, 1, cols), (257, 3, 1, rows), (258, 3, 1, 16), (259, 3, 1, 1),
               (262, 3, 1, 1), (273, 4, 1, 8), (277, 3, 1, 1), (278, 3, 1, rows),
               (279, 4, 1, len(data))]
    ifd_offset = 8 + len(data)
    ifd = struct.pack("<H", len(entries))
    for tag, typ, count, value in entries:
        packed = struct.pack("<HI", value, 0)[:4] if typ == 3 else struct.pack("<I", value)
        ifd += struct.pack("<HHI", tag, typ, count) + packed
    ifd += struct.pack("<I", 0)
    with open(path, "wb") as fh:
        fh.write(b"II*\x00" + struct.pack("<I", ifd_offset) + data + ifd)
