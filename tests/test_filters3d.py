"""The stage filters on volumes (3D mode) in real VTK pipelines: .vti reader -> density ->
CVT sites -> Delaunay tetrahedra -> tetrahedron gray -> graph cut -> interfaces, written and
read back, each stage compared with the ctseg stage function on the same arrays, and the
chain compared with CTSegmentFilter's Mode '3d' output (same points, tetrahedra, materials,
interfaces) under a rotated and a mirrored (LPS) direction; progress; wrong inputs."""
import numpy as np
import pytest
from vtkmodules.util import numpy_support

from ctseg.errors import CTSegError
from ctseg.filters import (CTSegmentFilter, CVTSitesFilter, DelaunayMeshFilter,
                           DelaunayTetraFilter, DensityMapFilter, GraphCutSegmentFilter,
                           MaterialBoundaryFilter, SubpixelBoundaryFilter, TriangleGrayFilter,
                           array_to_image, polydata_to_arrays)
from ctseg.filters.convert3d import grid_to_arrays
from ctseg.geometry import ImageGeometry
from ctseg.params import resolve
from ctseg.phantoms import make_volume
from ctseg.phantoms3d import make_part_3d
from ctseg.stages3d import cvt_sites_3d, density_3d, tetrahedra_3d
from ctseg.tetrahedra import tetra_volumes

N_SITES = 200
SPACING = (0.8, 0.9, 1.2)


def _rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


ROT = _rotation((1, 2, 3), 0.7)
GEOMETRIES = {
    "rotated": ImageGeometry(origin=(5.0, -3.0, 1.5), spacing=SPACING, direction=ROT),
    "lps": ImageGeometry(origin=(-20.0, 7.0, 3.0), spacing=SPACING,
                         direction=ROT @ np.diag([-1.0, 1.0, 1.0])),
}


@pytest.fixture(scope="module")
def volume():
    vol = make_volume(8, 32, seed=3).image[:, 1:31, :]  # air, aluminium, a thin polymer ring, steel
    assert len(set(vol.shape)) == 3  # every axis its own length: no axis mix-up hides
    return vol


def _vti_reader(path, arr, geom):
    from vtkmodules.vtkIOXML import vtkXMLImageDataReader, vtkXMLImageDataWriter

    w = vtkXMLImageDataWriter()
    w.SetFileName(str(path))
    w.SetInputData(array_to_image(arr, geom))
    assert w.Write() == 1
    reader = vtkXMLImageDataReader()
    reader.SetFileName(str(path))
    return reader


def _round_trip(port, path):
    """Write an algorithm's output port to an XML file and read it back."""
    from vtkmodules.vtkIOXML import (vtkXMLPolyDataReader, vtkXMLPolyDataWriter,
                                     vtkXMLUnstructuredGridReader, vtkXMLUnstructuredGridWriter)

    grid = str(path).endswith(".vtu")
    writer = vtkXMLUnstructuredGridWriter() if grid else vtkXMLPolyDataWriter()
    writer.SetFileName(str(path))
    writer.SetInputConnection(port)
    assert writer.Write() == 1
    reader = vtkXMLUnstructuredGridReader() if grid else vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    return reader.GetOutput()


def _watch(*filters):
    seen = {type(f).__name__: [] for f in filters}
    for f in filters:
        f.AddObserver("ProgressEvent",
                      lambda o, e, name=type(f).__name__: seen[name].append(o.GetProgress()))
    return seen


def _field(data, name):
    return numpy_support.vtk_to_numpy(data.GetFieldData().GetArray(name))


def _canonical(triangles, *columns):
    """Each triangle rotated to start at its smallest vertex (orientation kept), with
    per-triangle ``columns`` appended, rows sorted."""
    t = np.asarray(triangles, np.int64)
    rows = np.arange(len(t))[:, None]
    rolled = t[rows, (np.argmin(t, axis=1)[:, None] + np.arange(3)) % 3]
    rolled = np.column_stack([rolled, *columns])
    return rolled[np.lexsort(rolled.T[::-1])]


@pytest.mark.parametrize("name", list(GEOMETRIES))
def test_stage_chain_equals_the_composite_3d(tmp_path, volume, name):
    geom = GEOMETRIES[name]
    reader = _vti_reader(tmp_path / "in.vti", volume, geom)
    dens = DensityMapFilter()
    dens.SetInputConnection(reader.GetOutputPort())
    sites = CVTSitesFilter()
    sites.SetNumberOfSites(N_SITES)
    sites.SetInputConnection(dens.GetOutputPort())
    tets = DelaunayTetraFilter()
    tets.SetInputConnection(sites.GetOutputPort())
    gray = TriangleGrayFilter()
    gray.SetInputConnection(0, tets.GetOutputPort())
    gray.SetInputConnection(1, reader.GetOutputPort())
    cut = GraphCutSegmentFilter()
    cut.SetInputConnection(0, gray.GetOutputPort())
    cut.SetInputConnection(1, reader.GetOutputPort())
    sub = SubpixelBoundaryFilter()
    sub.SetInputConnection(0, cut.GetOutputPort())
    sub.SetInputConnection(1, reader.GetOutputPort())
    bnd = MaterialBoundaryFilter()
    bnd.SetInputConnection(sub.GetOutputPort())
    stages = (dens, sites, tets, gray, cut, sub, bnd)
    progress = _watch(*stages)
    out = _round_trip(sub.GetOutputPort(), tmp_path / "tets.vtu")
    faces_out = _round_trip(bnd.GetOutputPort(), tmp_path / "interfaces.vtp")
    for f in stages:
        assert f.last_error is None, (type(f).__name__, f.last_error)
    for stage, values in progress.items():  # every stage reported, in order, to the end
        assert values and values == sorted(values) and values[-1] == 1.0, (stage, values)
    assert len(progress["CVTSitesFilter"]) > 3 and len(progress["GraphCutSegmentFilter"]) > 3

    # each stage as the ctseg stage function on the same arrays
    p = resolve(None, n_sites=N_SITES)
    rho = density_3d(volume, p, SPACING)
    got = numpy_support.vtk_to_numpy(dens.GetOutput().GetPointData().GetArray("density"))
    np.testing.assert_array_equal(got.reshape(volume.shape), rho)
    cvt = cvt_sites_3d(rho, p, SPACING)
    s_pts = numpy_support.vtk_to_numpy(sites.GetOutput().GetPoints().GetData())
    np.testing.assert_allclose(s_pts, geom.to_world(cvt.sites / SPACING), atol=1e-9)
    site_class = sites.GetOutput().GetPointData().GetArray("site_class")
    np.testing.assert_array_equal(numpy_support.vtk_to_numpy(site_class), cvt.site_class)
    np.testing.assert_allclose(_field(sites.GetOutput(), "cvt_energy"), cvt.energy)
    mesh, slivers = tetrahedra_3d(cvt.sites, volume.shape, p, SPACING)
    assert _field(tets.GetOutput(), "slivers_left")[0] == slivers
    t_pts, t_tets, _ = grid_to_arrays(tets.GetOutput())
    assert len(t_tets) == len(mesh.tetrahedra)
    assert tetra_volumes(t_pts, t_tets).min() > 0  # positive in world space, mirrored or not

    # the chain, written and read back, is the composite's Mode '3d' output
    comp = CTSegmentFilter()
    comp.SetInputConnection(reader.GetOutputPort())
    comp.SetMode("3d")
    comp.SetNumberOfSites(N_SITES)
    comp.SetStreakCorrection(False)  # the 3D stage chain has no streak stage
    comp_progress = _watch(comp)["CTSegmentFilter"]
    comp.Update()
    assert comp.last_error is None and comp_progress[-1] == 1.0
    ref_pts, ref_tets, ref_arrays = grid_to_arrays(comp.GetOutput(0))
    pts, tet_ids, arrays = grid_to_arrays(out)
    assert np.array_equal(tet_ids, ref_tets)
    np.testing.assert_allclose(pts, ref_pts, atol=1e-9)
    assert np.array_equal(arrays["material"], ref_arrays["material"])
    np.testing.assert_allclose(arrays["gray"], ref_arrays["gray"], rtol=1e-9)
    np.testing.assert_allclose(_field(out, "material_gray"), comp.result.material_gray,
                               rtol=1e-9)
    assert _field(out, "relabelled_for_manifold")[0] == \
        comp.result.diagnostics["relabelled_for_manifold"]
    assert _field(out, "subpixel_moved")[0] == comp.result.diagnostics["subpixel_moved"] > 0
    # air, aluminium and steel: the 2-voxel polymer ring is too thin for a level of its own
    # at this size (a fourth level here was a partial-volume mode, before levels needed a core)
    assert len(np.unique(arrays["material"])) == 3
    assert comp.result.diagnostics["relabelled_for_manifold"] > 0  # the repair ran
    assert comp.result.diagnostics["blur_px"] is not None  # and the blur correction

    # a grid without the recorded box coordinates (the composite's) maps its world points
    # again: the same gray up to round-off
    regray = TriangleGrayFilter().apply(comp.GetOutput(0), reader.GetOutput())
    assert regray.IsA("vtkUnstructuredGrid")
    np.testing.assert_allclose(grid_to_arrays(regray)[2]["gray"], ref_arrays["gray"], rtol=1e-9)

    # interfaces: the same oriented triangles and sides as the composite's output 1; on its
    # own grid exactly its output 1
    ref_faces = comp.GetOutput(1)
    f_pts, f_tri, f_arr = polydata_to_arrays(faces_out)
    r_pts, r_tri, r_arr = polydata_to_arrays(ref_faces)
    np.testing.assert_allclose(f_pts, r_pts, atol=1e-9)
    key = lambda tri, arr: _canonical(tri, arr["material_a"], arr["material_b"])
    assert np.array_equal(key(f_tri, f_arr), key(r_tri, r_arr))
    own = MaterialBoundaryFilter().apply(comp.GetOutput(0))
    o_pts, o_tri, o_arr = polydata_to_arrays(own)
    assert np.array_equal(_canonical(o_tri), _canonical(r_tri))
    if name == "rotated":  # no mirror: the same faces in the same order
        assert np.array_equal(o_tri, r_tri) and np.array_equal(f_tri, r_tri)
        assert all(np.array_equal(o_arr[k], r_arr[k]) for k in ("material_a", "material_b"))


def test_one_slice_keeps_the_2d_stages():
    """A one-slice image through the same classes is the slices mode (triangles)."""
    img = make_part_3d(size=20, seed=0).image[10]
    dens = DensityMapFilter().apply(array_to_image(img))
    sites = CVTSitesFilter()
    sites.SetNumberOfSites(40)
    tri = DelaunayMeshFilter().apply(sites.apply(dens))
    assert tri.IsA("vtkPolyData") and tri.GetNumberOfPolys() > 0
    assert sites.GetOutput().GetPointData().GetArray("site_class") is None
    gray = TriangleGrayFilter().apply(tri, array_to_image(img))
    assert gray.IsA("vtkPolyData") and gray.GetCellData().GetArray("gray") is not None


@pytest.fixture(scope="module")
def small():
    """A small volume, its density image, 3D sites and tetrahedra."""
    vol = make_part_3d(size=12, seed=2).image
    image = array_to_image(vol, ImageGeometry(spacing=(0.5, 0.5, 0.5)))
    dens = DensityMapFilter().apply(image)
    sites = CVTSitesFilter()
    sites.SetNumberOfSites(40)
    pts = sites.apply(dens)
    grid = DelaunayTetraFilter().apply(pts)
    return vol, image, pts, grid


def test_wrong_inputs_say_what_is_missing(small):
    vol, image, sites3d, grid = small
    with pytest.raises(CTSegError, match="TriangleGrayFilter"):
        GraphCutSegmentFilter().apply(grid, image)  # a tetra grid without gray
    cut = GraphCutSegmentFilter()
    with pytest.raises(CTSegError):
        cut.apply(grid, image)
    assert cut.GetOutput().GetNumberOfCells() == 0  # left empty, not wrong
    with pytest.raises(CTSegError, match="GraphCutSegmentFilter"):
        MaterialBoundaryFilter().apply(grid)  # no material
    with pytest.raises(CTSegError, match="DelaunayTetraFilter"):
        DelaunayMeshFilter().apply(sites3d)
    slice_sites = CVTSitesFilter()
    slice_sites.SetNumberOfSites(20)
    sites2d = slice_sites.apply(DensityMapFilter().apply(array_to_image(vol[5])))
    with pytest.raises(CTSegError, match="DelaunayMeshFilter"):
        DelaunayTetraFilter().apply(sites2d)
    with pytest.raises(CTSegError, match="volume"):
        TriangleGrayFilter().apply(grid, array_to_image(vol[5]))  # tetrahedra over one slice
    with pytest.raises(CTSegError, match="at least 2 voxels"):
        DensityMapFilter().apply(array_to_image(np.zeros((4, 1, 10))))
    with pytest.raises(CTSegError, match="outside the volume"):
        other = ImageGeometry(origin=(3.0, 0.0, 0.0), spacing=(0.5, 0.5, 0.5))
        TriangleGrayFilter().apply(grid, array_to_image(vol, other))
    from vtkmodules.vtkCommonTransforms import vtkTransform
    from vtkmodules.vtkFiltersGeneral import vtkTransformFilter

    move = vtkTransform()
    move.Translate(100.0, 0.0, 0.0)
    moved = vtkTransformFilter()
    moved.SetTransform(move)
    moved.SetInputData(grid)
    moved.Update()  # its recorded box coordinates are stale now: the points are used
    assert moved.GetOutput().GetPointData().GetArray("ctseg_box_coordinates") is not None
    with pytest.raises(CTSegError, match="outside the volume"):
        TriangleGrayFilter().apply(moved.GetOutput(), image)
    with pytest.raises(CTSegError, match="n_sites"):
        too_many = CVTSitesFilter()
        too_many.SetNumberOfSites(vol.size + 1)
        too_many.apply(DensityMapFilter().apply(image))


def test_3d_parameters_reach_their_stage(small):
    vol, image, sites3d, grid = small
    assert set(DelaunayTetraFilter.PARAMETERS) == {"sliver_min_dihedral_deg", "sliver_rounds",
                                                   "seed"}
    assert "voxels_per_site" in CVTSitesFilter.PARAMETERS
    auto = CVTSitesFilter()
    auto.SetVoxelsPerSite(vol.size / 70)
    pts = auto.apply(DensityMapFilter().apply(image))
    cvt = cvt_sites_3d(density_3d(vol, None, (0.5, 0.5, 0.5)), resolve(None, n_sites=70),
                       (0.5, 0.5, 0.5))
    assert pts.GetNumberOfPoints() == len(cvt.sites)
    none = DelaunayTetraFilter()
    none.SetSliverRounds(0)
    assert _field(none.apply(sites3d), "slivers_left")[0] >= _field(grid, "slivers_left")[0]


def test_mode_auto_output_type_by_shape_and_dask_client(volume):
    """Mode 'auto': tetrahedra (a grid) for a volume, triangles for a thin volume and for a
    volume whose slices go to a Dask cluster (decided before any work is done)."""
    from vtkmodules.vtkCommonExecutionModel import vtkTrivialProducer

    def output_class(arr, client=None):
        src = vtkTrivialProducer()
        src.SetOutput(array_to_image(arr))
        f = CTSegmentFilter()
        f.SetInputConnection(src.GetOutputPort())
        if client:
            f.SetDaskClient(client)
        f.UpdateDataObject()
        return f.GetOutputDataObject(0).GetClassName()

    assert output_class(volume) == "vtkUnstructuredGrid"
    assert output_class(volume[:, :1, :]) == "vtkPolyData"
    assert output_class(volume, client="tcp://127.0.0.1:1") == "vtkPolyData"
