"""What every ctseg VTK filter shares (the PVGeo pattern): one base class over
VTKPythonAlgorithmBase with error reporting, parameters whose setters call Modified(), the
conversions of the inputs, and an ``apply`` convenience for plain Python use."""
import traceback

from vtkmodules.util.vtkAlgorithm import VTKPythonAlgorithmBase
from vtkmodules.vtkCommonDataModel import vtkDataObject, vtkImageData, vtkPolyData

from ctseg.errors import CTSegError, InputError

from .convert import image_to_array


def parameter(attr, cast, doc=""):
    """A (setter, getter) pair for a filter parameter stored in ``self.<attr>``; the setter
    casts the value and calls Modified() only when it changes."""

    def setter(self, value):
        self._set(attr, cast(value))

    def getter(self):
        return getattr(self, attr)

    setter.__doc__ = getter.__doc__ = doc
    return setter, getter


class CTSegAlgorithm(VTKPythonAlgorithmBase):
    """Base of the ctseg filters.

    Subclasses implement ``_request(request, in_info, out_info)``; an error is reported
    through VTK's error mechanism (ParaView shows it in its output window) and kept in
    ``last_error``, and the output is left empty rather than wrong.
    """

    def __init__(self, n_inputs=1, input_type="vtkImageData", n_outputs=1,
                 output_type="vtkPolyData"):
        super().__init__(nInputPorts=n_inputs, inputType=input_type,
                         nOutputPorts=n_outputs, outputType=output_type)
        self.last_error = None

    def _set(self, name, value):
        if getattr(self, name) != value:
            setattr(self, name, value)
            self.Modified()

    def RequestData(self, request, in_info, out_info):
        self.last_error = None
        try:
            self._request(request, in_info, out_info)
        except CTSegError as exc:
            self.last_error = str(exc)
            self._report(str(exc))
            return 0
        except Exception as exc:  # a bug: keep the traceback for the report
            self.last_error = f"{type(exc).__name__}: {exc}"
            self._report(traceback.format_exc())
            return 0
        return 1

    def _report(self, message):
        from vtkmodules.vtkCommonCore import vtkOutputWindow

        vtkOutputWindow.GetInstance().DisplayErrorText(
            f"{type(self).__name__}: {message}\n")

    # --- inputs and outputs -------------------------------------------------------------
    @staticmethod
    def _input(in_info, port=0):
        return vtkDataObject.GetData(in_info[port], 0)

    def _input_slice(self, in_info, port=0):
        """The image on ``port`` as a (rows, cols) array and its geometry; volumes refused."""
        image = vtkImageData.GetData(in_info[port], 0)
        if image is None:
            raise InputError(f"input {port}: expected a vtkImageData")
        arr, geom = image_to_array(image)
        if arr.ndim != 2:
            raise InputError(f"image: {arr.shape[0]} slices; {type(self).__name__} takes one "
                             "slice (CTSegmentFilter segments volumes slice by slice; "
                             "vtkExtractVOI picks one slice)")
        return arr, geom, image

    @staticmethod
    def _output_poly(out_info, port=0):
        return vtkPolyData.GetData(out_info, port)

    def GetOutput(self, port=0):
        """The output data object, as VTK's own algorithms offer it."""
        return self.GetOutputDataObject(port)

    def apply(self, *inputs):
        """Run the filter on data objects (one per input port) in plain Python and return
        the first output. Raises the ctseg error instead of returning an empty output."""
        for port, data in enumerate(inputs):
            self.SetInputDataObject(port, data)
        self.Update()
        if self.last_error:
            raise CTSegError(self.last_error)
        return self.GetOutputDataObject(0)
