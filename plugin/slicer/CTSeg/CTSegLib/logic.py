"""The GUI-free logic of the 3D Slicer module: a scalar volume node in, a model node (the
segmented mesh, coloured by material) and a segmentation node (one segment per material)
out, parameters kept in a parameter node.

Imports only MRML (``slicer``'s node classes) and ctseg, never qt, ctk or
``slicer.ScriptedLoadableModule``, so it runs in the full application and in PyPI's
slicer-core alike (the tests use the latter).
"""
import numpy as np
from vtkmodules.util import numpy_support
from vtkmodules.vtkCommonDataModel import vtkImageData
from vtkmodules.vtkCommonMath import vtkMatrix4x4

import slicer

from ctseg.errors import CTSegError, InputError, ParameterError
from ctseg.filters import segmentation_to_polydata
from ctseg.filters.convert import ImageGeometry, image_to_array
from ctseg.filters.writers import material_colors
from ctseg.pipeline import segment_image
from ctseg.volume import segment_volume, volume_labels

# parameter name -> (default, type, ctseg keyword); 0 means "from the data" where it may
PARAMETERS = {
    "NumberOfSites": (0, int, "n_sites"),
    "NumberOfMaterials": (0, int, "n_materials"),
    "Seed": (0, int, "seed"),
    "SliceAxis": ("z", str, "axis"),
    "NumberOfJobs": (1, int, "n_jobs"),
    "Lambda": (70.0, float, "lam"),
    "Beta": (0.286, float, "beta"),
}
MODULE_NAME = "CTSeg"


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
        for name, (default, _, _) in PARAMETERS.items():
            if not node.GetParameter(name):
                node.SetParameter(name, str(default))
        return node

    def parameters(self, node=None):
        """The parameter node's values as ctseg keywords."""
        node = node or self.parameter_node()
        out = {}
        for name, (default, kind, key) in PARAMETERS.items():
            text = node.GetParameter(name) or str(default)
            try:
                value = kind(text)
            except ValueError:
                raise ParameterError(f"{name}: {text!r} is not a {kind.__name__}") from None
            out[key] = value
        return out

    # --- the work -------------------------------------------------------------------
    def run(self, volume_node, parameter_node=None, progress=None):
        """Segment ``volume_node``; return ``(model_node, segmentation_node, result)``.

        The model node holds the mesh in RAS (cell arrays ``material``, ``gray``,
        ``slice``; shown coloured by material); the segmentation node holds one segment
        per material, made from the mesh rasterised on the volume's voxels (binary
        labelmap representation, closed surfaces by the registered converter).
        ``progress(fraction, message)`` is called as the work goes on.

        Raises
        ------
        ctseg.errors.CTSegError
            No image in the node, a bad parameter, or anything ctseg refuses.
        """
        report = progress or (lambda fraction, message: None)
        image = volume_node.GetImageData() if volume_node is not None else None
        if image is None:
            raise InputError("volume: the node holds no image data")
        arr, _ = image_to_array(image)
        geom = volume_geometry(volume_node)
        kw = self.parameters(parameter_node)
        common = dict(n_sites=kw["n_sites"] or None, seed=kw["seed"],
                      n_materials=kw["n_materials"] or None, lam=kw["lam"], beta=kw["beta"])
        name = volume_node.GetName()
        report(0.0, f"segmenting {name}")
        if arr.ndim == 2:
            result = segment_image(arr, progress=lambda f, s: report(0.9 * f, s), **common)
            labels = None
        else:
            result = segment_volume(arr, axis=kw["axis"], n_jobs=kw["n_jobs"],
                                    progress=lambda f, s: report(0.9 * f, s), **common)
            labels = volume_labels(result, arr.shape)
        mesh, _ = segmentation_to_polydata(result, geom)
        report(0.9, "building the nodes")
        model = self._model_node(mesh, f"{name} ctseg mesh", result.n_materials)
        if labels is None:
            from ctseg.metrics import label_image

            labels = label_image(result.points, result.triangles, result.material, arr.shape)[None]
        segmentation = self._segmentation_node(labels, volume_node, f"{name} ctseg segmentation",
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
        model = slicer.vtkMRMLModelNode()
        model.SetName(name)
        self.scene.AddNode(model)
        model.SetAndObservePolyData(mesh)
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
        img = vtkImageData()
        img.SetDimensions(labels.shape[2], labels.shape[1], labels.shape[0])
        # label k + 1 for material k: 0 is the background an import leaves out
        img.GetPointData().SetScalars(
            numpy_support.numpy_to_vtk((labels + 1).astype(np.int16).ravel(), deep=True))
        labelmap.SetAndObserveImageData(img)
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
        colours = material_colors(np.arange(len(material_gray))) / 255.0
        for k in range(seg.GetNumberOfSegments()):
            segment = seg.GetNthSegment(k)
            material = int(segment.GetLabelValue()) - 1
            segment.SetName(f"material {material} (gray {material_gray[material]:.4g})")
            segment.SetColor(*colours[material])
        self.scene.RemoveNode(labelmap)
        return segmentation
