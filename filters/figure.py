"""The paper's Fig. 5 rendered with VTK offscreen (no display, no matplotlib): six panels of
one slice -- input, density map, CVT regions with sites, Delaunay mesh over the image (the
streak-corrected one when the correction changed it), mesh coloured by material, material
boundaries over the input."""
import os

import numpy as np
from vtkmodules.util import numpy_support
from vtkmodules.vtkCommonCore import vtkLookupTable

from ctseg.errors import InputError

from .convert import _add_cell_array, _cells, _points, array_to_image
from .writers import PALETTE, atomic_outputs, check_output_path

PANEL_PX = 420
TITLE_PX = 26


def _image_actor(values, lut_range=None, lut=None):
    """A (rows, cols) array as an image actor, pixel (r, c) centred at (c, r, 0)."""
    from vtkmodules.vtkImagingCore import vtkImageMapToColors
    from vtkmodules.vtkRenderingCore import vtkImageActor

    img = array_to_image(np.asarray(values, dtype=np.float64))
    if lut is None:
        lo, hi = lut_range
        lut = vtkLookupTable()
        lut.SetRange(lo, hi if hi > lo else lo + 1.0)
        lut.SetSaturationRange(0, 0)
        lut.SetHueRange(0, 0)
        lut.SetValueRange(0, 1)
        lut.Build()
    colours = vtkImageMapToColors()
    colours.SetInputData(img)
    colours.SetLookupTable(lut)
    colours.SetOutputFormatToRGB()
    colours.Update()
    actor = vtkImageActor()
    actor.GetMapper().SetInputData(colours.GetOutput())
    actor.InterpolateOff()
    return actor


def _poly_actor(poly, rgb=None, width=1.0, point_size=1.0, lut=None, z=0.01):
    from vtkmodules.vtkRenderingCore import vtkActor, vtkPolyDataMapper

    mapper = vtkPolyDataMapper()
    mapper.SetInputData(poly)
    if lut is not None:
        mapper.SetLookupTable(lut)
        mapper.SetScalarModeToUseCellData()
        mapper.SetScalarRange(0, lut.GetNumberOfTableValues() - 1)
    else:
        mapper.ScalarVisibilityOff()
    actor = vtkActor()
    actor.SetMapper(mapper)
    actor.SetPosition(0, 0, z)  # just above the image plane
    prop = actor.GetProperty()
    if rgb is not None:
        prop.SetColor(*rgb)
    prop.SetLineWidth(width)
    prop.SetPointSize(point_size)
    prop.LightingOff()  # flat colours, as in a picture
    return actor


def _mesh_poly(points, triangles=None, material=None, lines=None, vertices=False):
    """Polydata on 2D points (z = 0): triangles (with ``material``), 2-point lines, or one
    vertex per point."""
    from vtkmodules.vtkCommonDataModel import vtkPolyData

    poly = vtkPolyData()
    poly.SetPoints(_points(np.column_stack([points, np.zeros(len(points))])))
    if triangles is not None:
        poly.SetPolys(_cells(np.asarray(triangles).ravel(), 3))
    if lines is not None:
        poly.SetLines(_cells(np.asarray(lines).ravel(), 2))
    if vertices:
        poly.SetVerts(_cells(np.arange(len(points)), 1))
    if material is not None:
        _add_cell_array(poly, np.asarray(material, np.int32), "material")
        poly.GetCellData().SetActiveScalars("material")
    return poly


def _palette_lut(n):
    lut = vtkLookupTable()
    lut.SetNumberOfTableValues(max(n, 1))
    for k in range(max(n, 1)):
        r, g, b = PALETTE[k % len(PALETTE)] / 255.0
        lut.SetTableValue(k, r, g, b, 1.0)
    lut.SetRange(0, max(n - 1, 1))
    return lut


REGION_COLOUR_SEED = 0
"""Seed of the random colours of the CVT regions (the same colours in every figure)."""


def _region_lut(n):
    rng = np.random.default_rng(REGION_COLOUR_SEED)
    lut = vtkLookupTable()
    lut.SetNumberOfTableValues(n)
    for k, (r, g, b) in enumerate(rng.uniform(0.35, 1.0, (n, 3))):
        lut.SetTableValue(k, r, g, b, 1.0)
    lut.SetRange(0, n - 1)
    return lut


def _edges(triangles):
    t = np.asarray(triangles)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0)


def offscreen_window():
    """A render window that can draw without a screen, or InputError saying why not.

    VTK >= 9.4 wheels fall back on EGL or OSMesa when there is no X display; older builds
    (Debian's VTK 9.2 in ParaView 5.11) only have X, and abort the whole process when asked
    to render without one, so that case is refused here instead.
    """
    import ctypes.util

    import vtkmodules.vtkRenderingOpenGL2  # noqa: F401 - the render window implementation
    from vtkmodules.vtkRenderingCore import vtkRenderWindow

    headless = not os.environ.get("DISPLAY")
    if headless and "VTK_DEFAULT_OPENGL_WINDOW" not in os.environ:
        # pick the backend ourselves: VTK would try X first (and warn), and with neither
        # EGL nor OSMesa present it crashes the process instead of failing
        for lib, backend in (("EGL", "vtkEGLRenderWindow"), ("OSMesa", "vtkOSOpenGLRenderWindow")):
            if ctypes.util.find_library(lib):
                os.environ["VTK_DEFAULT_OPENGL_WINDOW"] = backend
                break
        else:
            raise InputError("figure: no display and neither EGL nor OSMesa is installed; "
                             "install libegl1 (Debian/Ubuntu) or run under xvfb-run")
    window = vtkRenderWindow()
    if window.GetClassName() == "vtkXOpenGLRenderWindow" and headless:
        raise InputError("figure: this VTK renders through X only and there is no display; "
                         "run under xvfb-run, or use VTK >= 9.4 (offscreen EGL/OSMesa)")
    window.SetOffScreenRendering(1)
    return window


def render_figure(path, image, seg, title=None):
    """Render the six panels of the paper's Fig. 5 for one slice and write them as PNG.

    Parameters
    ----------
    path : str or path-like
        Output .png (written under a temporary name, then renamed).
    image : (rows, cols) array_like
        The slice.
    seg : ctseg.SegmentedMesh
        Its segmentation, with the ``density`` and ``cvt_labels`` maps.
    title : str, optional
        Shown above the first panel.

    Returns
    -------
    rgb : (h, w, 3) uint8 ndarray
        The picture written.

    Raises
    ------
    InputError
        Not a .png path, or a segmentation without its per-pixel maps.
    """
    from vtkmodules.vtkRenderingCore import vtkRenderer, vtkTextActor
    import vtkmodules.vtkRenderingFreeType  # noqa: F401 - text rendering

    path, _ = check_output_path(path, (".png",))
    img = np.asarray(image, float)
    if seg.density is None or seg.cvt_labels is None:
        raise InputError("figure: the segmentation has no density or CVT maps (volumes keep "
                         "them for the figure slice only)")
    rows, cols = img.shape
    lo, hi = np.percentile(img, [0.5, 99.5])
    n_mat = int(seg.n_materials)
    edges = _edges(seg.triangles)
    n_regions = int(seg.cvt_labels.max()) + 1
    corrected = seg.corrected_image
    # the window first: it loads the OpenGL implementations the actors below are made of
    window = offscreen_window()
    panels = [
        ("input", [_image_actor(img, (lo, hi))]),
        ("density map", [_image_actor(seg.density, (seg.density.min(), seg.density.max()))]),
        (f"CVT: {len(seg.points)} sites", [
            _image_actor(seg.cvt_labels, lut=_region_lut(n_regions)),
            _poly_actor(_mesh_poly(seg.points, vertices=True), rgb=(0, 0, 0), point_size=3.0)]),
        (f"Delaunay: {len(seg.triangles)} triangles"
         + (", streak-corrected image" if corrected is not None else ""), [
            _image_actor(img if corrected is None else corrected, (lo, hi)),
            _poly_actor(_mesh_poly(seg.points, lines=edges), rgb=(1.0, 0.25, 0.25))]),
        (f"materials: {n_mat}", [
            _poly_actor(_mesh_poly(seg.points, seg.triangles, seg.material),
                        lut=_palette_lut(n_mat), z=0.0),
            _poly_actor(_mesh_poly(seg.points, lines=edges), rgb=(0, 0, 0), width=0.5)]),
        ("material boundaries", [
            _image_actor(img, (lo, hi)),
            _poly_actor(_mesh_poly(seg.points, lines=seg.boundary_edges),
                        rgb=(1.0, 0.15, 0.15), width=2.0)]),
    ]
    scale = PANEL_PX / max(rows, cols)
    pw, ph = int(round(cols * scale)), int(round(rows * scale))
    width, height = 3 * pw, 2 * (ph + TITLE_PX)
    window.SetSize(width, height)
    window.SetMultiSamples(0)
    for k, (label, actors) in enumerate(panels):
        col, row = k % 3, k // 3
        ren = vtkRenderer()
        ren.SetBackground(1, 1, 1)
        ren.SetViewport(col / 3, (1 - row) / 2, (col + 1) / 3, (2 - row) / 2)
        for actor in actors:
            ren.AddActor(actor)
        text = vtkTextActor()
        text.SetInput(f"{title}: {label}" if k == 0 and title else label)
        text.GetTextProperty().SetFontSize(16)
        text.GetTextProperty().SetColor(0, 0, 0)
        pos = text.GetPositionCoordinate()  # in the panel's own viewport
        pos.SetCoordinateSystemToNormalizedViewport()
        pos.SetValue(0.02, (ph + 5) / (ph + TITLE_PX))
        ren.AddViewProp(text)
        # looking down on the image plane, y up, with a title strip above the image
        cam = ren.GetActiveCamera()
        cam.ParallelProjectionOn()
        cx, cy = (cols - 1) / 2, (rows - 1) / 2 + 0.5 * rows * TITLE_PX / ph
        cam.SetFocalPoint(cx, cy, 0)
        cam.SetPosition(cx, cy, 10 * max(rows, cols))
        cam.SetViewUp(0, 1, 0)
        cam.SetParallelScale(0.5 * rows * (ph + TITLE_PX) / ph)
        ren.ResetCameraClippingRange()
        window.AddRenderer(ren)
    return save_window(window, path)


def save_window(window, path):
    """Render ``window``, write it to ``path`` as PNG (under a temporary name, then
    renamed), release it and return the picture as an (h, w, 3) uint8 array, top row
    first."""
    from vtkmodules.vtkIOImage import vtkPNGWriter
    from vtkmodules.vtkRenderingCore import vtkWindowToImageFilter

    window.Render()
    grab = vtkWindowToImageFilter()
    grab.SetInput(window)
    grab.ReadFrontBufferOff()
    grab.Update()
    shot = grab.GetOutput()
    dims = shot.GetDimensions()
    rgb = numpy_support.vtk_to_numpy(shot.GetPointData().GetScalars())
    rgb = rgb.reshape(dims[1], dims[0], -1)[..., :3]
    with atomic_outputs([path]) as (tmp,):
        writer = vtkPNGWriter()
        writer.SetFileName(tmp)
        writer.SetInputData(shot)
        writer.Write()
        if not os.path.getsize(tmp):
            raise InputError(f"{path}: VTK could not write the PNG")
    window.Finalize()
    return np.ascontiguousarray(rgb[::-1])

