"""Readers (every input format, on small files the tests write themselves) and writers
(every output format, reopened by pymeshlab or VTK, never by our own reader)."""
import gzip
import os
import zlib

import numpy as np
import pytest

from ctseg.errors import InputError, MeshCheckError
from ctseg.filters import (append_polydata, array_to_image, boundary_to_polydata,
                           mesh_to_polydata, polydata_to_arrays, read_image, read_polydata,
                           write_mesh, write_polydata)
from ctseg.filters.writers import material_colors
from ctseg.geometry import ImageGeometry

from file_writers import write_ct_dicom, write_tiff16

ROT = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def _vtk_write(writer_cls, path, data):
    w = writer_cls()
    w.SetFileName(str(path))
    w.SetInputData(data)
    w.Write()


def _volume(shape=(4, 5, 6), dtype=np.int16):
    return (np.arange(np.prod(shape)).reshape(shape) * 7 - 50).astype(dtype)


# ----------------------------------------------------------------------------- pictures
def test_png_round_trip_and_truncated(tmp_path):
    from vtkmodules.vtkIOImage import vtkPNGWriter

    arr = (np.arange(30 * 20).reshape(20, 30) % 251).astype(np.uint8)
    _vtk_write(vtkPNGWriter, tmp_path / "a.png", array_to_image(arr))
    back, geom = read_image(tmp_path / "a.png")
    assert np.array_equal(back, arr) and geom.spacing == (1.0, 1.0, 1.0)
    data = (tmp_path / "a.png").read_bytes()
    (tmp_path / "t.png").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="t.png"):
        read_image(tmp_path / "t.png")


def test_colour_png_becomes_luminance(tmp_path):
    from vtkmodules.vtkIOImage import vtkPNGWriter

    rgb = np.zeros((8, 9, 3), np.uint8)
    rgb[..., 0] = 200
    rgb[..., 1] = 100
    _vtk_write(vtkPNGWriter, tmp_path / "c.png", array_to_image(rgb, components=3))
    back, _ = read_image(tmp_path / "c.png")
    np.testing.assert_allclose(back, 0.299 * 200 + 0.587 * 100)


def test_tiff_16bit_known_values(tmp_path):
    arr = (np.arange(25 * 17).reshape(17, 25) * 97 % 65000).astype(np.uint16)
    write_tiff16(tmp_path / "a.tif", arr)
    back, _ = read_image(tmp_path / "a.tif")
    # the first stored row is the top of the picture: the largest j, as for PNG
    assert back.dtype == np.uint16 and np.array_equal(back, arr[::-1])
    data = (tmp_path / "a.tif").read_bytes()
    (tmp_path / "cut.tif").write_bytes(data[: len(data) // 3])
    with pytest.raises(InputError, match="cut.tif"):
        read_image(tmp_path / "cut.tif")


def test_multipage_tiff_and_tiff_folder_are_volumes(tmp_path):
    import tifffile

    vol = _volume((3, 5, 6), np.uint16)
    tifffile.imwrite(tmp_path / "stack.tif", vol, photometric="minisblack")
    back, _ = read_image(tmp_path / "stack.tif")
    assert np.array_equal(back, vol[:, ::-1])
    folder = tmp_path / "slices"
    folder.mkdir()
    for k in range(3):  # natural order: 2 before 10
        write_tiff16(folder / f"img{[2, 10, 11][k]}.tif", vol[k])
    back, _ = read_image(folder)
    assert np.array_equal(back, vol[:, ::-1])
    write_tiff16(folder / "img12.tif", np.zeros((4, 4), np.uint16))
    with pytest.raises(InputError, match="differ in shape"):
        read_image(folder)


def test_npy(tmp_path):
    arr = np.random.default_rng(0).normal(size=(7, 9))
    np.save(tmp_path / "a.npy", arr)
    back, geom = read_image(tmp_path / "a.npy")
    assert np.array_equal(back, arr) and geom.origin == (0.0, 0.0, 0.0)


# ---------------------------------------------------------------------------- DICOM
def test_dicom_rescale_and_geometry(tmp_path):
    px = (np.arange(12 * 10).reshape(12, 10) * 7).astype(np.uint16)
    write_ct_dicom(tmp_path / "ct.dcm", px, slope=2.0, intercept=-1024.0, spacing=(0.5, 0.25),
                   position=(-3.0, 4.0, 7.5))
    arr, geom = read_image(tmp_path / "ct.dcm")
    # Hounsfield units; stored row order kept, the geometry places the first stored pixel
    np.testing.assert_array_equal(arr, px * 2.0 - 1024.0)
    assert geom.spacing[:2] == (0.25, 0.5)  # DICOM stores the row spacing first
    np.testing.assert_allclose(geom.to_world([0, 0, 0]), [-3.0, 4.0, 7.5])
    np.testing.assert_allclose(geom.to_world([1, 1, 0]), [-2.75, 4.5, 7.5])
    # a DICOM file without the extension is recognised by its preamble
    os.rename(tmp_path / "ct.dcm", tmp_path / "IM0001")
    arr2, _ = read_image(tmp_path / "IM0001")
    np.testing.assert_array_equal(arr2, arr)


def test_dicom_series_sorted_by_position_with_tilted_orientation(tmp_path):
    vol = _volume((5, 6, 7), np.uint16)
    # rows run along -y, columns along +x: a rotated slice plane; normal is +z
    orient = (0, -1, 0, 1, 0, 0)
    for k in range(5):  # files named against the slice order
        write_ct_dicom(tmp_path / f"f{4 - k}.dcm", vol[k], spacing=(0.5, 0.8), intercept=-10,
                       position=(1.0, 2.0, 0.3 + 1.5 * k), orientation=orient, instance=k + 1)
    (tmp_path / "notes.txt").write_text("not dicom")
    arr, geom = read_image(tmp_path)
    np.testing.assert_array_equal(arr, vol - 10.0)
    assert geom.spacing == (0.8, 0.5, 1.5)
    np.testing.assert_allclose(geom.to_world([0, 0, 0]), [1.0, 2.0, 0.3])
    # one column step moves along the row direction (0, -1, 0) by 0.8 mm
    np.testing.assert_allclose(geom.to_world([1, 0, 4]), [1.0, 2.0 - 0.8, 0.3 + 6.0])


def test_dicom_folder_with_two_series_needs_a_choice(tmp_path):
    for k in range(2):
        write_ct_dicom(tmp_path / f"a{k}.dcm", np.full((4, 4), k, np.uint16), instance=k + 1,
                       position=(0, 0, k), series_uid="1.2.3.1", description="bone")
        write_ct_dicom(tmp_path / f"b{k}.dcm", np.full((4, 4), 9, np.uint16), instance=k + 11,
                       position=(0, 0, k), series_uid="1.2.3.2", description="soft")
    with pytest.raises(InputError, match="2 DICOM series.*1.2.3.1.*bone.*1.2.3.2"):
        read_image(tmp_path)
    arr, _ = read_image(tmp_path, series="1.2.3.2")
    assert arr.shape == (2, 4, 4) and np.all(arr == 9)
    with pytest.raises(InputError, match="no DICOM series 9.9"):
        read_image(tmp_path, series="9.9")


def test_dicom_series_with_uneven_spacing_is_refused(tmp_path):
    for k, z in enumerate([0.0, 1.0, 2.0, 4.0]):
        write_ct_dicom(tmp_path / f"s{k}.dcm", np.zeros((4, 4), np.uint16), position=(0, 0, z),
                       instance=k + 1)
    with pytest.raises(InputError, match="spacing varies"):
        read_image(tmp_path)


# -------------------------------------------------------------- formats with geometry
def _nrrd_header(shape_xyz, encoding, extra=""):
    return ("NRRD0004\ntype: short\ndimension: 3\nspace: left-posterior-superior\n"
            f"sizes: {' '.join(map(str, shape_xyz))}\n"
            "space directions: (0,-0.5,0) (0.6,0,0) (0,0,2)\nkinds: domain domain domain\n"
            f"endian: little\nencoding: {encoding}\nspace origin: (1,2,3)\n{extra}\n").encode()


@pytest.mark.parametrize("encoding", ["raw", "gzip"])
def test_nrrd_known_values_and_geometry(tmp_path, encoding):
    vol = _volume()
    body = vol.astype("<i2").tobytes()
    body = gzip.compress(body) if encoding == "gzip" else body
    (tmp_path / "v.nrrd").write_bytes(_nrrd_header(vol.shape[::-1], encoding) + body)
    arr, geom = read_image(tmp_path / "v.nrrd")
    assert np.array_equal(arr, vol)
    assert geom.spacing == (0.5, 0.6, 2.0)
    # index (1, 0, 0) moves by the first space direction, (0, 1, 0) by the second
    np.testing.assert_allclose(geom.to_world([1, 0, 0]), [1.0, 1.5, 3.0])
    np.testing.assert_allclose(geom.to_world([0, 1, 1]), [1.6, 2.0, 5.0])
    (tmp_path / "cut.nrrd").write_bytes(_nrrd_header(vol.shape[::-1], encoding) + body[:20])
    with pytest.raises(InputError, match="cut.nrrd"):
        read_image(tmp_path / "cut.nrrd")


def test_nifti_round_trip_with_qform(tmp_path):
    from vtkmodules.vtkCommonMath import vtkMatrix4x4
    from vtkmodules.vtkIOImage import vtkNIFTIImageWriter

    vol = _volume()
    m, qform = vtkMatrix4x4(), np.eye(4)
    qform[:3, :3], qform[:3, 3] = ROT, (10.0, -4.0, 0.0)
    m.DeepCopy(qform.ravel().tolist())
    img = array_to_image(vol, ImageGeometry(spacing=(0.5, 0.6, 2.0)))
    w = vtkNIFTIImageWriter()
    w.SetFileName(str(tmp_path / "v.nii.gz"))
    w.SetInputData(img)
    w.SetQFormMatrix(m)
    w.Write()
    arr, geom = read_image(tmp_path / "v.nii.gz")
    assert np.array_equal(arr, vol)
    np.testing.assert_allclose(geom.spacing, (0.5, 0.6, 2.0), rtol=1e-6)
    np.testing.assert_allclose(geom.to_world([2, 1, 1]), [10.0 - 0.6, -4.0 + 1.0, 2.0], atol=1e-5)


@pytest.mark.parametrize("compressed", [False, True])
def test_metaimage_geometry_as_itk_reads_it(tmp_path, compressed):
    """TransformMatrix lists each index axis's direction in turn (SimpleITK wrote this header
    for direction [[0, -1, 0], [1, 0, 0], [0, 0, 1]]; it put index (1, 0, 0) at (1, 2.5, 3))."""
    vol = _volume((2, 3, 4))
    body = vol.astype("<i2").tobytes()
    body = zlib.compress(body) if compressed else body
    head = ("ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
            f"CompressedData = {compressed}\n"
            + (f"CompressedDataSize = {len(body)}\n" if compressed else "")
            + "TransformMatrix = 0 1 0 -1 0 0 0 0 1\nOffset = 1 2 3\n"
            "ElementSpacing = 0.5 0.6 2\nDimSize = 4 3 2\nElementType = MET_SHORT\n"
            "ElementDataFile = LOCAL\n").encode()
    (tmp_path / "v.mha").write_bytes(head + body)
    arr, geom = read_image(tmp_path / "v.mha")
    assert np.array_equal(arr, vol)
    np.testing.assert_allclose(geom.to_world([1, 0, 0]), [1.0, 2.5, 3.0])
    np.testing.assert_allclose(geom.to_world([0, 1, 1]), [1.0 - 0.6, 2.0, 5.0])
    (tmp_path / "cut.mha").write_bytes(head + body[: len(body) // 2])
    with pytest.raises(InputError, match="cut.mha"):
        read_image(tmp_path / "cut.mha")


@pytest.mark.parametrize("header,match", [
    ("NDims = 4\nDimSize = 2 4 3 2\n", "need 2 or 3 sizes"),
    ("NDims = 3\nDimSize = 4 -3 2\n", "need 2 or 3 sizes"),
    ("NDims = 3\nDimSize = 4 3\n", "need 2 or 3 sizes"),
    ("NDims = 3\nDimSize = 4 3 2\nCompressedData = True\n", "without CompressedDataSize"),
    ("NDims = 3\nDimSize = 4 3 2\nCompressedData = True\nCompressedDataSize = 9999\n",
     "does not fit"),
])
def test_metaimage_headers_vtk_cannot_read_are_refused(tmp_path, header, match):
    """Headers on which vtkMetaImageReader aborts the process (4 sizes, a negative one) or
    returns memory it never filled (compressed data without its size) get an InputError."""
    body = _volume((2, 3, 4)).astype("<i2").tobytes()
    if "CompressedData =" in header:
        body = zlib.compress(body)
    (tmp_path / "v.mha").write_bytes(
        ("ObjectType = Image\n" + header + "ElementType = MET_SHORT\nElementDataFile = LOCAL\n"
         ).encode() + body)
    with pytest.raises(InputError, match=match):
        read_image(tmp_path / "v.mha")


def test_metaimage_slice_list_is_refused(tmp_path):
    (tmp_path / "s0.raw").write_bytes(_volume((1, 3, 4)).astype("<i2").tobytes())
    (tmp_path / "v.mhd").write_text("ObjectType = Image\nNDims = 3\nDimSize = 4 3 2\n"
                                    "ElementType = MET_SHORT\nElementDataFile = LIST\ns0.raw\n"
                                    "missing.raw\n")
    with pytest.raises(InputError, match="several files"):
        read_image(tmp_path / "v.mhd")


def test_vti_round_trip_with_direction(tmp_path, ext=".vti"):
    from vtkmodules.vtkIOXML import vtkXMLImageDataWriter

    vol = _volume()
    geom = ImageGeometry(origin=(1, 2, 3), spacing=(0.5, 0.6, 2.0), direction=ROT)
    _vtk_write(vtkXMLImageDataWriter, tmp_path / f"v{ext}", array_to_image(vol, geom))
    arr, back = read_image(tmp_path / f"v{ext}")
    assert np.array_equal(arr, vol)
    np.testing.assert_allclose(back.to_world([[1, 2, 3], [0, 0, 0]]),
                               geom.to_world([[1, 2, 3], [0, 0, 0]]))
    data = (tmp_path / f"v{ext}").read_bytes()
    (tmp_path / f"cut{ext}").write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(InputError, match=f"cut{ext}"):
        read_image(tmp_path / f"cut{ext}")


# ----------------------------------------------------------------------- bad files
@pytest.mark.parametrize("name,content", [
    ("bad.png", b"\x89PNG\r\n\x1a\n garbage"), ("bad.tif", b"II*\x00 garbage"),
    ("bad.npy", b"\x93NUMPY garbage"), ("bad.dcm", b"\0" * 128 + b"DICM" + b"\x02\x00"),
    ("bad.nrrd", b"NRRD0004\ngarbage\n\n"), ("bad.nii", b"\0" * 40),
    ("bad.mha", b"ObjectType = Image\n"), ("bad.vti", b"<VTKFile type='ImageData'>"),
    ("image.xyz", b"whatever"), ("png_named.tif", b"\x89PNG\r\n\x1a\n"),
])
def test_corrupt_or_unknown_files(tmp_path, name, content):
    (tmp_path / name).write_bytes(content)
    with pytest.raises(InputError, match=name):
        read_image(tmp_path / name)


def test_missing_file_and_empty_folder(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_image(tmp_path / "nope.png")
    with pytest.raises(InputError, match="no DICOM or TIFF"):
        read_image(tmp_path)


# -------------------------------------------------------------------------- writers
def _two_slice_mesh():
    """Two slices of a 3 x 2 px square, 4 triangles each, materials 0..2."""
    pts = np.array([[0, 0], [1.5, 0], [3, 0], [0, 2], [1.5, 2], [3, 2]], float)
    tri = np.array([[0, 1, 3], [1, 4, 3], [1, 2, 4], [2, 5, 4]])
    geom = ImageGeometry(origin=(10, -5, 2), spacing=(0.5, 0.25, 1.5), direction=ROT)
    parts = [mesh_to_polydata(pts, tri, [0, 1, 1, 2], [1.0, 2.0, 2.5, 9.0], geom, slice_index=k)
             for k in range(2)]
    return append_polydata(parts), geom, pts, tri


def test_vtp_and_vtu_round_trip_with_geometry(tmp_path):
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

    poly, geom, pts, tri = _two_slice_mesh()
    written, checks = write_mesh(poly, tmp_path / "m.vtp")
    assert written == [str(tmp_path / "m.vtp")]
    assert checks["ok"] and checks["faces"] == 8 and checks["non_manifold_edges"] == 0
    p, t, arrays = polydata_to_arrays(read_polydata(tmp_path / "m.vtp"))
    ijk = np.column_stack([np.tile(pts, (2, 1)), np.repeat([0.0, 1.0], len(pts))])
    np.testing.assert_allclose(p, geom.to_world(ijk))
    assert np.array_equal(t, np.concatenate([tri, tri + len(pts)]))
    assert arrays["material"].tolist() == [0, 1, 1, 2] * 2
    assert arrays["slice"].tolist() == [0] * 4 + [1] * 4
    write_mesh(poly, tmp_path / "m.vtu")
    r = vtkXMLUnstructuredGridReader()
    r.SetFileName(str(tmp_path / "m.vtu"))
    r.Update()
    grid = r.GetOutput()
    assert grid.GetNumberOfCells() == 8 and grid.GetCellType(0) == 5  # VTK_TRIANGLE
    np.testing.assert_allclose(numpy_support.vtk_to_numpy(grid.GetPoints().GetData()), p)
    assert numpy_support.vtk_to_numpy(grid.GetCellData().GetArray("gray")).tolist() == [1.0, 2.0, 2.5, 9.0] * 2
    assert not [f for f in os.listdir(tmp_path) if f.startswith(".ctseg-")]


class _Loaded:
    """What pymeshlab reads back (copied: its Mesh dies with its MeshSet)."""

    def __init__(self, path):
        import pymeshlab

        ms = pymeshlab.MeshSet()
        ms.load_new_mesh(str(path))
        m = ms.current_mesh()
        self.vertices, self.faces = m.vertex_matrix().copy(), m.face_matrix().copy()
        self.quality = m.face_scalar_array().copy() if m.has_face_scalar() else None
        self.colors = m.face_color_matrix().copy() if m.has_face_color() else None


def test_ply_has_material_as_face_colour_and_quality(tmp_path):
    poly, _, _, tri = _two_slice_mesh()
    write_mesh(poly, tmp_path / "m.ply")
    m = _Loaded(tmp_path / "m.ply")
    p, t, arrays = polydata_to_arrays(poly)
    assert np.array_equal(m.faces, t)
    np.testing.assert_allclose(m.vertices, p)
    assert m.quality.tolist() == arrays["material"].tolist()
    rgb = np.round(m.colors[:, :3] * 255).astype(int)
    assert np.array_equal(rgb, material_colors(arrays["material"]))


def test_stl_one_file_per_material(tmp_path):
    poly, _, _, _ = _two_slice_mesh()
    written, _ = write_mesh(poly, tmp_path / "m.stl")
    assert [os.path.basename(w) for w in written] == [f"m_material{k}.stl" for k in range(3)]
    assert not (tmp_path / "m.stl").exists()
    p, t, arrays = polydata_to_arrays(poly)
    for k, path in enumerate(written):
        m = _Loaded(path)
        want = t[arrays["material"] == k]
        assert len(m.faces) == len(want)
        # same triangles in space (STL repeats vertices; pymeshlab merges them back)
        got = np.sort(np.round(m.vertices[m.faces], 6).reshape(len(want), -1), axis=0)
        np.testing.assert_allclose(got, np.sort(np.round(p[want], 6).reshape(len(want), -1), axis=0))


def test_obj_one_group_per_material(tmp_path):
    poly, _, _, _ = _two_slice_mesh()
    written, _ = write_mesh(poly, tmp_path / "m.obj")
    assert [os.path.basename(w) for w in written] == ["m.obj", "m.mtl"]
    m = _Loaded(tmp_path / "m.obj")
    p, t, arrays = polydata_to_arrays(poly)
    assert len(m.faces) == len(t)
    np.testing.assert_allclose(m.vertices, p)
    # groups, read straight from the text
    group, got = None, []
    for line in (tmp_path / "m.obj").read_text().splitlines():
        if line.startswith("g "):
            group = int(line.split("_")[1])
        elif line.startswith("f "):
            got.append((group, tuple(int(v) - 1 for v in line.split()[1:])))
    want = sorted((int(k), tuple(tr)) for k, tr in zip(arrays["material"], t))
    assert sorted(got) == want
    assert "newmtl material_2" in (tmp_path / "m.mtl").read_text()


def test_meshlab_project_one_layer_per_material(tmp_path):
    import pymeshlab

    poly, _, _, _ = _two_slice_mesh()
    written, _ = write_mesh(poly, tmp_path / "m.mlp")
    assert [os.path.basename(w) for w in written] == ["m.mlp"] + [f"m_material{k}.ply" for k in range(3)]
    ms = pymeshlab.MeshSet()
    ms.load_project(str(tmp_path / "m.mlp"))
    p, t, arrays = polydata_to_arrays(poly)
    assert ms.mesh_number() == 3
    for k in range(3):
        layer = ms.mesh(k)
        want = t[arrays["material"] == k]
        got = np.sort(np.round(layer.vertex_matrix()[layer.face_matrix()], 6).reshape(len(want), -1), axis=0)
        np.testing.assert_allclose(got, np.sort(np.round(p[want], 6).reshape(len(want), -1), axis=0))
        rgb = np.round(layer.face_color_matrix()[:, :3] * 255).astype(int)
        assert np.all(rgb == material_colors([k])[0])
        assert np.all(layer.face_scalar_array() == k)


def test_failed_check_writes_nothing(tmp_path):
    # the same triangle twice: a duplicated face
    poly = mesh_to_polydata(np.array([[0, 0], [1, 0], [0, 1]], float),
                            np.array([[0, 1, 2], [0, 1, 2]]), [0, 1], [1.0, 2.0])
    for ext in (".vtp", ".ply", ".stl", ".obj", ".mlp"):
        with pytest.raises(MeshCheckError, match="duplicated_faces"):
            write_mesh(poly, tmp_path / f"m{ext}")
    assert os.listdir(tmp_path) == []


def test_boundary_polydata(tmp_path):
    pts = np.array([[0, 0], [1, 0], [2, 0]], float)
    poly = boundary_to_polydata(pts, [np.array([0, 1, 2])], np.array([[0, 2]]))
    back = read_polydata(write_polydata(poly, tmp_path / "b.vtp"))
    assert back.GetNumberOfLines() == 1 and back.GetCell(0).GetNumberOfPoints() == 3
    assert back.GetCellData().GetArray("material_b").GetValue(0) == 2


def test_unknown_format_missing_or_unwritable_folder(tmp_path):
    poly = mesh_to_polydata(np.array([[0, 0], [1, 0], [0, 1]], float), np.array([[0, 1, 2]]), [0], [1.0])
    with pytest.raises(InputError, match="unknown output format"):
        write_mesh(poly, tmp_path / "m.abc")
    with pytest.raises(InputError, match="does not exist"):
        write_mesh(poly, tmp_path / "nowhere" / "m.vtp")
    with pytest.raises(InputError, match="is a folder"):
        write_mesh(poly, tmp_path)
    with pytest.raises(InputError, match="not writable|cannot write"):  # even for root
        write_mesh(poly, "/proc/m.vtp")
