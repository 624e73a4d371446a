"""The ParaView plugin's 3D mode inside the real ParaView (Debian's 5.11), headless.

    PYTHONPATH=<site-packages with ctseg> pvpython plugin/paraview/tests/test_paraview3d.py [SCREENSHOT.png]

A true 3D phantom (:func:`ctseg.phantoms3d.make_part_3d`: a tilted aluminium housing, a
polymer layer and bushing, a steel shaft and ball, gas pores) with anisotropic voxels and
a non-zero origin is written to a .vti, opened by ParaView's XML reader and segmented by
CT Segment with Mode '3d'. Every check is on the data fetched back from the pipeline
(ParaView swallows exceptions raised in RequestData): the output types as Mode changes,
the tetrahedra (positive, filling the image's box in world coordinates, Dice per material
against the truth), each material's surface (closed and manifold, by ParaView's own
Extract Surface and Feature Edges filters and by ctseg's closed-surface checks) and the
interface triangles. With a file name, also renders the material surfaces cut open.
Prints 'N passed, M failed' and exits non-zero on any failure.
"""
import os
import sys
import tempfile
import time

import numpy as np
from paraview import servermanager
from paraview.simple import (Clip, ColorBy, CreateView, ExtractSurface, FeatureEdges,
                             GetColorTransferFunction, GetScalarBar, LoadPlugin, Render,
                             SaveScreenshot, Show, Text, Threshold)

from ctseg.filters import polydata_to_arrays
from ctseg.filters.convert3d import grid_to_arrays
from ctseg.geometry import ImageGeometry
from ctseg.meshcheck import check_closed_surface
from ctseg.metrics import dice_per_label
from ctseg.phantoms3d import make_part_3d
from ctseg.raster import tetra_label_volume
from ctseg.surfaces import material_surface
from ctseg.tetrahedra import TetraMesh, face_graph, tetra_faces, tetra_volumes
from pvharness import check, fetch, finish, write_vti

PLUGIN = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "ctseg_paraview.py")
LoadPlugin(PLUGIN, remote=False, ns=globals())
SPACING = (0.1, 0.1, 0.15)  # mm: anisotropic voxels, the part a physical cube
GEOM = ImageGeometry(origin=(-3.0, 1.5, 10.0), spacing=SPACING)
MATERIALS = ("air", "polymer", "aluminium", "steel")
# measured 0.987, 0.544, 0.854, 0.904 (64 voxels across, seed 0, default parameters: the
# four levels come from the tetrahedra, ctseg/levels3d.py); the thin polymer bushing,
# 4 noise sd above air, is the hard one
MIN_DICE = (0.97, 0.45, 0.80, 0.87)
DONE = {}


def edge_uses(triangles):
    """How many triangles use each undirected edge."""
    tri = np.asarray(triangles, np.int64).reshape(-1, 3)
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    return np.unique(edges, axis=0, return_counts=True)[1]


tmp = tempfile.mkdtemp()
part = make_part_3d(64, 0, SPACING)  # size, seed
reader = write_vti(os.path.join(tmp, "part.vti"), part.image, GEOM)
small = write_vti(os.path.join(tmp, "small.vti"), make_part_3d(24, seed=1, porosity=False).image, GEOM)


@check("3d: Mode (auto, the default, on a volume) switches output 0 between vtkUnstructuredGrid and vtkPolyData")
def _():
    seg = CTSegment(Input=small, NumberOfSites=150, NumberOfJobs=1)  # noqa: F821 - LoadPlugin
    assert seg.Mode == "auto"  # a volume that fits: 3D
    view = CreateView("RenderView")
    shown = Show(seg, view)
    for mode, kind in (("auto", "vtkUnstructuredGrid"), ("slices", "vtkPolyData"),
                       ("3d", "vtkUnstructuredGrid")):
        seg.Mode = mode
        seg.UpdatePipeline()
        out = fetch(seg)
        assert out.GetClassName() == kind, (mode, out.GetClassName())
        assert seg.GetDataInformation(0).GetDataSetTypeAsString() == kind
        assert servermanager.Fetch(seg, idx=1).GetClassName() == "vtkPolyData"
        Render(view)  # the view's representation follows the new output type
        drawn = shown.SMProxy.GetRepresentedDataInformation().GetNumberOfCells()
        # a surface representation draws the triangles, or the tetrahedra's outer faces
        want = (len(face_graph(grid_to_arrays(out)[1])[2]) if kind == "vtkUnstructuredGrid"
                else out.GetNumberOfCells())
        assert drawn == want, (mode, drawn, want)


@check("3d: tetrahedra in world coordinates, positive, filling the box; Dice per material")
def _():
    seg = CTSegment(Input=reader, Mode="3d", NumberOfJobs=1)  # noqa: F821
    t0 = time.perf_counter()
    seg.UpdatePipeline()
    print(f"    segmentation of {part.image.shape} voxels in ParaView: {time.perf_counter() - t0:.1f} s")
    grid = fetch(seg)
    assert grid.GetClassName() == "vtkUnstructuredGrid", grid.GetClassName()
    pts, tets, arrays = grid_to_arrays(grid)  # refuses any cell but a tetrahedron
    assert {"material", "gray"} <= set(arrays), set(arrays)
    vol = tetra_volumes(pts, tets)
    assert vol.min() > 0, f"{int((vol <= 0).sum())} tetrahedra of volume <= 0"
    bounds = np.array(reader.GetDataInformation().GetBounds()).reshape(3, 2)
    assert np.allclose(pts.min(axis=0), bounds[:, 0]) and np.allclose(pts.max(axis=0), bounds[:, 1])
    assert np.isclose(vol.sum(), np.prod(bounds[:, 1] - bounds[:, 0]), rtol=1e-9), "box not filled"
    labels = tetra_label_volume(GEOM.to_index(pts), tets, arrays["material"], part.image.shape)
    dice = dice_per_label(labels, part.truth.astype(np.int64), 4)
    print(f"    {len(tets)} tetrahedra, {len(pts)} vertices, {grid.GetNumberOfCells()} cells; "
          f"Dice per material {dict(zip(MATERIALS, np.round(dice, 3)))}")
    assert np.all(dice >= MIN_DICE), dice
    gray = arrays["gray"]
    means = [gray[arrays["material"] == k].mean() for k in range(4)]
    assert np.all(np.diff(means) > 0), means  # numbered by ascending gray
    DONE.update(seg=seg, pts=pts, tets=tets, material=arrays["material"])


@check("3d: each material's surface closed and manifold (ParaView's filters, ctseg's checks)")
def _():
    seg, pts, tets, mat = (DONE[k] for k in ("seg", "pts", "tets", "material"))
    mesh = TetraMesh(pts, tets, *face_graph(tets))
    for k, name in enumerate(MATERIALS):
        # k +- 0.5: a bound equal to the property's default (0) would be reset to the data's range
        solid = Threshold(Input=seg, Scalars=["CELLS", "material"], LowerThreshold=k - 0.5,
                          UpperThreshold=k + 0.5)
        assert fetch(solid).GetNumberOfCells() == int((mat == k).sum()), name
        surface = ExtractSurface(Input=solid)
        edges = FeatureEdges(Input=surface, BoundaryEdges=1, NonManifoldEdges=1, FeatureEdges=0,
                             ManifoldEdges=0)
        _, tri, _ = polydata_to_arrays(fetch(surface))
        uses = edge_uses(tri)
        open_or_not_manifold = servermanager.Fetch(edges).GetNumberOfCells()
        s = material_surface(mesh, mat, k)  # one vertex copy per fan where pieces touch
        report = check_closed_surface(s.points, s.triangles, s.element_volume, what=name)
        print(f"    {name}: {len(tri)} surface triangles; Feature Edges: {open_or_not_manifold} "
              f"boundary or non-manifold edges; edges used by 1 triangle: {int((uses == 1).sum())}, "
              f"> 2: {int((uses > 2).sum())}; pymeshlab: {report['boundary_edges']} boundary, "
              f"{report['non_manifold_edges']} non-manifold edges, encloses "
              f"{report['enclosed_volume']:.4f} mm^3 = its tetrahedra's {s.element_volume:.4f}")
        assert open_or_not_manifold == 0 and np.all(uses == 2), name
        assert len(s.triangles) == len(tri), (name, len(s.triangles), len(tri))


@check("3d: output 1 holds exactly the faces between materials, oriented from a to b")
def _():
    seg, pts, tets, mat = (DONE[k] for k in ("seg", "pts", "tets", "material"))
    inter = fetch(seg, 1)
    ipts, faces, arrays = polydata_to_arrays(inter)
    a, b = arrays["material_a"], arrays["material_b"]
    assert np.all(a < b) and len(np.unique(np.column_stack([a, b]), axis=0)) >= 3
    assert np.allclose(ipts, pts), "interfaces over other points than the tetrahedra"
    # every face of every tetrahedron, outward; an interface face is the outward face of
    # its material_a tetrahedron (normal from a to b)
    outward = tetra_faces(tets)
    owner = np.repeat(np.arange(len(tets)), 4)
    key = {tuple(np.roll(f, -int(np.argmin(f)))): owner[i] for i, f in enumerate(outward)}
    adjacency = face_graph(tets)[0]
    between = int((mat[adjacency[:, 0]] != mat[adjacency[:, 1]]).sum())
    assert len(faces) == between, (len(faces), between)
    for f, ma in zip(faces, a):
        t = key.get(tuple(np.roll(f, -int(np.argmin(f)))))
        assert t is not None and mat[t] == ma, "an interface triangle not outward from material_a"
    print(f"    {len(faces)} interface triangles, pairs {sorted(set(zip(a.tolist(), b.tolist())))}")


def material_colours(view):
    lut = GetColorTransferFunction("material")
    lut.InterpretValuesAsCategories = 1
    lut.Annotations = [str(v) for k, m in enumerate(MATERIALS) for v in (k, m)]
    lut.IndexedColors = [0.16, 0.16, 0.16, 0.9, 0.62, 0.0, 0.34, 0.71, 0.91, 0.0, 0.62, 0.45]
    bar = GetScalarBar(lut, view)
    bar.Title = "material"
    bar.ComponentTitle = ""
    bar.TitleColor = bar.LabelColor = [0, 0, 0]
    bar.TitleFontSize = bar.LabelFontSize = 18
    bar.WindowLocation = "Any Location"
    bar.Position = [0.86, 0.3]
    bar.ScalarBarLength = 0.4
    return lut


CAMERA = (7.0, 8.0, 6.0)  # from the focal point: the cut (facing +y) and the part's +x side
ZOOM = 1.2
SHIFT = 0.04  # of the camera's distance: the part a little left of the legend


def screenshot(path):
    """The solid materials' tetrahedra cut open by a plane through the centre, seen from
    the cut's side: the steel shaft in the polymer bushing in the aluminium housing."""
    seg = DONE["seg"]
    centre = np.array(reader.GetDataInformation().GetBounds()).reshape(3, 2).mean(axis=1)
    solids = Threshold(Input=seg, Scalars=["CELLS", "material"], LowerThreshold=0.5,
                       UpperThreshold=3.5)
    cut = Clip(Input=solids, ClipType="Plane")  # keeps y <= centre: the cut faces +y
    cut.ClipType.Origin = centre.tolist()
    cut.ClipType.Normal = [0.0, 1.0, 0.0]
    view = CreateView("RenderView")
    view.ViewSize = [900, 600]
    view.Background = [1, 1, 1]
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0
    view.OrientationAxesVisibility = 0
    material_colours(view)
    shown = Show(cut, view)
    ColorBy(shown, ("CELLS", "material"))
    shown.SetRepresentationType("Surface With Edges")
    shown.EdgeColor = [0.2, 0.2, 0.2]
    shown.Ambient, shown.Diffuse = 0.25, 0.85
    shown.SetScalarBarVisibility(view, True)
    shape = " x ".join(str(n) for n in part.image.shape[::-1])
    label = Show(Text(Text=f"ctseg 3D mode in ParaView 5.11: {shape} voxels, {len(DONE['tets'])} "
                           "tetrahedra;\npolymer, aluminium and steel cut open at the centre"), view)
    label.Color = [0, 0, 0]
    label.FontSize = 18
    label.Justification = "Left"
    label.WindowLocation = "Upper Left Corner"
    Render(view)  # the first render resets the camera: set it after
    view.CameraFocalPoint = centre.tolist()
    view.CameraPosition = (centre + np.array(CAMERA)).tolist()
    view.CameraViewUp = [0.0, 0.0, 1.0]
    view.ResetCamera()
    focal = np.array(view.CameraFocalPoint)
    eye = focal + (np.array(view.CameraPosition) - focal) / ZOOM
    right = np.cross(focal - eye, view.CameraViewUp)
    shift = SHIFT * np.linalg.norm(focal - eye) * right / np.linalg.norm(right)
    view.CameraFocalPoint, view.CameraPosition = (focal + shift).tolist(), (eye + shift).tolist()
    Render(view)
    SaveScreenshot(path, view, ImageResolution=[900, 600], CompressionLevel="9")
    assert 10000 < os.path.getsize(path) < 300_000, os.path.getsize(path)


if len(sys.argv) > 1:
    check(f"3d screenshot {sys.argv[1]}")(lambda: screenshot(sys.argv[1]))

finish()
