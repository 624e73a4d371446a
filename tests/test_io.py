import os

import numpy as np
import pytest

from ctseg.errors import InputError
from ctseg.filters import (array_to_image, boundary_to_polydata, mesh_to_polydata,
                           polydata_to_arrays, read_image, read_polydata, write_polydata)
from ctseg.filters.convert import ImageGeometry

from file_writers import write_ct_dicom, write_tiff16


def _vtk_write(writer_cls, path, arr):
    w = writer_cls()
    w.SetFileName(str(path))
    w.SetInputData(array_to_image(arr))
    w.Write()


def test_png_round_trip(tmp_path):
    from vtkmodules.vtkIOImage import vtkPNGWriter

    arr = (np.arange(30 * 20).reshape(20, 30) % 251).astype(np.uint8)
    _vtk_write(vtkPNGWriter, tmp_path / "a.png", arr)
    back, geom = read_image(tmp_path / "a.png")
    assert np.array_equal(back, arr) and geom.spacing == (1.0, 1.0, 1.0)


def test_colour_png_becomes_luminance(tmp_path):
    from vtkmodules.vtkIOImage import vtkPNGWriter
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkCommonDataModel import vtkImageData

    rgb = np.zeros((8, 9, 3), np.uint8)
    rgb[..., 0] = 200
    rgb[..., 1] = 100
    img = vtkImageData()
    img.SetDimensions(9, 8, 1)
    a = numpy_support.numpy_to_vtk(rgb.reshape(-1, 3), deep=True)
    img.GetPointData().SetScalars(a)
    w = vtkPNGWriter()
    w.SetFileName(str(tmp_path / "c.png"))
    w.SetInputData(img)
    w.Write()
    back, _ = read_image(tmp_path / "c.png")
    np.testing.assert_allclose(back, 0.299 * 200 + 0.587 * 100)


def test_tiff_16bit_known_values(tmp_path):
    arr = (np.arange(25 * 17).reshape(17, 25) * 97 % 65000).astype(np.uint16)
    write_tiff16(tmp_path / "a.tif", arr)
    back, _ = read_image(tmp_path / "a.tif")
    # the first stored row is the top of the picture: the largest j, as for PNG and DICOM
    assert back.dtype == np.uint16 and np.array_equal(back, arr[::-1])
    data = (tmp_path / "a.tif").read_bytes()
    (tmp_path / "cut.tif").write_bytes(data[: len(data) // 3])
    with pytest.raises(InputError):
        read_image(tmp_path / "cut.tif")


def test_dicom_rescale_and_spacing(tmp_path):
    px = (np.arange(12 * 10).reshape(12, 10) * 7).astype(np.uint16)
    write_ct_dicom(tmp_path / "ct.dcm", px, slope=2.0, intercept=-1024.0, spacing=(0.5, 0.25))
    arr, geom = read_image(tmp_path / "ct.dcm")
    # Hounsfield units; the first stored row ends up at the top (largest j), as in VTK
    np.testing.assert_array_equal(arr, px[::-1] * 2.0 - 1024.0)
    assert geom.spacing[:2] == (0.25, 0.5)  # DICOM stores row spacing first
    # a DICOM file without the extension is recognised by its preamble
    os.rename(tmp_path / "ct.dcm", tmp_path / "IM0001")
    arr2, _ = read_image(tmp_path / "IM0001")
    np.testing.assert_array_equal(arr2, arr)


def test_npy(tmp_path):
    arr = np.random.default_rng(0).normal(size=(7, 9))
    np.save(tmp_path / "a.npy", arr)
    back, geom = read_image(tmp_path / "a.npy")
    assert np.array_equal(back, arr) and geom.origin == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("name,content", [
    ("bad.png", b"\x89PNG\r\n\x1a\n garbage"),
    ("bad.tif", b"II*\x00 garbage"),
    ("bad.npy", b"\x93NUMPY garbage"),
    ("bad.dcm", b"\0" * 128 + b"DICM" + b"\x02\x00"),
    ("image.xyz", b"whatever"),
    ("png_named.tif", b"\x89PNG\r\n\x1a\n"),
])
def test_corrupt_or_unknown_files(tmp_path, name, content):
    (tmp_path / name).write_bytes(content)
    with pytest.raises(InputError, match=name):
        read_image(tmp_path / name)


def test_truncated_png(tmp_path):
    from vtkmodules.vtkIOImage import vtkPNGWriter

    _vtk_write(vtkPNGWriter, tmp_path / "t.png", np.full((40, 40), 9, np.uint8))
    data = (tmp_path / "t.png").read_bytes()
    (tmp_path / "t.png").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError):
        read_image(tmp_path / "t.png")


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_image(tmp_path / "nope.png")
    with pytest.raises(InputError, match="directory"):
        read_image(tmp_path)


def test_polydata_round_trip_with_geometry(tmp_path):
    pts = np.array([[0, 0], [3, 0], [0, 2], [3, 2]], float)
    tri = np.array([[0, 1, 2], [1, 3, 2]])
    theta = np.deg2rad(30)
    rot = np.array([[np.cos(theta), -np.sin(theta), 0], [np.sin(theta), np.cos(theta), 0], [0, 0, 1]])
    geom = ImageGeometry(origin=(10, -5, 2), spacing=(0.5, 0.25, 1.0), direction=rot)
    poly = mesh_to_polydata(pts, tri, [0, 1], [1.5, 2.5], geom)
    out = write_polydata(poly, tmp_path / "m.vtp")
    p, t, arrays = polydata_to_arrays(read_polydata(out))
    expected = np.array([10, -5, 2]) + (np.column_stack([pts, np.zeros(4)]) * [0.5, 0.25, 1.0]) @ rot.T
    np.testing.assert_allclose(p, expected)
    assert np.array_equal(t, tri)
    assert arrays["material"].tolist() == [0, 1] and arrays["gray"].tolist() == [1.5, 2.5]
    assert arrays["slice"].tolist() == [0, 0]
    assert not [f for f in os.listdir(tmp_path) if f.startswith(".ctseg-")]


def test_boundary_polydata(tmp_path):
    pts = np.array([[0, 0], [1, 0], [2, 0]], float)
    poly = boundary_to_polydata(pts, [np.array([0, 1, 2])], np.array([[0, 2]]))
    back = read_polydata(write_polydata(poly, tmp_path / "b.vtp"))
    assert back.GetNumberOfLines() == 1 and back.GetCell(0).GetNumberOfPoints() == 3
    assert back.GetCellData().GetArray("material_b").GetValue(0) == 2


def test_unknown_output_format_and_missing_folder(tmp_path):
    poly = mesh_to_polydata(np.array([[0, 0], [1, 0], [0, 1]], float), np.array([[0, 1, 2]]), [0], [1.0])
    with pytest.raises(InputError, match="unknown output format"):
        write_polydata(poly, tmp_path / "m.abc")
    with pytest.raises(InputError, match="does not exist"):
        write_polydata(poly, tmp_path / "nowhere" / "m.vtp")
