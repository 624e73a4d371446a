"""3D Slicer scripted module: segment a CT volume into a mesh with one material per
element (ctseg, after Yang et al. 2014): triangles slice by slice, or tetrahedra with a
closed surface per material in 3D mode.

The Widget only gathers parameters into the parameter node and calls the Logic
(``CTSegLib/logic.py``), which holds all the work and runs without the GUI. Its fields are
made from the parameter spec (:mod:`ctseg.params`, through the Logic's
``field_description``): a spin box with the spec's range per number ("auto" at 0 where
the value may come from the data), a combo box per choice (Mode: 'auto', 'slices' or '3d'), a
check box per switch.
"""
import ctk
import qt
import slicer
from slicer.ScriptedLoadableModule import (ScriptedLoadableModule, ScriptedLoadableModuleTest,
                                           ScriptedLoadableModuleWidget)

from CTSegLib.logic import (GROUP_LABELS, PARAMETERS, CTSegLogic, field_description,
                            parameter_text)

PHANTOM_SEED_3D = 0  # the self-test phantom's shapes (not ctseg's seed parameter)


class CTSeg(ScriptedLoadableModule):
    def __init__(self, parent):
        ScriptedLoadableModule.__init__(self, parent)
        parent.title = "CT Segment (ctseg)"
        parent.categories = ["Segmentation"]
        parent.dependencies = []
        parent.contributors = ["ctseg developers"]
        parent.helpText = (
            "Segments a CT volume into a mesh whose small elements hug the material "
            "boundaries, one material per element (centroidal Voronoi tessellation and "
            "recursive graph cut, Yang et al. 2014). Mode 'slices': triangles slice by "
            "slice; output a model coloured by material and a segmentation with one "
            "segment per material. Mode '3d': tetrahedra; output a model of the "
            "tetrahedra (cut in the slice views) and a segmentation whose segments are "
            "ctseg's closed surfaces, one per material. Mode 'auto' (the default): 3D "
            "where the memory allows it, else slices.")
        parent.acknowledgementText = "ctseg is GPL-3.0-or-later."


class CTSegWidget(ScriptedLoadableModuleWidget):
    """Inputs and parameters; the Logic does the rest."""

    def setup(self):
        ScriptedLoadableModuleWidget.setup(self)
        self.logic = CTSegLogic(slicer.mrmlScene)
        box = ctk.ctkCollapsibleButton()
        box.text = "Segment"
        self.layout.addWidget(box)
        form = qt.QFormLayout(box)
        self.volume = slicer.qMRMLNodeComboBox()
        self.volume.nodeTypes = ["vtkMRMLScalarVolumeNode"]
        self.volume.noneEnabled = False
        self.volume.addEnabled = False
        self.volume.removeEnabled = False
        self.volume.setMRMLScene(slicer.mrmlScene)
        form.addRow("CT volume:", self.volume)
        self.fields = {}
        forms = {}
        for name, spec in PARAMETERS.items():
            if spec.group not in forms:
                section = ctk.ctkCollapsibleButton()
                section.text = GROUP_LABELS.get(spec.group, spec.group)
                section.collapsed = spec.group not in ("sites", "volume")  # volume: Mode
                form.addRow(section)
                forms[spec.group] = qt.QFormLayout(section)
            field = self._field(field_description(spec))
            forms[spec.group].addRow(f"{name}:", field)
            self.fields[name] = field
        self.progress = qt.QProgressBar()
        form.addRow(self.progress)
        self.apply = qt.QPushButton("Segment")
        form.addRow(self.apply)
        self.apply.connect("clicked(bool)", self.onApply)
        self.layout.addStretch(1)
        self._show(self.logic.parameter_node())

    @staticmethod
    def _field(desc):
        """A Qt field for one parameter from the Logic's description of it."""
        if desc["widget"] == "check":
            field = qt.QCheckBox()
        elif desc["widget"] == "combo":
            field = qt.QComboBox()
            field.addItems(desc["items"])
        elif desc["widget"] == "text":
            field = qt.QLineEdit()
        else:
            field = qt.QSpinBox() if desc["widget"] == "int" else qt.QDoubleSpinBox()
            if desc["widget"] == "float":
                field.setDecimals(desc["decimals"])
                field.setSingleStep(desc["step"])
            field.setRange(desc["minimum"], desc["maximum"])
            if desc["special"]:
                field.setSpecialValueText(desc["special"])  # shown at the minimum
        field.toolTip = desc["tooltip"]
        return field

    def _show(self, node):
        params = self.logic.parameters(node)
        for name, field in self.fields.items():
            spec = PARAMETERS[name]
            value = getattr(params, spec.name)
            if isinstance(field, qt.QCheckBox):
                field.checked = bool(value)
            elif isinstance(field, qt.QComboBox):
                field.setCurrentText(value)
            elif isinstance(field, qt.QLineEdit):
                field.text = spec.to_text(value)
            else:
                field.setValue(spec.to_number(value))

    def _text(self, name, field):
        spec = PARAMETERS[name]
        if isinstance(field, qt.QCheckBox):
            return parameter_text(spec, field.checked)
        if isinstance(field, qt.QComboBox):
            return field.currentText
        if isinstance(field, qt.QLineEdit):
            return field.text
        value = field.value
        return parameter_text(spec, spec.from_number(int(value) if spec.kind == "int" else value))

    def onApply(self):
        def progress(fraction, message):
            self.progress.setValue(int(100 * fraction))
            self.progress.setFormat(f"{message} %p%")
            slicer.app.processEvents()

        with slicer.util.tryWithErrorDisplay("ctseg could not segment the volume.",
                                             waitCursor=True):
            node = self.logic.parameter_node()
            for name, field in self.fields.items():
                node.SetParameter(name, self._text(name, field))
            model, segmentation, result = self.logic.run(self.volume.currentNode(), node,
                                                         progress)
            segmentation.CreateClosedSurfaceRepresentation()  # the segments in 3D (slices mode)
            slicer.util.resetThreeDViews()
            self.progress.setFormat(f"{result.n_materials} materials %p%")


class CTSegTest(ScriptedLoadableModuleTest):
    """Runs the Logic tests (plugin/slicer/test_slicer_logic.py's checks) in the
    application: simulated parts with known truth, segmented in slices mode and in 3D
    mode and compared."""

    def runTest(self):
        import numpy as np

        from ctseg.metrics import dice_per_label
        from ctseg.phantoms import make_volume

        slicer.mrmlScene.Clear(0)
        p = make_volume(5, 96, seed=4)
        volume = slicer.util.addVolumeFromArray(p.image)
        logic = CTSegLogic(slicer.mrmlScene)
        logic.parameter_node().SetParameter("NumberOfSites", "350")
        logic.parameter_node().SetParameter("Mode", "slices")
        model, segmentation, result = logic.run(volume)
        self.assertEqual(result.n_materials, 4)
        self.assertGreater(model.GetPolyData().GetNumberOfCells(), 0)
        self.assertEqual(segmentation.GetSegmentation().GetNumberOfSegments(), 4)
        from ctseg.raster import volume_labels

        dice = dice_per_label(volume_labels(result, p.image.shape), p.truth.astype(np.int64), 4)
        self.assertGreater(min(dice[0], dice[2], dice[3]), 0.93)
        self.delayDisplay(f"ctseg: Dice per material {np.round(dice, 3)}")
        self.test_3d_mode()

    def test_3d_mode(self):
        import numpy as np

        from ctseg.metrics import dice_per_label
        from ctseg.phantoms3d import make_part_3d

        slicer.mrmlScene.Clear(0)
        spacing = (0.2, 0.2, 0.3)
        p = make_part_3d(64, seed=PHANTOM_SEED_3D, spacing=spacing)
        volume = slicer.util.addVolumeFromArray(p.image, ijkToRAS=np.diag([-0.2, -0.2, 0.3, 1.0]))
        logic = CTSegLogic(slicer.mrmlScene)
        node = logic.parameter_node()
        node.SetParameter("Mode", "3d")
        model, segmentation, result = logic.run(volume)
        self.assertEqual(model.GetMesh().GetNumberOfCells(), len(result.tetrahedra))
        seg = segmentation.GetSegmentation()
        self.assertEqual(seg.GetNumberOfSegments(), 4)
        self.assertEqual(seg.GetSourceRepresentationName(), "Closed surface")
        labelmap = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLLabelMapVolumeNode")
        ids = [seg.GetNthSegmentID(k) for k in range(4)]
        self.assertTrue(slicer.vtkSlicerSegmentationsModuleLogic.ExportSegmentsToLabelmapNode(
            segmentation, ids, labelmap, volume))
        lab = slicer.util.arrayFromVolume(labelmap).astype(np.int64) - 1
        dice = dice_per_label(lab, p.truth.astype(np.int64), 4)
        self.assertGreater(min(dice[0], dice[3]), 0.8)
        self.delayDisplay(f"ctseg 3D: Dice per material {np.round(dice, 3)}")
