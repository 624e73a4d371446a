"""What every ctseg VTK filter shares (the PVGeo pattern): one base class over
VTKPythonAlgorithmBase with error reporting, parameter setters that call Modified(), and an
``apply`` convenience for plain Python use."""
import traceback

from vtkmodules.util.vtkAlgorithm import VTKPythonAlgorithmBase

from ctseg.errors import CTSegError


class CTSegAlgorithm(VTKPythonAlgorithmBase):
    """Base of the ctseg filters.

    ``RequestData`` is implemented by subclasses as ``_request(request, in_info, out_info)``;
    an error is reported through VTK's error mechanism (ParaView shows it in its output
    window) and kept in ``last_error``, and the output is left empty rather than wrong.
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

    def GetOutput(self, port=0):
        """The output data object, as VTK's own algorithms offer it."""
        return self.GetOutputDataObject(port)

    def apply(self, data):
        """Run the filter on a data object in plain Python and return the output.

        Raises the ctseg error instead of returning an empty output.
        """
        self.SetInputDataObject(0, data)
        self.Update()
        if self.last_error:
            raise CTSegError(self.last_error)
        return self.GetOutputDataObject(0)
