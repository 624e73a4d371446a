import numpy as np
import pytest

import ctseg
from ctseg.errors import CTSegError
from ctseg.filters import CTSegmentFilter, array_to_image, polydata_to_arrays
from ctseg.filters.convert import ImageGeometry

from conftest import disc_image


def test_segment_filter_in_a_vtk_pipeline(tmp_path):
    """reader -> CTSegmentFilter -> writer -> reader, compared with ctseg.segment_image."""
    from vtkmodules.vtkIOXML import (vtkXMLImageDataReader, vtkXMLImageDataWriter,
                                     vtkXMLPolyDataReader, vtkXMLPolyDataWriter)

    img, _ = disc_image(48, noise=4.0)
    theta = np.deg2rad(20)
    rot = np.array([[np.cos(theta), -np.sin(theta), 0], [np.sin(theta), np.cos(theta), 0], [0, 0, 1]])
    geom = ImageGeometry(origin=(5.0, -3.0, 1.5), spacing=(0.2, 0.3, 1.0), direction=rot)
    w = vtkXMLImageDataWriter()
    w.SetFileName(str(tmp_path / "in.vti"))
    w.SetInputData(array_to_image(img, geom))
    w.Write()
    reader = vtkXMLImageDataReader()
    reader.SetFileName(str(tmp_path / "in.vti"))
    seg_filter = CTSegmentFilter()
    seg_filter.SetNumberOfSites(60)
    seg_filter.SetInputConnection(reader.GetOutputPort())
    progress = []
    seg_filter.AddObserver("ProgressEvent", lambda o, e: progress.append(o.GetProgress()))
    writer = vtkXMLPolyDataWriter()
    writer.SetFileName(str(tmp_path / "out.vtp"))
    writer.SetInputConnection(seg_filter.GetOutputPort())
    writer.Write()
    back = vtkXMLPolyDataReader()
    back.SetFileName(str(tmp_path / "out.vtp"))
    back.Update()
    pts, tri, arrays = polydata_to_arrays(back.GetOutput())

    ref = ctseg.segment_image(img, n_sites=60)
    assert np.array_equal(tri, ref.triangles)
    assert np.array_equal(arrays["material"], ref.material)
    np.testing.assert_allclose(arrays["gray"], ref.gray)
    world = np.array(geom.origin) + (np.column_stack([ref.points, np.zeros(len(ref.points))])
                                     * [0.2, 0.3, 1.0]) @ rot.T
    np.testing.assert_allclose(pts, world, atol=1e-9)
    assert progress and max(progress) == 1.0
    assert seg_filter.GetOutput().GetNumberOfCells() == len(tri)


def test_parameters_mark_modified():
    f = CTSegmentFilter()
    t0 = f.GetMTime()
    f.SetSeed(0)  # unchanged: no Modified()
    assert f.GetMTime() == t0
    f.SetNumberOfMaterials(2)
    assert f.GetMTime() > t0 and f.GetNumberOfMaterials() == 2


def test_errors_are_reported_not_silent():
    from vtkmodules.vtkCommonCore import vtkOutputWindow, vtkStringOutputWindow

    sink = vtkStringOutputWindow()
    vtkOutputWindow.SetInstance(sink)
    try:
        f = CTSegmentFilter()
        f.SetNumberOfSites(3)
        with pytest.raises(CTSegError, match="n_sites"):
            f.apply(array_to_image(np.random.default_rng(0).random((10, 10))))
        assert "n_sites" in sink.GetOutput()
        assert f.GetOutputDataObject(0).GetNumberOfCells() == 0
    finally:
        vtkOutputWindow.SetInstance(None)
