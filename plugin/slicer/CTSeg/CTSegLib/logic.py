"""The GUI-free logic of the 3D Slicer module: a scalar volume node in, a model node (the
segmented mesh, coloured by material) and a segmentation node (one segment per material)
out, parameters kept in a parameter node.

The parameter ``Mode`` chooses the mesh: 'slices' (triangles slice by slice; the segments
are the mesh rasterised on the volume's voxels, closed surfaces made by Slicer's
converter), '3d' (tetrahedra; the segments are ctseg's own closed surfaces, one per
material, kept as the segmentation's source representation), or 'auto', the default (3D
for a volume whose 3D mode fits in memory, else slices).

Imports only MRML (``slicer``'s node classes) and ctseg, never qt, ctk or
``slicer.ScriptedLoadableModule``, so it runs in the full application and in PyPI's
slicer-core alike (the tests use the latter). The parameters are those of
:mod:`ctseg.params`, every one of them, named in the parameter node by their VTK name
(``Param.vtk``: NumberOfSites, Lambda, SliceAxis, ...) and kept as text ('auto', or 0, for
an automatic value).
"""
import numpy as np
from vtkmodules.vtkCommonMath import vtkMatrix4x4

import slicer

from ctseg.errors import CTSegError, InputError, ParameterError
from ctseg.filters import (array_to_image, segment_array, segmentation_to_polydata,
                           tetra_segmentation_to_vtk)
from ctseg.filters.convert import ImageGeometry, image_to_array
from ctseg.filters.convert3d import triangles_polydata, world_surfaces
from ctseg.filters.writers import material_colors
from ctseg.params import AUTO, AUTO_NUMBER, SPECS, resolve
from ctseg.raster import label_image, volume_labels

PARAMETERS = {spec.vtk: spec for spec in SPECS.values()}
"""Parameter node name -> :class:`ctseg.params.Param`, every spec parameter, in the spec's
order."""
MODULE_NAME = "CTSeg"


def parameter_text(spec, value):
    """How a parameter value is written in the parameter node (read back by
    ``spec.parse``)."""
    return spec.to_text(value)


GROUP_LABELS = {"density": "Density map", "sites": "Initial sites", "cvt": "CVT (Lloyd)",
                "levels": "Material levels", "graphcut": "Graph cut",
                "recursion": "Recursive cut", "corrections": "Corrections",
                "volume": "Volume"}


def _decimals(value):
    text = f"{value:.12g}" if isinstance(value, float) else ""
    if "e-" in text:
        return int(text.split("e-")[1])
    return len(text.split(".")[1]) if "." in text else 0


def field_description(spec):
    """What the Widget shows for one parameter, from the spec alone (no Qt here).

    Returns
    -------
    dict
        ``widget``: 'check' (bool), 'combo' (choice; ``items``), 'text' (a list of
        numbers, as :meth:`ctseg.params.Param.to_text` writes it), 'int' or 'float' (spin
        boxes with ``minimum``, ``maximum``, and for floats ``decimals`` and ``step``);
        ``special``: the text shown at the minimum when that minimum means 'auto'
        (:data:`ctseg.params.AUTO_NUMBER`), else None; ``tooltip``: meaning, unit, range.
    """
    tooltip = spec.doc + (f" [{spec.unit}]" if spec.unit else "") + f"; valid: {spec.range_text()}"
    out = {"widget": spec.kind, "tooltip": tooltip, "special": None}
    if spec.kind == "bool":
        out["widget"] = "check"
    elif spec.kind == "floats":
        out["widget"] = "text"
    elif spec.kind == "choice":
        out.update(widget="combo", items=list(spec.choices))
    else:
        low = spec.low
        if spec.auto:
            low = min(low, AUTO_NUMBER)
            out["special"] = AUTO
        out.update(minimum=low, maximum=spec.high)
        if spec.kind == "float":
            # a step of a tenth of the default's order of magnitude (or of the range's)
            ref = abs(spec.default) if spec.default not in (AUTO, 0) else min(spec.high - low, 10)
            step = 10.0 ** (np.floor(np.log10(ref)) - 1)
            decimals = max(4, _decimals(float(step)), _decimals(float(spec.low)))
            out.update(decimals=decimals, step=float(step))
        else:
            out.update(minimum=int(low), maximum=int(spec.high))
    return out


def register_segmentation_converters():
    """Let segmentations convert between binary labelmaps and closed surfaces (slicer-core
    registers no conversion rule by itself; the application does, and a second
    registration of the same rule is ignored)."""
    factory = slicer.vtkSegmentationConverterFactory.GetInstance()
    have = {rule.GetName() for rule in factory.GetConverterRules()}
    for rule_class in (slicer.vtkBinaryLabelmapToClosedSurfaceConversionRule,
                       slicer.vtkClosedSurfaceToBinaryLabelmapConversionRule):
        rule = rule_class()
        if rule.GetName() not in have:
            factory.RegisterConverterRule(rule)


def volume_geometry(volume_node):
    """ctseg's index-to-world map of a volume node: its IJK-to-RAS matrix (Slicer keeps the
    image data's own origin and spacing at 0 and 1 and the geometry in that matrix)."""
    m = vtkMatrix4x4()
    volume_node.GetIJKToRASMatrix(m)
    mat = np.array([[m.GetElement(r, c) for c in range(4)] for r in range(4)])
    spacing = np.linalg.norm(mat[:3, :3], axis=0)
    return ImageGeometry(origin=mat[:3, 3], spacing=spacing, direction=mat[:3, :3] / spacing)


class CTSegLogic:
    """Segment a scalar volume node with ctseg.

    Parameters
    ----------
    scene : vtkMRMLScene
        ``slicer.mrmlScene`` in the application; any scene in scripts and tests.
    """

    def __init__(self, scene):
        self.scene = scene

    # --- parameters -----------------------------------------------------------------
    def parameter_node(self):
        """The module's parameter node (created with the defaults on first use)."""
        node = None
        for k in range(self.scene.GetNumberOfNodesByClass("vtkMRMLScriptedModuleNode")):
            cand = self.scene.GetNthNodeByClass(k, "vtkMRMLScriptedModuleNode")
            if cand.GetModuleName() == MODULE_NAME:
                node = cand
                break
        if node is None:
            node = slicer.vtkMRMLScriptedModuleNode()
            node.SetModuleName(MODULE_NAME)
            node.SetName(f"{MODULE_NAME} parameters")
            self.scene.AddNode(node)
        for name, spec in PARAMETERS.items():
            if not node.GetParameter(name):
                node.SetParameter(name, parameter_text(spec, spec.default))
        return node

    def parameters(self, node=None):
        """The parameter node's values as a :class:`ctseg.params.SegmentParams`.

        Raises
        ------
        ParameterError
            A value the spec refuses, naming the node parameter and the ctseg name.
        """
        node = node or self.parameter_node()
        values = {}
        for name, spec in PARAMETERS.items():
            text = node.GetParameter(name)
            if not text:
                continue
            try:
                values[spec.name] = spec.parse(text)
            except ParameterError as exc:
                raise ParameterError(f"{name}: {exc}") from None
        return resolve(**values)

    # --- the work -------------------------------------------------------------------
    def run(self, volume_node, parameter_node=None, progress=None):
        """Segment ``volume_node``; return ``(model_node, segmentation_node, result)``.

        Mode 'slices': the model node holds the triangle mesh in RAS (cell arrays
        ``material``, ``gray``, ``slice``); the segmentation node holds one segment per
        material, made from the mesh rasterised on the volume's voxels (binary labelmap
        representation, closed surfaces by the registered converter); ``result`` is a
        SegmentedMesh or VolumeSegmentation.

        Mode '3d' (and 'auto', the default, on a volume whose 3D mode fits in memory:
        :func:`ctseg.volume.volume_mode`): the model node holds the tetrahedra in RAS (a vtkUnstructuredGrid,
        cell arrays ``material`` and ``gray``; shown cut in the slice views); the
        segmentation node holds one segment per material whose source representation is
        ctseg's closed surface of that material, in RAS; ``result`` is a
        TetraSegmentation (spacing: the volume's).

        Either way the model is coloured by material, segment k is named
        ``material k (gray G)`` with material k's colour, and ``progress(fraction,
        message)`` is called as the work goes on.

        Raises
        ------
        ctseg.errors.CTSegError
            No image in the node, a bad parameter, a single slice in mode '3d', or
            anything ctseg refuses.
        """
        report = progress or (lambda fraction, message: None)
        image = volume_node.GetImageData() if volume_node is not None else None
        if image is None:
            raise InputError("volume: the node holds no image data")
        arr, _ = image_to_array(image)
        geom = volume_geometry(volume_node)
        params = self.parameters(parameter_node)
        name = volume_node.GetName()
        report(0.0, f"segmenting {name}")
        result = segment_array(arr, params, spacing=geom.spacing,
                               progress=lambda f, s: report(0.9 * f, s))
        report(0.9, "building the nodes")
        if hasattr(result, "tetrahedra"):  # mode '3d', or 'auto' on a volume that fits
            grid, _ = tetra_segmentation_to_vtk(result, geom)
            model = self._model_node(grid, f"{name} ctseg tetrahedra", result.n_materials)
            # the box of tetrahedra would hide everything in 3D: its cut shows in the slices
            model.GetDisplayNode().SetVisibility3D(False)
            model.GetDisplayNode().SetVisibility2D(True)
            segmentation = self._surface_segmentation_node(
                world_surfaces(result, geom), volume_node, f"{name} ctseg segmentation",
                result.material_gray)
        else:
            labels = volume_labels(result, arr.shape) if arr.ndim == 3 else None
            mesh, _ = segmentation_to_polydata(result, geom)
            model = self._model_node(mesh, f"{name} ctseg mesh", result.n_materials)
            if labels is None:
                labels = label_image(result.points, result.triangles, result.material,
                                     arr.shape)[None]
            segmentation = self._segmentation_node(labels, volume_node,
                                                   f"{name} ctseg segmentation",
                                                   result.material_gray)
        report(1.0, "done")
        return model, segmentation, result

    def _color_table(self, n_materials):
        table = slicer.vtkMRMLColorTableNode()
        table.SetTypeToUser()
        table.SetNumberOfColors(n_materials)
        table.SetName("ctseg materials")
        for k, rgb in enumerate(material_colors(np.arange(n_materials)) / 255.0):
            table.SetColor(k, f"material {k}", *rgb, 1.0)
        self.scene.AddNode(table)
        return table

    def _model_node(self, mesh, name, n_materials):
        """A model node of a vtkPolyData or vtkUnstructuredGrid, coloured by material."""
        model = slicer.vtkMRMLModelNode()
        model.SetName(name)
        self.scene.AddNode(model)
        model.SetAndObserveMesh(mesh)
        display = slicer.vtkMRMLModelDisplayNode()
        self.scene.AddNode(display)
        display.SetActiveScalarName("material")
        display.SetActiveAttributeLocation(1)  # cells (vtkAssignAttribute::CELL_DATA)
        display.SetAndObserveColorNodeID(self._color_table(n_materials).GetID())
        display.SetScalarRangeFlag(0)  # the colour table's range: one colour per material
        display.SetScalarVisibility(True)
        model.SetAndObserveDisplayNodeID(display.GetID())
        return model

    def _segmentation_node(self, labels, volume_node, name, material_gray):
        """One segment per material from a (nz, ny, nx) label array on the volume's voxels."""
        register_segmentation_converters()
        labelmap = slicer.vtkMRMLLabelMapVolumeNode()
        labelmap.SetName(f"{name} labels")
        self.scene.AddNode(labelmap)
        # label k + 1 for material k: 0 is the background an import leaves out; the
        # image keeps the identity geometry and the node the volume's IJK-to-RAS
        labelmap.SetAndObserveImageData(array_to_image((labels + 1).astype(np.int16)))
        m = vtkMatrix4x4()
        volume_node.GetIJKToRASMatrix(m)
        labelmap.SetIJKToRASMatrix(m)
        segmentation = slicer.vtkMRMLSegmentationNode()
        segmentation.SetName(name)
        self.scene.AddNode(segmentation)
        segmentation.CreateDefaultDisplayNodes()
        if not slicer.vtkSlicerSegmentationsModuleLogic.ImportLabelmapToSegmentationNode(labelmap, segmentation):
            raise CTSegError("segmentation: Slicer could not import the material labels")
        seg = segmentation.GetSegmentation()
        for k in range(seg.GetNumberOfSegments()):
            segment = seg.GetNthSegment(k)
            material = int(segment.GetLabelValue()) - 1
            segment.SetName(segment_name(material, material_gray))
            segment.SetColor(*segment_color(material))
        self.scene.RemoveNode(labelmap)
        return segmentation

    def _surface_segmentation_node(self, surfaces, volume_node, name, material_gray):
        """One segment per material from ctseg's closed surfaces ``(material, RAS points,
        triangles)``, the closed surface being the segmentation's source representation;
        binary labelmaps convert on the volume's voxel grid. The lowest-gray material
        (the air around the part, whose surface includes the box) is hidden in 3D."""
        register_segmentation_converters()
        segmentation = slicer.vtkMRMLSegmentationNode()
        segmentation.SetName(name)
        self.scene.AddNode(segmentation)
        segmentation.CreateDefaultDisplayNodes()
        segmentation.SetReferenceImageGeometryParameterFromVolumeNode(volume_node)
        to_surfaces = getattr(segmentation, "SetSourceRepresentationToClosedSurface", None) \
            or segmentation.SetMasterRepresentationToClosedSurface  # Slicer before the "source" rename
        to_surfaces()
        display = segmentation.GetDisplayNode()
        for material, points, triangles in surfaces:
            segment_id = segmentation.AddSegmentFromClosedSurfaceRepresentation(
                triangles_polydata(points, triangles, {}), segment_name(material, material_gray),
                segment_color(material), f"material_{material}")
            if not segment_id:
                raise CTSegError(f"segmentation: Slicer refused the surface of material {material}")
            if material == 0:
                display.SetSegmentVisibility3D(segment_id, False)
        return segmentation


def segment_name(material, material_gray):
    """The segment name of a material: 'material k (gray G)', G in the input's units."""
    return f"material {material} (gray {material_gray[material]:.4g})"


def segment_color(material):
    """The segment colour (r, g, b in 0..1) of a material: ctseg's material colour."""
    return tuple(float(c) for c in material_colors([material])[0] / 255.0)
