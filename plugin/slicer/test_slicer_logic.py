"""The 3D Slicer module's Logic on PyPI's slicer-core (MRML without the GUI).

    .venv-slicer/bin/python -m pytest plugin/slicer/test_slicer_logic.py

A NRRD volume with known truth, written here, is read through Slicer's own storage node
(so the IJK-to-RAS geometry is Slicer's: LPS file -> RAS scene); the Logic's nodes are
checked against that geometry and the truth.
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
ORIGIN = (10.0, -20.0, 5.0)


@pytest.fixture(scope="module")
def loaded(tmp_path_factory):
    import nrrd

    p = make_volume(5, 96, seed=4)
    path = str(tmp_path_factory.mktemp("slicer") / "part.nrrd")
    header = {"space": "left-posterior-superior", "space origin": np.array(ORIGIN),
              "space directions": np.diag(SPACING), "kinds": ["domain"] * 3}
    nrrd.write(path, p.image, header, index_order="C")
    scene = slicer.vtkMRMLScene()
    volume = slicer.vtkMRMLScalarVolumeNode()
    volume.SetName("part")
    scene.AddNode(volume)
    storage = slicer.vtkMRMLVolumeArchetypeStorageNode()
    scene.AddNode(storage)
    storage.SetFileName(path)
    assert storage.ReadData(volume)
    logic = CTSegLogic(scene)
    params = logic.parameter_node()
    params.SetParameter("NumberOfSites", "350")
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
        if name != "NumberOfSites":
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
    """A volume node of one slice is a 2D problem; its segments cover that slice."""
    p = loaded["phantom"]
    img = array_to_image(p.image[2])
    node = slicer.vtkMRMLScalarVolumeNode()
    node.SetName("one slice")
    node.SetSpacing(0.3, 0.3, 1.0)
    node.SetAndObserveImageData(img)
    loaded["scene"].AddNode(node)
    model, segmentation, result = loaded["logic"].run(node)
    assert result.n_materials == 4 and model.GetPolyData().GetNumberOfCells() == len(result.triangles)
    assert segmentation.GetSegmentation().GetNumberOfSegments() == 4
