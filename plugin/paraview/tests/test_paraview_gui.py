"""The plugin in ParaView's GUI (the `paraview` binary, not pvpython): a startup script.

    CTSEG_GUI_RESULT=result.json PV_PLUGIN_PATH=plugin/paraview paraview --dr \
        --script=plugin/paraview/tests/test_paraview_gui.py

(run_gui_test.sh does it under Xvfb, with the README's PYTHONPATH.) The GUI loads the
plugin from PV_PLUGIN_PATH (the README's step 3), not this script. The script then opens a
small true 3D phantom with ParaView's reader, applies CT Segment with Mode '3d' and shows
it in the GUI's render view as the active source, so that the pipeline browser lists it and
the properties panel shows its properties; it checks, from the GUI's own Python, that the
filter is registered as a pipeline source, has every spec parameter as a property, is
shown in the view and gives tetrahedra. It writes the checks to CTSEG_GUI_RESULT
(JSON: {"checks": [[name, error or null], ...], ...}) and returns to the GUI, which stays
open for the runner to capture the window and close it.
"""
import json
import os
import tempfile
import time
import traceback

import paraview.simple as pvs
from paraview import servermanager

RESULT = os.environ.get("CTSEG_GUI_RESULT", os.path.join(tempfile.gettempdir(), "ctseg_gui.json"))
CHECKS = []
INFO = {}


def check(name):
    def run(fn):
        try:
            fn()
            CHECKS.append((name, None))
        except Exception:
            CHECKS.append((name, traceback.format_exc()))
        return fn
    return run


@check("the GUI loaded the plugin from PV_PLUGIN_PATH: CTSegment is a paraview.simple filter")
def _():
    assert hasattr(pvs, "CTSegment"), "no CTSegment in paraview.simple (plugin not loaded)"
    pxm = servermanager.ProxyManager().SMProxyManager  # the session's proxy manager
    assert pxm.GetPrototypeProxy("filters", "CTSegment") is not None


@check("CT Segment (Mode '3d') on a volume from ParaView's reader, in the pipeline and the view")
def _():
    from vtkmodules.vtkIOXML import vtkXMLImageDataWriter

    from ctseg.filters import array_to_image
    from ctseg.geometry import ImageGeometry
    from ctseg.params import SPECS
    from ctseg.phantoms3d import make_part_3d

    path = os.path.join(tempfile.mkdtemp(), "part.vti")
    w = vtkXMLImageDataWriter()
    w.SetFileName(path)
    spacing = (0.1, 0.1, 0.15)
    part = make_part_3d(64, 0, spacing)  # as in test_paraview3d.py
    w.SetInputData(array_to_image(part.image, ImageGeometry(origin=(1.0, 2.0, 3.0), spacing=spacing)))
    w.Write()
    reader = pvs.OpenDataFile(path)
    pvs.RenameSource("part.vti", reader)
    reader.UpdatePipeline()  # as Apply does before a filter is added in the GUI
    seg = pvs.CTSegment(Input=reader, Mode="3d")
    # Gray Values offers the image's point arrays and starts on its active scalars
    assert list(seg.GrayValues) == ["POINTS", "scalars"], seg.GrayValues
    pvs.RenameSource("CT Segment", seg)
    view = pvs.GetActiveViewOrCreate("RenderView")
    t0 = time.perf_counter()
    shown = pvs.Show(seg, view)
    INFO["segment_s"] = round(time.perf_counter() - t0, 1)
    pvs.ColorBy(shown, ("CELLS", "material"))
    lut = pvs.GetColorTransferFunction("material")
    lut.InterpretValuesAsCategories = 1
    lut.Annotations = ["0", "air", "1", "polymer", "2", "aluminium", "3", "steel"]
    lut.IndexedColors = [0.16, 0.16, 0.16, 0.9, 0.62, 0.0, 0.34, 0.71, 0.91, 0.0, 0.62, 0.45]
    shown.SetScalarBarVisibility(view, True)
    shown.SetRepresentationType("Surface With Edges")
    solids = pvs.Threshold(Input=seg, Scalars=["CELLS", "material"], LowerThreshold=0.5,
                           UpperThreshold=3.5)  # all but air
    clip = pvs.Clip(Input=solids, ClipType="Plane")  # the inside, cut open
    bounds = reader.GetDataInformation().GetBounds()
    clip.ClipType.Origin = [(bounds[2 * a] + bounds[2 * a + 1]) / 2 for a in range(3)]
    clip.ClipType.Normal = [0.0, 1.0, 0.0]
    cut = pvs.Show(clip, view)
    pvs.ColorBy(cut, ("CELLS", "material"))
    cut.SetRepresentationType("Surface With Edges")
    cut.EdgeColor = [0.2, 0.2, 0.2]
    pvs.Hide(seg, view)
    pvs.SetActiveSource(seg)  # the properties panel shows CT Segment's properties
    view.CameraPosition = [3.0, 15.0, 8.0]
    view.CameraViewUp = [0.0, 0.0, 1.0]
    view.ResetCamera()
    pvs.Render(view)
    sources = {name: proxy for (name, _), proxy in pvs.GetSources().items()}
    INFO["sources"] = sorted(sources)
    assert sources.get("CT Segment") is seg, INFO["sources"]
    assert seg.GetXMLLabel() == "CT Segment", seg.GetXMLLabel()
    props = set(seg.ListProperties())
    missing = sorted(s.vtk for s in SPECS.values() if s.vtk not in props)
    assert not missing, f"properties missing: {missing}"
    INFO["properties"] = len(props)
    assert seg.Mode == "3d"
    assert pvs.GetActiveSource() is seg
    assert pvs.GetDisplayProperties(clip, view).Visibility == 1
    grid = servermanager.Fetch(seg)
    assert grid is not None and grid.GetClassName() == "vtkUnstructuredGrid", grid
    assert grid.GetNumberOfCells() > 1000 and grid.GetCellType(0) == 10, grid.GetNumberOfCells()
    INFO["tetrahedra"] = grid.GetNumberOfCells()
    INFO["materials"] = list(grid.GetCellData().GetArray("material").GetRange())
    assert INFO["materials"] == [0.0, 3.0], INFO["materials"]


with open(RESULT + ".tmp", "w") as fh:
    json.dump({"checks": CHECKS, **INFO}, fh, indent=1)
os.replace(RESULT + ".tmp", RESULT)  # the runner waits for this file
