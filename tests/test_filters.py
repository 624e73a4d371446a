"""The VTK filters in real VTK pipelines, compared with the ctseg functions on the same arrays;
world geometry (spacing, origin, rotated direction); volumes slice by slice along each axis;
the same bytes from every executor."""
import numpy as np
import pytest

import ctseg
from ctseg.errors import CTSegError
from ctseg.filters import (CTSegmentFilter, CVTSitesFilter, DelaunayMeshFilter,
                           DensityMapFilter, GraphCutSegmentFilter, MaterialBoundaryFilter,
                           MetalStreakFilter, SubpixelBoundaryFilter, TriangleGrayFilter, array_to_image,
                           polydata_to_arrays)
from ctseg.geometry import AXES, ImageGeometry
from ctseg.metrics import dice_per_label
from ctseg.phantoms import make_phantom, make_volume
from ctseg.triangulation import triangle_areas
from ctseg.raster import volume_labels

from conftest import disc_image

THETA = np.deg2rad(20)
ROT = np.array([[np.cos(THETA), -np.sin(THETA), 0], [np.sin(THETA), np.cos(THETA), 0], [0, 0, 1]])
GEOM = ImageGeometry(origin=(5.0, -3.0, 1.5), spacing=(0.2, 0.3, 0.7), direction=ROT)


def _vti_reader(tmp_path, arr, geom=GEOM):
    from vtkmodules.vtkIOXML import vtkXMLImageDataReader, vtkXMLImageDataWriter

    w = vtkXMLImageDataWriter()
    w.SetFileName(str(tmp_path / "in.vti"))
    w.SetInputData(array_to_image(arr, geom))
    w.Write()
    reader = vtkXMLImageDataReader()
    reader.SetFileName(str(tmp_path / "in.vti"))
    return reader


def _write_and_reread(tmp_path, port, name="out.vtp"):
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader, vtkXMLPolyDataWriter

    writer = vtkXMLPolyDataWriter()
    writer.SetFileName(str(tmp_path / name))
    writer.SetInputConnection(port)
    assert writer.Write() == 1
    back = vtkXMLPolyDataReader()
    back.SetFileName(str(tmp_path / name))
    back.Update()
    return back.GetOutput()


def _world(points2d, k=0.0, geom=GEOM):
    return geom.to_world(np.column_stack([points2d, np.full(len(points2d), k)]))


def test_segment_filter_in_a_vtk_pipeline(tmp_path):
    """reader -> CTSegmentFilter -> writer -> reader, compared with ctseg.segment_image."""
    img, _ = disc_image(48, noise=4.0)
    seg_filter = CTSegmentFilter()
    seg_filter.SetNumberOfSites(60)
    reader = _vti_reader(tmp_path, img)  # kept alive: a port does not own its producer
    seg_filter.SetInputConnection(reader.GetOutputPort())
    progress = []
    seg_filter.AddObserver("ProgressEvent", lambda o, e: progress.append(o.GetProgress()))
    pts, tri, arrays = polydata_to_arrays(_write_and_reread(tmp_path, seg_filter.GetOutputPort(0)))
    ref = ctseg.segment_image(img, n_sites=60)
    assert np.array_equal(tri, ref.triangles)
    assert np.array_equal(arrays["material"], ref.material)
    np.testing.assert_allclose(arrays["gray"], ref.gray)
    np.testing.assert_allclose(pts, _world(ref.points), atol=1e-9)
    assert progress and max(progress) == 1.0 and progress == sorted(progress)
    # output 1: the boundary polylines, on the same world points
    bnd = seg_filter.GetOutput(1)
    lines, sides = ref.boundary_polylines()
    assert bnd.GetNumberOfLines() == len(lines)
    first = np.array([bnd.GetPoint(bnd.GetCell(0).GetPointId(q)) for q in range(len(lines[0]))])
    np.testing.assert_allclose(first, _world(ref.points[lines[0]]), atol=1e-9)


def test_stage_filters_chain_equals_segment_image(tmp_path):
    """reader -> streak correction -> density -> CVT sites -> Delaunay -> triangle gray -> graph cut -> boundary,
    each stage's output compared with the ctseg function on the same arrays."""
    from vtkmodules.util import numpy_support

    img = make_phantom(96, seed=0).image.astype(float)  # steel: the streak stage acts
    reader = _vti_reader(tmp_path, img)
    streaks = MetalStreakFilter()
    streaks.SetInputConnection(reader.GetOutputPort())
    dens = DensityMapFilter()
    dens.SetInputConnection(streaks.GetOutputPort())
    sites = CVTSitesFilter()
    sites.SetNumberOfSites(150)
    sites.SetInputConnection(dens.GetOutputPort())
    mesh = DelaunayMeshFilter()
    mesh.SetInputConnection(sites.GetOutputPort())
    gray = TriangleGrayFilter()
    gray.SetInputConnection(0, mesh.GetOutputPort())
    gray.SetInputConnection(1, streaks.GetOutputPort())
    cut = GraphCutSegmentFilter()
    cut.SetInputConnection(0, gray.GetOutputPort())
    cut.SetInputConnection(1, streaks.GetOutputPort())
    sub = SubpixelBoundaryFilter()
    sub.SetInputConnection(0, cut.GetOutputPort())
    sub.SetInputConnection(1, streaks.GetOutputPort())
    bnd = MaterialBoundaryFilter()
    bnd.SetInputConnection(sub.GetOutputPort())
    out = _write_and_reread(tmp_path, sub.GetOutputPort())
    bnd.Update()
    for f in (streaks, dens, sites, mesh, gray, cut, sub, bnd):
        assert f.last_error is None, (type(f).__name__, f.last_error)

    ref = ctseg.segment_image(img, n_sites=150)
    fd = streaks.GetOutput().GetFieldData()
    assert fd.GetArray("streak_weight").GetValue(0) == ref.diagnostics["streak_correction"]["weight"] > 0
    assert fd.GetArray("streak_halo_px").GetValue(0) == ref.diagnostics["streak_correction"]["halo_px"]
    corrected = numpy_support.vtk_to_numpy(streaks.GetOutput().GetPointData().GetScalars())
    np.testing.assert_array_equal(corrected.reshape(img.shape), ref.corrected_image)
    original = numpy_support.vtk_to_numpy(streaks.GetOutput().GetPointData().GetArray("original"))
    np.testing.assert_array_equal(original.reshape(img.shape), img)
    rho = numpy_support.vtk_to_numpy(dens.GetOutput().GetPointData().GetArray("density"))
    np.testing.assert_array_equal(rho.reshape(img.shape), ref.density)
    s_pts, _, _ = polydata_to_arrays(sites.GetOutput())
    cvt = ctseg.lloyd_cvt(ref.density, ctseg.ward_sites(ref.density, 150))
    np.testing.assert_allclose(s_pts, _world(cvt.sites), atol=1e-9)
    energy = numpy_support.vtk_to_numpy(sites.GetOutput().GetFieldData().GetArray("cvt_energy"))
    np.testing.assert_allclose(energy, ref.diagnostics["cvt_energy"])
    pts, tri, arrays = polydata_to_arrays(out)
    assert np.array_equal(tri, ref.triangles)
    np.testing.assert_allclose(pts, _world(ref.points), atol=1e-9)
    np.testing.assert_allclose(arrays["gray"], ref.gray, rtol=1e-9)
    assert np.array_equal(arrays["material"], ref.material)
    lines, sides = ref.boundary_polylines()
    got = bnd.GetOutput()
    assert got.GetNumberOfLines() == len(lines)
    a = numpy_support.vtk_to_numpy(got.GetCellData().GetArray("material_a"))
    b = numpy_support.vtk_to_numpy(got.GetCellData().GetArray("material_b"))
    assert sorted(zip(a, b)) == sorted(map(tuple, sides))


def test_stage_filters_report_what_is_missing():
    img = array_to_image(np.random.default_rng(0).random((10, 10)))
    with pytest.raises(CTSegError, match="DensityMapFilter"):
        CVTSitesFilter().apply(img)
    with pytest.raises(CTSegError, match="at least 2 voxels"):
        DensityMapFilter().apply(array_to_image(np.zeros((3, 1, 10))))
    sites = CVTSitesFilter()
    sites.SetNumberOfSites(20)
    tri = DelaunayMeshFilter().apply(sites.apply(DensityMapFilter().apply(img)))
    with pytest.raises(CTSegError, match="TriangleGrayFilter"):
        GraphCutSegmentFilter().apply(tri, img)
    with pytest.raises(CTSegError, match="geometry"):
        DelaunayMeshFilter().apply(tri.__class__())


def test_parameters_mark_modified():
    f = CTSegmentFilter()
    t0 = f.GetMTime()
    f.SetSeed(0)  # unchanged: no Modified()
    f.SetNumberOfSites("auto")
    f.SetParameter("n_sites", 0)  # the AUTO number
    assert f.GetMTime() == t0
    f.SetNumberOfMaterials(2)
    assert f.GetMTime() > t0 and f.GetNumberOfMaterials() == 2
    t1 = f.GetMTime()
    f.SetParameter("lam", 50.0)
    assert f.GetMTime() > t1 and f.GetParameter("lam") == 50.0 == f.GetLambda()
    assert f.params.lam == 50.0 and f.params.beta == ctseg.SegmentParams().beta
    with pytest.raises(CTSegError, match="did you mean 'lam'"):
        f.SetParameter("lambda", 1.0)
    f.SetSliceAxis("x")
    assert f.GetSliceAxis() == "x"


def test_numbers_from_vtk_and_python_values():
    """0 is AUTO where a parameter may be automatic, a choice index is that choice; Python
    values are checked by the spec, and an error names parameter, value and range."""
    from ctseg.params import AUTO, SPECS

    f = CTSegmentFilter()
    f.SetNumberOfSites(300)
    assert f.GetNumberOfSites() == 300
    f.SetNumberOfSites(0)
    assert f.GetNumberOfSites() == AUTO
    f.SetSliceAxis(2)
    assert f.GetSliceAxis() == SPECS["axis"].choices[2]
    f.SetInitialization(1)
    assert f.GetInitialization() == SPECS["init"].choices[1]
    f.SetStreakCorrection(0)
    assert f.GetStreakCorrection() is False
    f.SetTheta255(0.0)
    assert f.GetTheta255() == AUTO
    with pytest.raises(CTSegError, match=r"n_sites: 2 is not valid; valid: \[4, "):
        f.SetNumberOfSites(2)
    with pytest.raises(CTSegError, match="choice index 3"):
        f.SetSliceAxis(3)
    with pytest.raises(CTSegError, match="density_floor"):
        f.SetDensityFloor(0)  # no auto: 0 is a value, and out of range
    d = DensityMapFilter()
    d.SetDensityFloor(0.05)
    assert d.GetParameter("density_floor") == 0.05 and d.density_kwargs()["density_floor"] == 0.05
    with pytest.raises(CTSegError, match="not a parameter of DensityMapFilter"):
        d.SetParameter("lam", 50.0)  # another stage's
    with pytest.raises(CTSegError, match="did you mean 'density_floor'"):
        d.SetParameter("floor", 0.05)
    with pytest.raises(CTSegError, match="lambda: not a ctseg parameter; did you mean 'lam'"):
        CTSegmentFilter().SetParameter("lambda", 3.0)  # no parameter at all, not another stage's
    assert not hasattr(d, "SetFloor") and not hasattr(d, "SetSaturation")


def test_stage_parameters_reach_the_stage():
    """A parameter set on a stage filter changes what that stage computes, as the same
    keyword does for the ctseg function."""
    from vtkmodules.util import numpy_support

    img, _ = disc_image(32, noise=2.0)
    dens = DensityMapFilter()
    dens.SetDensityRidge(0.0)
    dens.SetDensitySaturation(1.0)
    out = dens.apply(array_to_image(img))
    rho = numpy_support.vtk_to_numpy(out.GetPointData().GetArray("density")).reshape(img.shape)
    np.testing.assert_array_equal(rho, ctseg.density_map(img, density_ridge=0.0,
                                                         density_saturation=1.0))
    sites = CVTSitesFilter()
    sites.SetNumberOfSites(30)
    sites.SetInitialization("random")
    sites.SetMaximumIterations(3)
    s_out = sites.apply(out)
    cvt = ctseg.lloyd_cvt(rho, ctseg.initial_sites(rho, 30, init="random"), max_iter=3)
    np.testing.assert_allclose(polydata_to_arrays(s_out)[0], _world(cvt.sites, geom=ImageGeometry()))


def test_auto_site_count_is_segment_images():
    """NumberOfSites auto: the stage chain counts sites as segment_image does (the
    boundary rule on the gray slice), here where edge length, not the size rule,
    decides (a porous casting slice: far more sites than one per 128 px)."""
    from ctseg.phantoms_granular import make_granular

    img = make_granular("casting", 96, seed=0).image.astype(float)
    seg = ctseg.segment_image(img, max_iter=1)
    budget = seg.diagnostics["sites"]
    assert budget["rule"] in ("boundary", "dense") and budget["n_sites"] > 2 * img.size / 128
    sites = CVTSitesFilter()
    sites.SetMaximumIterations(1)
    out = sites.apply(DensityMapFilter().apply(array_to_image(img)))
    assert out.GetNumberOfPoints() == len(seg.points)  # the sites and the border's
    sites.SetSiteRule("area")
    assert sites.apply(DensityMapFilter().apply(array_to_image(img))).GetNumberOfPoints() \
        == len(ctseg.segment_image(img, max_iter=1, site_rule="area").points)


def test_errors_are_reported_not_silent():
    from vtkmodules.vtkCommonCore import vtkOutputWindow, vtkStringOutputWindow

    sink = vtkStringOutputWindow()
    vtkOutputWindow.SetInstance(sink)
    try:
        f = CTSegmentFilter()
        f.SetNumberOfSites(101)  # valid in itself, too many for 10 x 10 pixels
        with pytest.raises(CTSegError, match="n_sites"):
            f.apply(array_to_image(np.random.default_rng(0).random((10, 10))))
        assert "n_sites" in sink.GetOutput()
        assert f.GetOutputDataObject(0).GetNumberOfCells() == 0
    finally:
        vtkOutputWindow.SetInstance(None)


@pytest.fixture(scope="module")
def volume():
    return make_volume(8, 96, seed=0)


def test_volume_slice_by_slice_with_known_truth(tmp_path, volume):
    """A 96 x 96 x 8 part (air, polymer, aluminium, steel; pores, a ball) through
    reader -> CTSegmentFilter: slices at their world positions, one material numbering."""
    from vtkmodules.util import numpy_support

    seg_filter = CTSegmentFilter()
    seg_filter.SetMode("slices")
    seg_filter.SetNumberOfSites(350)
    reader = _vti_reader(tmp_path, volume.image)
    seg_filter.SetInputConnection(reader.GetOutputPort())
    out = _write_and_reread(tmp_path, seg_filter.GetOutputPort())
    pts, tri, arrays = polydata_to_arrays(out)
    res = seg_filter.result
    assert len(res.slices) == 8 and res.n_materials == 4
    # each slice's triangles sit at that slice's k in index space
    ijk = GEOM.to_index(pts)
    k_of_cell = ijk[tri[:, 0], 2]
    np.testing.assert_allclose(k_of_cell, arrays["slice"], atol=1e-9)
    assert np.array_equal(np.unique(arrays["slice"]), np.arange(8))
    # one numbering: slice 1 holds air, aluminium and steel (no polymer), numbered as in
    # the whole volume (0, 2, 3), not 0..2 as a slice on its own would be
    assert set(np.unique(volume.truth[1])) == {0, 2, 3}
    # (by area: a 4.5 px^2 sliver where aluminium, steel and air meet reads as polymer)
    s1 = res.slices[1]
    area = np.bincount(s1.material, triangle_areas(s1.points, s1.triangles), 4)
    assert set(np.flatnonzero(area > 0.005 * area.sum())) == {0, 2, 3}
    assert set(np.unique(res.slices[0].material)) == {0}
    dice = dice_per_label(volume_labels(res, volume.image.shape), volume.truth.astype(np.int64), 4)
    assert min(dice[0], dice[2]) >= 0.97 and dice[3] >= 0.93 and dice[1] >= 0.93, dice
    mg = numpy_support.vtk_to_numpy(out.GetCellData().GetArray("gray"))
    assert len(mg) == len(tri)


@pytest.mark.parametrize("axis", ["y", "x"])
def test_volume_along_other_axes(axis, volume):
    """Slices along y or x sit at their index along that axis; every voxel of the volume is
    covered by exactly one slice's mesh."""
    vol = volume.image[:, 20:60, 24:56]  # (8, 40, 32): slices differ in shape by axis
    f = CTSegmentFilter()
    f.SetMode("slices")
    f.SetSliceAxis(axis)
    f.SetNumberOfSites(40)
    out = f.apply(array_to_image(vol, GEOM))
    pts, tri, arrays = polydata_to_arrays(out)
    ijk = GEOM.to_index(pts)
    col = {"y": 1, "x": 0}[axis]  # VTK index column of the slice axis
    np.testing.assert_allclose(ijk[tri[:, 0], col], arrays["slice"], atol=1e-9)
    assert len(f.result.slices) == vol.shape[AXES[axis]]
    other = [c for c in range(3) if c != col]
    extent = np.array([vol.shape[2], vol.shape[1], vol.shape[0]]) - 1
    np.testing.assert_allclose(ijk[:, other].min(axis=0), 0, atol=1e-9)
    np.testing.assert_allclose(ijk[:, other].max(axis=0), extent[other], atol=1e-9)


def test_same_bytes_from_every_executor(tmp_path, volume):
    """Serial, two local processes and a Dask LocalCluster write identical files."""
    from distributed import Client, LocalCluster

    from ctseg.filters import write_mesh

    vol = volume.image[2:6, 16:80, 16:80]
    files = {}

    def run(name, **kw):
        f = CTSegmentFilter()
        f.SetMode("slices")
        f.SetNumberOfSites(80)
        f.SetNumberOfJobs(kw.get("n_jobs", 1))
        if "client" in kw:
            f.SetDaskClient(kw["client"])
        mesh = f.apply(array_to_image(vol, GEOM))
        write_mesh(mesh, tmp_path / f"{name}.vtp")
        files[name] = (tmp_path / f"{name}.vtp").read_bytes()
        return f.result.diagnostics["executor"]

    assert run("serial") == "serial"
    assert run("processes", n_jobs=2) == "2 processes"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        assert run("dask", client=client) == "dask"
    assert files["serial"] == files["processes"] == files["dask"]


def test_a_failing_slice_is_named():
    from ctseg.volume import segment_volume

    vol = np.random.default_rng(0).random((3, 12, 12))
    with pytest.raises(CTSegError, match="slice 0: n_sites"):
        segment_volume(vol, mode="slices", n_sites=1000, n_jobs=1)


def test_volume_keeps_the_per_pixel_maps_of_the_figure_slice_only():
    from ctseg.phantoms import make_phantom
    from ctseg.volume import segment_volume
    vol = np.stack([make_phantom(96, seed=0).image] * 3)
    res = segment_volume(vol, mode="slices", n_sites=200, keep_maps=(1,))
    kept = res.slices[1]
    assert kept.density is not None and kept.cvt_labels is not None
    # the slice holds steel and its streaks: it was corrected and keeps that image too
    assert kept.diagnostics["streak_correction"]["weight"] > 0
    assert kept.corrected_image is not None and kept.corrected_image.shape == (96, 96)
    for k in (0, 2):
        s = res.slices[k]
        assert s.density is None and s.cvt_labels is None and s.corrected_image is None


def test_geometry_and_array_to_image():
    """ImageGeometry is ctseg's (no VTK); the VTK layer carries it on images and in field
    data; array_to_image is the one array -> vtkImageData conversion."""
    from vtkmodules.vtkCommonDataModel import vtkPolyData

    import ctseg.geometry
    from ctseg.filters import attach_geometry, geometry_from_field_data, image_to_array

    assert ImageGeometry is ctseg.geometry.ImageGeometry is ctseg.filters.ImageGeometry
    ijk = np.array([[1.0, 2.0, 3.0], [0.5, -1.0, 0.0]])
    np.testing.assert_allclose(GEOM.to_index(GEOM.to_world(ijk)), ijk)
    for bad in (dict(spacing=(1, 0, 1)), dict(origin=(0, 0)), dict(direction=np.zeros((3, 3)))):
        with pytest.raises(CTSegError, match="geometry"):
            ImageGeometry(**bad)
    vol = np.arange(2 * 3 * 4, dtype=float).reshape(2, 3, 4)
    arr, geom = image_to_array(array_to_image(vol, GEOM))
    assert np.array_equal(arr, vol) and geom == GEOM
    rgb = np.arange(3 * 4 * 3).reshape(3, 4, 3).astype(np.uint8)
    img = array_to_image(rgb, components=3)
    assert img.GetDimensions() == (4, 3, 1)
    assert img.GetPointData().GetScalars().GetTuple3(1) == tuple(float(v) for v in rgb[0, 1])
    with pytest.raises(CTSegError, match="3 components"):
        array_to_image(vol, components=3)
    poly = vtkPolyData()
    attach_geometry(poly, GEOM, (3, 4))
    assert geometry_from_field_data(poly) == (GEOM, (3, 4))


@pytest.mark.parametrize("voi", [(10, 39, 0, 31, 5, 5), (3, 36, 4, 27, 1, 6)])
def test_a_cropped_image_keeps_its_place(voi):
    """vtkExtractVOI (and ParaView's Extract Subset, a .vti with an offset extent) gives an
    image whose extent does not start at 0: VTK's point (i, j, k) of the extent lies at
    origin + D (i, j, k) * spacing. The mesh lies where those points are, in 2D and 3D."""
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkImagingCore import vtkExtractVOI

    from ctseg.filters import image_to_array

    vol = np.full((8, 32, 40), 50.0)
    vol[:, 8:24, 10:30] = 200.0
    vol += np.random.default_rng(0).normal(0, 3, vol.shape)
    # VTK 9.7's vtkExtractVOI garbles the origin of an image with a direction matrix: the
    # crop is made on an axis-aligned one, the direction checked on a hand-made extent below
    geom = ImageGeometry(origin=(5.0, -3.0, 1.5), spacing=(0.2, 0.3, 0.7))
    crop = vtkExtractVOI()
    crop.SetInputData(array_to_image(vol, geom))
    crop.SetVOI(*voi)
    crop.Update()
    first, last = np.array(voi[::2], float), np.array(voi[1::2], float)
    arr, got = image_to_array(crop.GetOutput())
    np.testing.assert_allclose(got.to_world(np.zeros(3)), geom.to_world(first), atol=1e-9)
    assert np.array_equal(arr, vol[voi[4]:voi[5] + 1, voi[2]:voi[3] + 1, voi[0]:voi[1] + 1].squeeze())
    seg = CTSegmentFilter()
    seg.SetInputConnection(crop.GetOutputPort())
    seg.SetNumberOfSites(60)
    seg.Update()
    assert seg.last_error is None
    mesh = seg.GetOutput(0)
    pts = numpy_support.vtk_to_numpy((mesh.GetPoints() if hasattr(mesh, "GetPoints") else
                                      mesh.GetBlock(0).GetPoints()).GetData())
    np.testing.assert_allclose(pts.min(axis=0), geom.to_world(first), atol=1e-6)
    np.testing.assert_allclose(pts.max(axis=0), geom.to_world(last), atol=1e-6)
    # a rotated image whose extent starts at `first`
    img = array_to_image(arr, GEOM)
    img.SetExtent(voi)
    _, got = image_to_array(img)
    np.testing.assert_allclose(got.to_world(np.zeros(3)), GEOM.to_world(first), atol=1e-9)
    np.testing.assert_allclose(got.to_world(last - first), GEOM.to_world(last), atol=1e-9)


def test_delaunay_stage_on_a_rotated_anisotropic_slice():
    """The sites come back from world to index coordinates 1e-15 off the border lines under
    a rotation with anisotropic spacing; the stage filter puts them back (a fuzz case that
    gave Qhull a zero-area sliver) and meshes as the composite does."""
    from vtkmodules.util import numpy_support

    from ctseg.filters import DensityMapFilter

    a = np.full((32, 40), 50.0)
    a[10:30, 8:30] = 150.0
    a += np.random.default_rng(0).normal(0, 3, a.shape)
    th = np.deg2rad(20)
    rot = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])
    img = array_to_image(a, ImageGeometry(origin=(3, 4, 5), spacing=(0.5, 0.25, 2), direction=rot))
    dens = DensityMapFilter()
    dens.SetInputDataObject(img)
    sites = CVTSitesFilter()
    sites.SetInputConnection(dens.GetOutputPort())
    sites.SetNumberOfSites(60)
    mesh = DelaunayMeshFilter()
    mesh.SetInputConnection(sites.GetOutputPort())
    mesh.Update()
    assert mesh.last_error is None, mesh.last_error
    comp = CTSegmentFilter()
    comp.SetInputDataObject(img)
    comp.SetNumberOfSites(60)
    comp.Update()
    assert mesh.GetOutput().GetNumberOfCells() == comp.GetOutput(0).GetNumberOfCells()
    got = numpy_support.vtk_to_numpy(mesh.GetOutput().GetPoints().GetData())
    assert np.isfinite(got).all()


def test_the_gray_values_can_be_a_point_array_that_is_not_active():
    """VTK's SetInputArrayToProcess (ParaView's "Gray Values") picks the point array the
    filters read; without it they read the active scalars. Here the active array is a
    label map and the gray values another array: the composite and the stages given the
    gray array's name give what ctseg gives on it; a wrong name is refused, naming the
    arrays there are."""
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkCommonDataModel import vtkDataObject

    from ctseg.beam_hardening import correct_streaks
    from ctseg.filters.convert import _point_array

    img = make_phantom(64, seed=0).image.astype(float)
    image = array_to_image((img > img.mean()).astype(float), name="labels")
    image.GetPointData().AddArray(_point_array(img, "gray"))

    def choose(f, name="gray"):
        f.SetInputArrayToProcess(0, 0, 0, vtkDataObject.FIELD_ASSOCIATION_POINTS, name)
        return f

    ref = ctseg.segment_image(img, n_sites=80)
    seg = choose(CTSegmentFilter())
    seg.SetNumberOfSites(80)
    _, tri, arrays = polydata_to_arrays(seg.apply(image))
    assert np.array_equal(tri, ref.triangles) and np.array_equal(arrays["material"], ref.material)
    np.testing.assert_allclose(arrays["gray"], ref.gray)
    plain = CTSegmentFilter()
    plain.SetNumberOfSites(80)
    assert polydata_to_arrays(plain.apply(image))[2]["gray"].max() <= 1.0  # the labels
    rho = choose(DensityMapFilter()).apply(image).GetPointData().GetArray("density")
    np.testing.assert_array_equal(numpy_support.vtk_to_numpy(rho).reshape(img.shape),
                                  ctseg.density_map(img))
    fixed = choose(MetalStreakFilter()).apply(image).GetPointData()
    np.testing.assert_array_equal(numpy_support.vtk_to_numpy(fixed.GetArray("gray")).reshape(img.shape),
                                  correct_streaks(img).image)
    assert fixed.GetScalars().GetName() == "gray" and fixed.GetArray("labels") is not None
    gray = choose(TriangleGrayFilter())
    got = polydata_to_arrays(gray.apply(seg.GetOutput(), image))[2]["gray"]
    np.testing.assert_allclose(got, ctseg.triangle_gray(img, ref.points, ref.triangles), rtol=1e-9)
    with pytest.raises(CTSegError, match=r"no point array named 'grey' \(its point arrays: labels, gray\)"):
        choose(CTSegmentFilter(), "grey").apply(image)
