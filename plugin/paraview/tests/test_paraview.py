"""The ParaView plugin inside the real ParaView (Debian's 5.11), headless: slices mode.

    PYTHONPATH=<site-packages with ctseg> pvpython plugin/paraview/tests/test_paraview.py [SCREENSHOT.png]

(The tests live in this subfolder, not beside the plugin: ParaView loads every .py file of a
PV_PLUGIN_PATH folder as a plugin, and would run a test file as one.)

ParaView prints and swallows exceptions raised inside RequestData and goes on with an empty
output, so every check here is on the data fetched back from the pipeline. With a file
name, also renders the segmented volume coloured by material (needs a display: xvfb-run).
Prints 'N passed, M failed' and exits non-zero on any failure.
"""
import os
import sys
import tempfile

import numpy as np
from paraview import servermanager
from paraview.simple import (ColorBy, CreateView, GetColorTransferFunction, GetScalarBar,
                             LoadPlugin, PNGSeriesReader, Render, SaveScreenshot, Show, Text,
                             Threshold)
from vtkmodules.util import numpy_support

from ctseg.density import density_map
from ctseg.filters import array_to_image, polydata_to_arrays
from ctseg.geometry import ImageGeometry
from ctseg.metrics import dice_per_label
from ctseg.params import SPECS
from ctseg.phantoms import make_volume
from ctseg.raster import label_image
from pvharness import check, fetch, finish, write_vti

PLUGIN = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "ctseg_paraview.py")
LoadPlugin(PLUGIN, remote=False, ns=globals())
GEOM = ImageGeometry(origin=(2.0, -1.0, 5.0), spacing=(0.1, 0.1, 0.8))


def labels_per_slice(poly, geom, shape):
    """Rasterise a fetched multi-slice mesh back onto the (nz, ny, nx) voxels."""
    pts, tri, arrays = polydata_to_arrays(poly)
    ijk = geom.to_index(pts)
    out = np.zeros(shape, np.int64)
    for k in range(shape[0]):
        cells = arrays["slice"] == k
        out[k] = label_image(ijk[:, :2], tri[cells], arrays["material"][cells], shape[1:])
    return out


tmp = tempfile.mkdtemp()
phantom = make_volume(6, 96, seed=1)
volume_reader = write_vti(os.path.join(tmp, "volume.vti"), phantom.image, GEOM)


@check("properties: every spec parameter, named and defaulted as the spec says")
def _():
    seg = CTSegment(Input=volume_reader)  # noqa: F821 - defined by LoadPlugin
    for name, spec in SPECS.items():
        prop = seg.SMProxy.GetProperty(spec.vtk)
        assert prop is not None, f"CTSegment has no property {spec.vtk} ({name})"
        want = spec.to_text(spec.default) if spec.kind == "floats" else spec.to_number(spec.default)
        assert prop.GetElement(0) == want, (spec.vtk, prop.GetElement(0))
    dens = CTDensityMap(Input=volume_reader)  # noqa: F821
    for spec in SPECS.values():  # the stage filter's property is named as the composite's
        assert (dens.SMProxy.GetProperty(spec.vtk) is not None) == (spec.group == "density"), spec.vtk
    assert dens.SMProxy.GetProperty("Floor") is None


@check("volume: composite filter, arrays, slices at their z, Dice per material")
def _():
    seg = CTSegment(Input=volume_reader, Mode="slices")  # noqa: F821 - defined by LoadPlugin
    seg.NumberOfSites = 350
    seg.NumberOfJobs = 1
    seg.UpdatePipeline()
    mesh = fetch(seg)
    names = {mesh.GetCellData().GetArrayName(k) for k in range(mesh.GetCellData().GetNumberOfArrays())}
    assert {"material", "gray", "slice"} <= names, names
    pts, tri, arrays = polydata_to_arrays(mesh)
    z_index = GEOM.to_index(pts)[tri[:, 0], 2]
    assert np.allclose(z_index, arrays["slice"]), "slices not at their positions"
    dice = dice_per_label(labels_per_slice(mesh, GEOM, phantom.image.shape),
                          phantom.truth.astype(np.int64), 4)
    print("    Dice per material (air, polymer, aluminium, steel):", np.round(dice, 3))
    assert min(dice[0], dice[2], dice[3]) >= 0.93 and dice[1] >= 0.75, dice
    bnd = fetch(seg, 1)
    assert bnd.GetNumberOfLines() > 0 and bnd.GetCellData().GetArray("material_a") is not None


@check("volume: gray levels typed as text: material k is the k-th level")
def _():
    truth = phantom.truth.astype(np.int64)
    levels = [float(np.median(phantom.image[truth == k])) for k in range(4)]
    seg = CTSegment(Input=volume_reader, Mode="slices", NumberOfSites=350, NumberOfJobs=1,  # noqa: F821
                    GrayLevels=", ".join(f"{v:.1f}" for v in levels))
    mesh = fetch(seg)
    dice = dice_per_label(labels_per_slice(mesh, GEOM, phantom.image.shape), truth, 4)
    print("    Dice per material with the true levels given:", np.round(dice, 3))
    assert min(dice) >= 0.75 and min(dice[0], dice[2], dice[3]) >= 0.93, dice
    # levels in the wrong units (outside the data's gray range): refused, output empty
    bad = CTSegment(Input=volume_reader, Mode="slices", NumberOfSites=350, NumberOfJobs=1,  # noqa: F821
                    GrayLevels="1000000, 2000000")
    bad.UpdatePipeline()
    data = servermanager.Fetch(bad)
    assert data is None or data.GetNumberOfCells() == 0


@check("volume: two worker processes give the same mesh")
def _():
    one = CTSegment(Input=volume_reader, Mode="slices", NumberOfSites=120, NumberOfJobs=1)  # noqa: F821
    two = CTSegment(Input=volume_reader, Mode="slices", NumberOfSites=120, NumberOfJobs=2)  # noqa: F821
    a, b = polydata_to_arrays(fetch(one)), polydata_to_arrays(fetch(two))
    assert np.array_equal(a[1], b[1]) and np.array_equal(a[2]["material"], b[2]["material"])
    assert np.allclose(a[0], b[0])


@check("slice from ParaView's PNG reader, and the stage filters give the same mesh")
def _():
    from vtkmodules.vtkIOImage import vtkPNGWriter

    img = phantom.image[3]
    g = np.clip((img - img.min()) / (img.max() - img.min()) * 255, 0, 255).astype(np.uint8)
    w = vtkPNGWriter()
    w.SetFileName(os.path.join(tmp, "slice.png"))
    w.SetInputData(array_to_image(g))
    w.Write()
    png = PNGSeriesReader(FileNames=[os.path.join(tmp, "slice.png")])
    whole = CTSegment(Input=png, NumberOfSites=300)  # noqa: F821
    fixed = CTMetalStreaks(Input=png)  # noqa: F821
    dens = CTDensityMap(Input=fixed)  # noqa: F821
    sites = CTCVTSites(Input=dens, NumberOfSites=300)  # noqa: F821
    tri = CTDelaunayMesh(Input=sites)  # noqa: F821
    gray = CTTriangleGray(Mesh=tri, Image=fixed)  # noqa: F821
    cut = CTGraphCut(Mesh=gray, Image=fixed)  # noqa: F821
    sub = CTSubpixelBoundary(Mesh=cut, Image=fixed)  # noqa: F821
    bnd = CTMaterialBoundary(Input=sub)  # noqa: F821
    a, b = polydata_to_arrays(fetch(whole)), polydata_to_arrays(fetch(sub))
    assert np.array_equal(a[1], b[1]), "stage chain made other triangles"
    assert np.allclose(a[0], b[0], atol=1e-9), "stage chain placed the vertices otherwise"
    assert np.array_equal(a[2]["material"], b[2]["material"]), "stage chain labelled otherwise"
    assert len(np.unique(a[2]["material"])) == 4, np.unique(a[2]["material"])
    assert fetch(bnd).GetNumberOfLines() == fetch(whole, 1).GetNumberOfLines()
    rho = numpy_support.vtk_to_numpy(fetch(dens).GetPointData().GetArray("density"))
    assert rho.min() > 0 and rho.max() > rho.min()
    # a stage property reaches the stage: the paper's map (no ridge, max normalisation)
    paper = CTDensityMap(Input=png, DensityRidge=0.0, DensitySaturation=1.0)  # noqa: F821
    got = numpy_support.vtk_to_numpy(fetch(paper).GetPointData().GetArray("density"))
    want = density_map(g, density_ridge=0.0, density_saturation=1.0)
    assert np.allclose(got.reshape(g.shape), want), "DensityRidge/DensitySaturation not applied"


@check("Gray Values: a point array that is not the active scalars")
def _():
    from ctseg.filters.convert import _point_array
    from vtkmodules.vtkIOXML import vtkXMLImageDataWriter
    from paraview.simple import XMLImageDataReader

    img = phantom.image[3]
    image = array_to_image((img > img.mean()).astype(float), GEOM, name="labels")
    image.GetPointData().AddArray(_point_array(img, "gray"))
    w = vtkXMLImageDataWriter()
    w.SetFileName(os.path.join(tmp, "two_arrays.vti"))
    w.SetInputData(image)
    w.Write()
    reader = XMLImageDataReader(FileName=[os.path.join(tmp, "two_arrays.vti")])
    plain = CTSegment(Input=reader, NumberOfSites=300)  # noqa: F821
    chosen = CTSegment(Input=reader, NumberOfSites=300, GrayValues=["POINTS", "gray"])  # noqa: F821
    gray_png = CTSegment(Input=write_vti(os.path.join(tmp, "gray.vti"), img, GEOM),  # noqa: F821
                         NumberOfSites=300)
    a, b = polydata_to_arrays(fetch(chosen)), polydata_to_arrays(fetch(gray_png))
    assert np.array_equal(a[1], b[1]) and np.array_equal(a[2]["material"], b[2]["material"])
    assert polydata_to_arrays(fetch(plain))[2]["gray"].max() <= 1.0  # the labels
    dens = CTDensityMap(Input=reader, GrayValues=["POINTS", "gray"])  # noqa: F821
    rho = numpy_support.vtk_to_numpy(fetch(dens).GetPointData().GetArray("density"))
    assert np.allclose(rho.reshape(img.shape), density_map(img))
    cut = CTGraphCut(Mesh=chosen, Image=reader)  # noqa: F821 - the image is port 1's
    assert cut.SMProxy.GetProperty("GrayValues") is not None
    assert CTDelaunayMesh(Input=chosen).SMProxy.GetProperty("GrayValues") is None  # noqa: F821


@check("errors: a parameter the input cannot take leaves an empty output, not a wrong one")
def _():
    too_many = phantom.image.shape[1] * phantom.image.shape[2] + 1  # sites per slice
    seg = CTSegment(Input=volume_reader, Mode="slices", NumberOfSites=too_many, NumberOfJobs=1)  # noqa: F821
    seg.UpdatePipeline()
    data = servermanager.Fetch(seg)
    assert data is None or data.GetNumberOfCells() == 0


if len(sys.argv) > 1:
    @check(f"screenshot {sys.argv[1]}")
    def _():
        seg = CTSegment(Input=volume_reader, Mode="slices", NumberOfSites=350)  # noqa: F821
        middle = Threshold(Input=seg, Scalars=["CELLS", "slice"], LowerThreshold=3,
                           UpperThreshold=3)
        view = CreateView("RenderView")
        view.ViewSize = [900, 700]
        view.Background = [1, 1, 1]
        if hasattr(view, "UseColorPaletteForBackground"):
            view.UseColorPaletteForBackground = 0
        view.OrientationAxesVisibility = 0
        lut = GetColorTransferFunction("material")
        lut.InterpretValuesAsCategories = 1
        lut.Annotations = ["0", "air", "1", "polymer", "2", "aluminium", "3", "steel"]
        lut.IndexedColors = [0.16, 0.16, 0.16, 0.9, 0.62, 0.0, 0.34, 0.71, 0.91, 0.0, 0.62, 0.45]
        solids = Threshold(Input=seg, Scalars=["CELLS", "material"], LowerThreshold=1,
                           UpperThreshold=3)
        stack = Show(solids, view)
        ColorBy(stack, ("CELLS", "material"))
        stack.Opacity = 0.35
        shown = Show(middle, view)
        ColorBy(shown, ("CELLS", "material"))
        shown.SetRepresentationType("Surface With Edges")
        shown.EdgeColor = [0.1, 0.1, 0.1]
        shown.SetScalarBarVisibility(view, True)
        bar = GetScalarBar(lut, view)
        bar.Title = "material"
        bar.ComponentTitle = ""
        bar.TitleColor = bar.LabelColor = [0, 0, 0]
        text = Text(Text="ctseg in ParaView 5.11: a 6-slice volume; slice 3 whole, the others without air")
        label = Show(text, view)
        label.Color = [0, 0, 0]
        label.WindowLocation = "Upper Left Corner"
        view.CameraPosition = [6.75, -10.0, 17.0]
        view.CameraFocalPoint = [6.75, 3.75, 7.0]
        view.CameraViewUp = [0.0, 0.6, 0.8]
        view.CameraParallelScale = 6.0
        Render(view)
        SaveScreenshot(sys.argv[1], view, ImageResolution=[900, 700])
        assert os.path.getsize(sys.argv[1]) > 10000

finish()
