"""The 3D Slicer module's Logic on PyPI's slicer-core (MRML without the GUI).

    plugin/slicer/run_tests.sh    (or: .venv-slicer/bin/python -P -m pytest plugin/slicer/test_slicer_logic.py)

NRRD volumes with known truth, written here, are read through Slicer's own storage node
(so the IJK-to-RAS geometry is Slicer's: LPS file -> RAS scene); the Logic's nodes are
checked against that geometry and the truth, in slices mode (a simulated stack of slices)
and in 3D mode (a true 3D phantom, anisotropic voxels, in a scene of its own).
"""
import os
import sys

import numpy as np
import pytest

import slicer

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "CTSeg"))
from CTSegLib.logic import PARAMETERS, CTSegLogic, parameter_text  # noqa: E402

from ctseg.filters import array_to_image  # noqa: E402
from ctseg.metrics import dice_per_label  # noqa: E402
from ctseg.params import SPECS  # noqa: E402
from ctseg.phantoms import make_volume  # noqa: E402

SPACING = (0.2, 0.2, 0.5)
PHANTOM_SEED_3D = 0  # the phantom's shapes (not ctseg's seed parameter)
ORIGIN = (10.0, -20.0, 5.0)


def _read_nrrd(image, spacing, origin, folder, name):
    """A new scene with ``image`` (nz, ny, nx) written as an LPS NRRD and read back by
    Slicer's own storage node."""
    import nrrd

    path = str(folder / f"{name}.nrrd")
    header = {"space": "left-posterior-superior", "space origin": np.array(origin),
              "space directions": np.diag(spacing), "kinds": ["domain"] * 3}
    nrrd.write(path, image, header, index_order="C")
    scene = slicer.vtkMRMLScene()
    volume = slicer.vtkMRMLScalarVolumeNode()
    volume.SetName(name)
    scene.AddNode(volume)
    storage = slicer.vtkMRMLVolumeArchetypeStorageNode()
    scene.AddNode(storage)
    storage.SetFileName(path)
    assert storage.ReadData(volume)
    return scene, volume


@pytest.fixture(scope="module")
def loaded(tmp_path_factory):
    p = make_volume(5, 96, seed=4)
    scene, volume = _read_nrrd(p.image, SPACING, ORIGIN, tmp_path_factory.mktemp("slicer"), "part")
    logic = CTSegLogic(scene)
    params = logic.parameter_node()
    params.SetParameter("NumberOfSites", "350")
    params.SetParameter("Mode", "slices")
    steps = []
    model, segmentation, result = logic.run(volume, params, progress=lambda f, m: steps.append(f))
    return dict(scene=scene, volume=volume, logic=logic, model=model,
                segmentation=segmentation, result=result, phantom=p, steps=steps)


def _ijk_to_ras(volume):
    from vtkmodules.vtkCommonMath import vtkMatrix4x4

    m = vtkMatrix4x4()
    volume.GetIJKToRASMatrix(m)
    return np.array([[m.GetElement(r, c) for c in range(4)] for r in range(4)])


def test_geometry_is_slicers(loaded):
    """Slicer reads the LPS file into RAS: x and y flip sign."""
    mat = _ijk_to_ras(loaded["volume"])
    np.testing.assert_allclose(np.diag(mat)[:3], [-0.2, -0.2, 0.5])
    np.testing.assert_allclose(mat[:3, 3], [-10.0, 20.0, 5.0])


def test_model_node_sits_on_the_volume_in_ras(loaded):
    from vtkmodules.util import numpy_support

    poly = loaded["model"].GetPolyData()
    res = loaded["result"]
    assert poly.GetNumberOfCells() == res.diagnostics["n_triangles"]
    cd = poly.GetCellData()
    assert {cd.GetArrayName(k) for k in range(cd.GetNumberOfArrays())} >= {"material", "gray", "slice"}
    # the vertices of slice 2, mapped by Slicer's own IJK-to-RAS matrix
    mat = _ijk_to_ras(loaded["volume"])
    s2 = res.slices[2]
    ijk = np.column_stack([s2.points, np.full(len(s2.points), 2.0), np.ones(len(s2.points))])
    want = (ijk @ mat.T)[:, :3]
    pts = numpy_support.vtk_to_numpy(poly.GetPoints().GetData())
    offset = sum(len(s.points) for s in res.slices[:2])
    np.testing.assert_allclose(pts[offset:offset + len(s2.points)], want, atol=1e-9)
    display = loaded["model"].GetDisplayNode()
    assert display.GetActiveScalarName() == "material" and display.GetScalarVisibility()
    assert display.GetColorNode().GetNumberOfColors() == res.n_materials


def test_segmentation_node_matches_the_truth(loaded):
    seg = loaded["segmentation"].GetSegmentation()
    res = loaded["result"]
    assert seg.GetNumberOfSegments() == res.n_materials == 4
    names = [seg.GetNthSegment(k).GetName() for k in range(4)]
    assert all(n.startswith(f"material {k}") for k, n in enumerate(names)), names
    labelmap = slicer.vtkMRMLLabelMapVolumeNode()
    loaded["scene"].AddNode(labelmap)
    assert slicer.vtkSlicerSegmentationsModuleLogic.ExportAllSegmentsToLabelmapNode(
        loaded["segmentation"], labelmap)
    # back on the volume's voxel grid
    from vtkmodules.util import numpy_support

    assert np.allclose(_ijk_to_ras(labelmap), _ijk_to_ras(loaded["volume"]))
    img = labelmap.GetImageData()
    dims = img.GetDimensions()
    lab = numpy_support.vtk_to_numpy(img.GetPointData().GetScalars()).reshape(dims[::-1]) - 1
    truth = loaded["phantom"].truth.astype(np.int64)
    assert lab.shape == truth.shape
    dice = dice_per_label(lab, truth, 4)
    print("Dice per material (air, polymer, aluminium, steel):", np.round(dice, 3))
    assert min(dice[0], dice[2], dice[3]) >= 0.93 and dice[1] >= 0.75, dice


def test_closed_surfaces_by_the_registered_converter(loaded):
    segmentation = loaded["segmentation"]
    assert segmentation.CreateClosedSurfaceRepresentation()
    seg = segmentation.GetSegmentation()
    from vtkmodules.vtkCommonDataModel import vtkPolyData

    for k in range(1, seg.GetNumberOfSegments()):  # the solids
        surface = vtkPolyData()
        segmentation.GetClosedSurfaceRepresentation(seg.GetNthSegmentID(k), surface)
        assert surface.GetNumberOfCells() > 0


def test_parameters_and_progress(loaded):
    assert loaded["result"].slices[0].diagnostics["n_sites"] == 350
    steps = loaded["steps"]
    assert steps[0] == 0.0 and steps[-1] == 1.0 and steps == sorted(steps)
    node = loaded["logic"].parameter_node()  # the same node, found again
    assert node.GetParameter("NumberOfSites") == "350"
    # every spec parameter is in the node, under its VTK name, with the spec's default
    assert list(PARAMETERS) == [spec.vtk for spec in SPECS.values()]
    for name, spec in PARAMETERS.items():
        if name not in ("NumberOfSites", "Mode"):
            assert node.GetParameter(name) == parameter_text(spec, spec.default), name
    node.SetParameter("Lambda", "many")
    with pytest.raises(ValueError, match="Lambda"):
        loaded["logic"].parameters()
    node.SetParameter("Lambda", "50")
    assert loaded["logic"].parameters().lam == 50.0
    node.SetParameter("Lambda", parameter_text(SPECS["lam"], SPECS["lam"].default))


def test_a_node_without_image_is_refused(loaded):
    from ctseg.errors import InputError

    empty = slicer.vtkMRMLScalarVolumeNode()
    loaded["scene"].AddNode(empty)
    with pytest.raises(InputError, match="no image data"):
        loaded["logic"].run(empty)


def test_a_single_slice_node(loaded):
    """A volume node of one slice is a 2D problem under Mode 'auto', the default; its
    segments cover that slice."""
    p = loaded["phantom"]
    img = array_to_image(p.image[2])
    node = slicer.vtkMRMLScalarVolumeNode()
    node.SetName("one slice")
    node.SetSpacing(0.3, 0.3, 1.0)
    node.SetAndObserveImageData(img)
    loaded["scene"].AddNode(node)
    params = loaded["logic"].parameter_node()
    params.SetParameter("Mode", "auto")
    try:
        model, segmentation, result = loaded["logic"].run(node)
    finally:
        params.SetParameter("Mode", "slices")
    assert result.n_materials == 4 and model.GetPolyData().GetNumberOfCells() == len(result.triangles)
    assert segmentation.GetSegmentation().GetNumberOfSegments() == 4


# --- 3D mode ------------------------------------------------------------------------
SPACING_3D = (0.2, 0.2, 0.3)
ORIGIN_3D = (-4.0, 12.0, 30.0)  # LPS, as in the file


@pytest.fixture(scope="module")
def loaded3d(tmp_path_factory):
    """A true 3D phantom (43 x 64 x 64 voxels of 0.2 x 0.2 x 0.3) segmented in 3D mode,
    in a scene of its own (its parameter node says Mode 3d)."""
    import time

    from ctseg.phantoms3d import make_part_3d

    p = make_part_3d(64, seed=PHANTOM_SEED_3D, spacing=SPACING_3D)
    scene, volume = _read_nrrd(p.image, SPACING_3D, ORIGIN_3D, tmp_path_factory.mktemp("slicer3d"),
                               "part3d")
    logic = CTSegLogic(scene)
    params = logic.parameter_node()
    params.SetParameter("Mode", "3d")
    steps = []
    start = time.perf_counter()
    model, segmentation, result = logic.run(volume, params, progress=lambda f, m: steps.append(f))
    print(f"3D mode: {p.image.shape} voxels in {time.perf_counter() - start:.1f} s")
    return dict(scene=scene, volume=volume, logic=logic, model=model,
                segmentation=segmentation, result=result, phantom=p, steps=steps)


def _world(points, spacing, mat):
    """Physical box points (index x spacing) -> RAS by an IJK-to-RAS matrix."""
    ijk = np.column_stack([np.asarray(points) / np.asarray(spacing), np.ones(len(points))])
    return (ijk @ mat.T)[:, :3]


def _exported_labels(loaded3d):
    """The segments exported by Slicer to a labelmap on the volume's grid, as ctseg
    material numbers (-1 where no segment is)."""
    from vtkmodules.util import numpy_support

    segmentation, volume = loaded3d["segmentation"], loaded3d["volume"]
    seg = segmentation.GetSegmentation()
    ids = [seg.GetNthSegmentID(k) for k in range(seg.GetNumberOfSegments())]
    labelmap = slicer.vtkMRMLLabelMapVolumeNode()
    loaded3d["scene"].AddNode(labelmap)
    assert slicer.vtkSlicerSegmentationsModuleLogic.ExportSegmentsToLabelmapNode(
        segmentation, ids, labelmap, volume)
    np.testing.assert_allclose(_ijk_to_ras(labelmap), _ijk_to_ras(volume), atol=1e-12)
    img = labelmap.GetImageData()
    dims = img.GetDimensions()
    lab = numpy_support.vtk_to_numpy(img.GetPointData().GetScalars()).reshape(dims[::-1])
    return lab.astype(np.int64) - 1


def test_3d_mode_is_a_spec_parameter(loaded3d):
    from CTSegLib.logic import field_description

    assert PARAMETERS["Mode"].name == "mode"
    assert field_description(PARAMETERS["Mode"])["items"] == ["auto", "slices", "3d"]
    assert loaded3d["logic"].parameters().mode == "3d"
    res = loaded3d["result"]
    assert type(res).__name__ == "TetraSegmentation"
    np.testing.assert_allclose(res.spacing, SPACING_3D)  # the volume's spacing, physical
    steps = loaded3d["steps"]
    assert steps[0] == 0.0 and steps[-1] == 1.0 and steps == sorted(steps)


def test_3d_segments_are_ctsegs_closed_surfaces_in_ras(loaded3d):
    """One segment per material, named and coloured by material, whose source
    representation is ctseg's own closed surface (same vertices and triangles, at the
    RAS points the IJK-to-RAS matrix gives), not a converter's."""
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkCommonDataModel import vtkPolyData

    from ctseg.filters.writers import material_colors

    segmentation, res = loaded3d["segmentation"], loaded3d["result"]
    seg = segmentation.GetSegmentation()
    assert seg.GetNumberOfSegments() == res.n_materials == 4
    assert seg.GetSourceRepresentationName() == \
        slicer.vtkSegmentationConverter.GetSegmentationClosedSurfaceRepresentationName()
    mat = _ijk_to_ras(loaded3d["volume"])
    colours = set()
    for k in range(4):
        segment = seg.GetNthSegment(k)
        assert segment.GetName() == f"material {k} (gray {res.material_gray[k]:.4g})"
        np.testing.assert_allclose(segment.GetColor(), material_colors([k])[0] / 255.0)
        colours.add(tuple(np.round(segment.GetColor(), 6)))
        surface = vtkPolyData()
        assert segmentation.GetClosedSurfaceRepresentation(seg.GetNthSegmentID(k), surface)
        mine = res.surfaces[k]
        assert mine.material == k
        print(f"material {k}: {surface.GetNumberOfPoints()} vertices, "
              f"{surface.GetNumberOfCells()} triangles (ctseg: {len(mine.points)}, "
              f"{len(mine.triangles)})")
        assert (surface.GetNumberOfPoints(), surface.GetNumberOfCells()) == \
            (len(mine.points), len(mine.triangles))
        pts = numpy_support.vtk_to_numpy(surface.GetPoints().GetData())
        np.testing.assert_allclose(pts, _world(mine.points, SPACING_3D, mat), atol=1e-9)
    assert len(colours) == 4
    # the air's surface (the box and the part) would hide the part in 3D
    display = segmentation.GetDisplayNode()
    assert [display.GetSegmentVisibility3D(seg.GetNthSegmentID(k)) for k in range(4)] == \
        [False, True, True, True]


def test_3d_segments_on_the_volume_grid_match_the_truth(loaded3d):
    """The segments exported to a labelmap on the volume's grid (Slicer's closed surface
    -> binary labelmap rule) agree with the phantom's truth, and with ctseg's own
    voxelisation of its tetrahedra."""
    from ctseg.raster import tetra_label_volume

    res, p = loaded3d["result"], loaded3d["phantom"]
    lab = _exported_labels(loaded3d)
    truth = p.truth.astype(np.int64)
    assert lab.shape == truth.shape
    dice = dice_per_label(lab, truth, 4)
    own = tetra_label_volume(res.points, res.tetrahedra, res.material, truth.shape, res.spacing)
    agree = dice_per_label(lab, own, 4)
    print("3D Dice to the truth (air, polymer, aluminium, steel):", np.round(dice, 3),
          "ctseg's own voxels to the truth:", np.round(dice_per_label(own, truth, 4), 3),
          "Slicer's voxels to ctseg's:", np.round(agree, 3),
          "unlabelled voxels:", int((lab < 0).sum()))
    # measured 0.975, 0.557, 0.848, 0.899 (defaults): ctseg's 3D accuracy on a part this small
    # (README, Accuracy in 3D), the same as its own voxelisation's but for the air below
    assert dice[0] >= 0.95 and dice[1] >= 0.4 and dice[2] >= 0.7 and dice[3] >= 0.8, dice
    # measured 0.987, 1, 1, 1: the same voxels, but that the tetrahedra end at the outer
    # voxel centres, so one face of the box lies on the air's surface and is left out
    assert agree[0] >= 0.97 and agree[1:].min() >= 0.99, agree
    outer = np.ones(truth.shape, bool)
    outer[1:-1, 1:-1, 1:-1] = False
    assert not (lab < 0)[~outer].any()


def test_3d_model_is_the_tetrahedra_in_ras(loaded3d):
    """The model node holds the tetrahedra (material and gray per cell) at RAS points:
    the IJK-to-RAS matrix of ctseg's points, spanning the volume's voxel centres."""
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkCommonDataModel import VTK_TETRA

    model, res, volume = loaded3d["model"], loaded3d["result"], loaded3d["volume"]
    grid = model.GetMesh()
    assert grid.GetClassName() == "vtkUnstructuredGrid"
    assert model.GetMeshType() == model.UnstructuredGridMeshType
    assert grid.GetNumberOfCells() == len(res.tetrahedra)
    assert set(numpy_support.vtk_to_numpy(grid.GetDistinctCellTypesArray())) == {VTK_TETRA}
    cd = grid.GetCellData()
    np.testing.assert_array_equal(numpy_support.vtk_to_numpy(cd.GetArray("material")), res.material)
    np.testing.assert_allclose(numpy_support.vtk_to_numpy(cd.GetArray("gray")), res.gray)
    mat = _ijk_to_ras(volume)
    pts = numpy_support.vtk_to_numpy(grid.GetPoints().GetData())
    np.testing.assert_allclose(pts, _world(res.points, SPACING_3D, mat), atol=1e-9)
    # the tetrahedra fill the box of voxel centres: Slicer's RAS bounds less half a voxel
    ras = [0.0] * 6
    volume.GetRASBounds(ras)
    half = np.abs(np.diag(mat)[:3]) / 2
    want = np.column_stack([np.array(ras[0::2]) + half, np.array(ras[1::2]) - half]).ravel()
    np.testing.assert_allclose(grid.GetBounds(), want, atol=1e-9)
    # positive volumes in RAS
    conn = numpy_support.vtk_to_numpy(grid.GetCells().GetConnectivityArray()).reshape(-1, 4)
    a, b, c, d = (pts[conn[:, i]] for i in range(4))
    assert (np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) > 0).all()
    display = model.GetDisplayNode()
    assert display.GetActiveScalarName() == "material" and display.GetScalarVisibility()
    assert display.GetColorNode().GetNumberOfColors() == res.n_materials
    assert display.GetVisibility2D() and not display.GetVisibility3D()


def test_3d_model_materials_match_the_segments(loaded3d):
    """Each segment's closed surface encloses exactly the volume of the model's
    tetrahedra of its material (RAS), and holds their centroids."""
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkPolyData
    from vtkmodules.vtkFiltersCore import vtkMassProperties
    from vtkmodules.vtkFiltersModeling import vtkSelectEnclosedPoints

    grid = loaded3d["model"].GetMesh()
    segmentation = loaded3d["segmentation"]
    seg = segmentation.GetSegmentation()
    pts = numpy_support.vtk_to_numpy(grid.GetPoints().GetData())
    conn = numpy_support.vtk_to_numpy(grid.GetCells().GetConnectivityArray()).reshape(-1, 4)
    material = numpy_support.vtk_to_numpy(grid.GetCellData().GetArray("material"))
    a, b, c, d = (pts[conn[:, i]] for i in range(4))
    vol = np.abs(np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)) / 6
    cent = (a + b + c + d) / 4
    rng = np.random.default_rng(0)
    for k in range(seg.GetNumberOfSegments()):
        surface = vtkPolyData()
        segmentation.GetClosedSurfaceRepresentation(seg.GetNthSegmentID(k), surface)
        mass = vtkMassProperties()
        mass.SetInputData(surface)
        mass.Update()
        np.testing.assert_allclose(mass.GetVolume(), vol[material == k].sum(), rtol=1e-6)
        # centroids of (up to 200) tetrahedra of material k lie inside segment k's surface
        mine = np.flatnonzero(material == k)
        pick = rng.choice(mine, min(200, len(mine)), replace=False)
        probe = vtkPolyData()
        probe.SetPoints(vtkPoints())
        probe.GetPoints().SetData(numpy_support.numpy_to_vtk(np.ascontiguousarray(cent[pick]), deep=True))
        enclosed = vtkSelectEnclosedPoints()
        enclosed.SetInputData(probe)
        enclosed.SetSurfaceData(surface)
        enclosed.SetTolerance(1e-9)
        enclosed.Update()
        inside = [enclosed.IsInside(i) for i in range(len(pick))]
        assert np.mean(inside) >= 0.99, (k, np.mean(inside))


def test_3d_mode_refuses_a_single_slice(loaded3d):
    from ctseg.errors import InputError

    node = slicer.vtkMRMLScalarVolumeNode()
    node.SetName("one slice")
    node.SetAndObserveImageData(array_to_image(loaded3d["phantom"].image[20]))
    loaded3d["scene"].AddNode(node)
    with pytest.raises(InputError, match="3D mode needs a volume"):
        loaded3d["logic"].run(node)
