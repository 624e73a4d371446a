"""The figure of a 3D segmentation, rendered with VTK offscreen: three orthogonal slices
through the volume's centre (the input gray, the tetrahedra the slice plane cuts coloured
by material, their edges, and the material outlines) and a 3D view of every material's
closed surface, cut open by a plane so that inner materials show.

Drawn in the box's physical coordinates ((i, j, k) x spacing): the picture shows the
part as measured, whatever the image's origin and direction."""
import numpy as np
from vtkmodules.util import numpy_support

from ctseg.geometry import volume_slice

from .convert import _add_cell_array, _cells, _points
from .convert3d import tetra_grid, triangles_polydata
from .figure import (PANEL_PX, TITLE_PX, _image_actor, _palette_lut, _poly_actor,
                     offscreen_window, save_window)
from .writers import PALETTE, check_output_path

PLANE_NUDGE = 1e-7
"""Slice planes sit this share of a voxel off the voxel centres, so that they cut through
elements rather than along their faces."""

# (slice axis as numpy axis, its name, the physical axes (x=0, y=1, z=2) of the image's
# columns and rows)
SLICES = ((0, "z", 0, 1), (1, "y", 0, 2), (2, "x", 1, 2))


def _cut(data, axis, position):
    """``data`` (grid or polydata) cut by the plane ``coordinate[axis] = position``."""
    from vtkmodules.vtkCommonDataModel import vtkPlane
    from vtkmodules.vtkFiltersCore import vtkCutter

    plane = vtkPlane()
    normal = [0.0, 0.0, 0.0]
    normal[axis] = 1.0
    origin = [0.0, 0.0, 0.0]
    origin[axis] = position
    plane.SetNormal(normal)
    plane.SetOrigin(origin)
    cutter = vtkCutter()
    cutter.SetCutFunction(plane)
    cutter.SetInputData(data)
    cutter.Update()
    return cutter.GetOutput()


def _flatten(poly, u, v):
    """A cut (3D polydata on a plane) -> polydata on (u, v, 0), cells and cell data kept."""
    from vtkmodules.vtkCommonDataModel import vtkPolyData

    out = vtkPolyData()
    out.DeepCopy(poly)
    if poly.GetNumberOfPoints():
        xyz = numpy_support.vtk_to_numpy(poly.GetPoints().GetData())
        out.SetPoints(_points(np.column_stack([xyz[:, u], xyz[:, v], np.zeros(len(xyz))])))
    if out.GetCellData().GetArray("material") is not None:
        out.GetCellData().SetActiveScalars("material")
    return out


def _cell_edges(poly):
    """The edges of a cut's polygons as 2-point lines (for drawing the mesh)."""
    from vtkmodules.vtkFiltersCore import vtkExtractEdges

    edges = vtkExtractEdges()
    edges.SetInputData(poly)
    edges.Update()
    return edges.GetOutput()


def _fit_camera(ren, u_extent, v_extent):
    """Parallel view of [0, u] x [0, v] filling a square panel below its title strip."""
    cam = ren.GetActiveCamera()
    cam.ParallelProjectionOn()
    per_px = 1.06 * max(u_extent, v_extent, 1e-12) / PANEL_PX
    cu, cv = u_extent / 2, v_extent / 2 + per_px * TITLE_PX / 2
    cam.SetFocalPoint(cu, cv, 0)
    cam.SetPosition(cu, cv, 10 * max(u_extent, v_extent, 1.0))
    cam.SetViewUp(0, 1, 0)
    cam.SetParallelScale(per_px * (PANEL_PX + TITLE_PX) / 2)
    ren.ResetCameraClippingRange()


def _slice_panel(volume, result, grid, interfaces, axis, name, u, v, lut, gray_range):
    sp = np.asarray(result.spacing, float)
    k = volume.shape[axis] // 2
    phys = 2 - axis  # physical axis of the numpy axis
    position = (k + PLANE_NUDGE) * sp[phys]
    cut = _flatten(_cut(grid, phys, position), u, v)
    lines = _flatten(_cut(interfaces, phys, position), u, v)
    image = _image_actor(volume_slice(volume, axis, k), gray_range)
    image.SetScale(sp[u], sp[v], 1.0)
    coloured = _poly_actor(cut, lut=lut, z=0.01 * sp.min())
    coloured.GetProperty().SetOpacity(0.45)
    actors = [image, coloured,
              _poly_actor(_cell_edges(cut), rgb=(0.15, 0.15, 0.15), width=0.5, z=0.02 * sp.min()),
              _poly_actor(lines, rgb=(1.0, 0.1, 0.1), width=2.5, z=0.03 * sp.min())]
    label = f"{name} slice {k} of {volume.shape[axis]}: {cut.GetNumberOfCells()} tetrahedra cut"
    extent = (np.array(volume.shape[::-1], float) - 1) * sp
    return label, actors, (extent[u], extent[v])


def _surface_panel(result, lut):
    """Actors of the closed surfaces (the lowest-gray material, usually air, left out
    unless it is the only one), cut open by the plane y = centre (the half nearer the
    camera removed), and the box's outline."""
    from vtkmodules.vtkCommonDataModel import vtkPlane
    from vtkmodules.vtkFiltersCore import vtkClipPolyData, vtkPolyDataNormals
    from vtkmodules.vtkFiltersSources import vtkOutlineSource
    from vtkmodules.vtkRenderingCore import vtkActor, vtkPolyDataMapper

    box = (np.array(result.shape[::-1], float) - 1) * np.asarray(result.spacing, float)
    shown = [s for s in result.surfaces if s.material > 0 or len(result.surfaces) == 1]
    actors = []
    plane = vtkPlane()
    plane.SetOrigin(*(box / 2))
    plane.SetNormal(0, 1, 0)
    for s in shown:
        poly = triangles_polydata(s.points, s.triangles,
                                  {"material": np.full(len(s.triangles), s.material, np.int32)})
        clip = vtkClipPolyData()
        clip.SetInputData(poly)
        clip.SetClipFunction(plane)
        normals = vtkPolyDataNormals()
        normals.SetInputConnection(clip.GetOutputPort())
        normals.ConsistencyOff()
        normals.SplittingOff()
        normals.Update()
        mapper = vtkPolyDataMapper()
        mapper.SetInputData(normals.GetOutput())
        mapper.ScalarVisibilityOff()
        actor = vtkActor()
        actor.SetMapper(mapper)
        r, g, b = PALETTE[s.material % len(PALETTE)] / 255.0
        actor.GetProperty().SetColor(r, g, b)
        actor.GetProperty().SetEdgeVisibility(True)
        actor.GetProperty().SetEdgeColor(0.2, 0.2, 0.2)
        actor.GetProperty().SetLineWidth(0.5)
        back = actor.MakeProperty()
        back.DeepCopy(actor.GetProperty())
        back.SetColor(0.55 * r, 0.55 * g, 0.55 * b)  # inside of a cut shell: darker
        actor.SetBackfaceProperty(back)
        actors.append(actor)
    # the section of the shown materials on the cutting plane closes the cut shells
    keep = np.isin(result.material, [s.material for s in shown])
    section = _cut(tetra_grid(result.points, result.tetrahedra[keep], result.material[keep],
                              result.gray[keep]), 1, box[1] / 2)
    if section.GetCellData().GetArray("material") is not None:
        section.GetCellData().SetActiveScalars("material")
    actors.append(_poly_actor(section, lut=lut, z=0.0))
    actors[-1].GetProperty().LightingOn()
    outline = vtkOutlineSource()
    outline.SetBounds(0, box[0], 0, box[1], 0, box[2])
    outline.Update()
    actors.append(_poly_actor(outline.GetOutput(), rgb=(0.3, 0.3, 0.3), width=1.0, z=0.0))
    label = f"closed surfaces of {len(shown)} material(s), cut open at y = {box[1] / 2:.4g}"
    return label, actors, box


def _legend(ren, result):
    from vtkmodules.vtkRenderingCore import vtkTextActor

    for k, g in enumerate(result.material_gray):
        text = vtkTextActor()
        text.SetInput(f"material {k}: gray {g:.4g}")
        prop = text.GetTextProperty()
        prop.SetFontSize(14)
        prop.SetBold(True)
        prop.SetColor(*(PALETTE[k % len(PALETTE)] / 255.0))
        pos = text.GetPositionCoordinate()
        pos.SetCoordinateSystemToNormalizedViewport()
        pos.SetValue(0.02, 0.02 + 0.05 * (len(result.material_gray) - 1 - k))
        ren.AddViewProp(text)


def render_volume_figure(path, volume, result, title=None):
    """Render the four panels of a 3D segmentation and write them as PNG.

    Parameters
    ----------
    path : str or path-like
        Output .png (written under a temporary name, then renamed).
    volume : (nz, ny, nx) array_like
        The segmented volume.
    result : ctseg.pipeline3d.TetraSegmentation
    title : str, optional
        Shown above the first panel.

    Returns
    -------
    rgb : (h, w, 3) uint8 ndarray
        The picture written.

    Raises
    ------
    InputError
        Not a .png path, or no way to render here.
    """
    from vtkmodules.vtkRenderingCore import vtkRenderer, vtkTextActor
    import vtkmodules.vtkRenderingFreeType  # noqa: F401 - text rendering

    path, _ = check_output_path(path, (".png",))
    vol = np.asarray(volume, float)
    lut = _palette_lut(int(result.n_materials))
    grid = tetra_grid(result.points, result.tetrahedra, result.material, result.gray)
    from vtkmodules.vtkCommonDataModel import vtkPolyData

    interfaces = vtkPolyData()
    interfaces.SetPoints(_points(result.points))
    interfaces.SetPolys(_cells(np.asarray(result.interfaces).ravel(), 3))
    _add_cell_array(interfaces, np.asarray(result.interface_materials)[:, 0].astype(np.int32),
                    "material_a")
    gray_range = tuple(np.percentile(vol, [0.5, 99.5]))
    # the window first: it loads the OpenGL implementations the actors below are made of
    window = offscreen_window()
    panels = [_slice_panel(vol, result, grid, interfaces, axis, name, u, v, lut, gray_range)
              for axis, name, u, v in SLICES]
    window.SetSize(2 * PANEL_PX, 2 * (PANEL_PX + TITLE_PX))
    window.SetMultiSamples(4)
    for n in range(4):
        col, row = n % 2, n // 2
        ren = vtkRenderer()
        ren.SetBackground(1, 1, 1)
        ren.SetViewport(col / 2, (1 - row) / 2, (col + 1) / 2, (2 - row) / 2)
        if n < 3:
            label, actors, (ue, ve) = panels[n]
        else:
            label, actors, box = _surface_panel(result, lut)
            _legend(ren, result)
        for actor in actors:
            ren.AddActor(actor)
        text = vtkTextActor()
        text.SetInput(f"{title}: {label}" if n == 0 and title else label)
        text.GetTextProperty().SetFontSize(14)
        text.GetTextProperty().SetColor(0, 0, 0)
        pos = text.GetPositionCoordinate()
        pos.SetCoordinateSystemToNormalizedViewport()
        pos.SetValue(0.02, (PANEL_PX + 6) / (PANEL_PX + TITLE_PX))
        ren.AddViewProp(text)
        if n < 3:
            _fit_camera(ren, ue, ve)
        else:
            cam = ren.GetActiveCamera()
            centre = box / 2
            d = 2.2 * float(np.linalg.norm(box))
            cam.SetFocalPoint(*centre)
            cam.SetPosition(centre[0] + 0.45 * d, centre[1] - 0.8 * d, centre[2] + 0.5 * d)
            cam.SetViewUp(0, 0, 1)
            ren.ResetCamera()
            cam.Zoom(0.9)
            cam.SetWindowCenter(-0.12, -0.16)  # the scene up and right, clear of the legend
            ren.ResetCameraClippingRange()
        window.AddRenderer(ren)
    return save_window(window, path)
