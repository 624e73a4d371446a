"""What every ctseg VTK filter shares (the PVGeo pattern): one base class over
VTKPythonAlgorithmBase with error reporting, the spec parameters as Set/Get pairs, the
conversions of the inputs, and an ``apply`` convenience for plain Python use.

A filter class names the parameters it takes in ``PARAMETERS`` (spec names of
:mod:`ctseg.params`); it then gets ``Set<Vtk>``/``Get<Vtk>`` for each (``Param.vtk``, e.g.
``SetNumberOfSites``, ``SetDensityFloor``), ``SetParameter(name, value)`` and
``GetParameter(name)`` by spec name, and its values in ``self.params``, a
:class:`ctseg.params.SegmentParams` handed as it is to the ctseg functions. Nothing about a
parameter (default, range, meaning) is written here: it all comes from the spec.
"""
import difflib
import numbers
import traceback

from vtkmodules.util.vtkAlgorithm import VTKPythonAlgorithmBase
from vtkmodules.vtkCommonDataModel import vtkDataObject, vtkImageData, vtkPolyData

from ctseg.errors import CTSegError, InputError, ParameterError
from ctseg.params import AUTO_NUMBER, DEFAULTS, SPECS, resolve_name

from .convert import image_to_array


def spec_names(*groups, names=()):
    """Spec parameter names of whole ``groups`` plus single ``names``, in the spec's order.

    Example
    -------
    >>> spec_names("cvt")
    ('tol_px', 'max_iter')
    """
    unknown = [n for n in names if n not in SPECS]
    if unknown:
        resolve_name(unknown[0])  # raises, naming the closest valid name
    return tuple(n for n, p in SPECS.items() if p.group in groups or n in names)


def spec_value(spec, value):
    """``value`` for parameter ``spec``: a Python value as the spec checks it, or a number
    as VTK and ParaView send it (:data:`ctseg.params.AUTO_NUMBER` for AUTO where the
    parameter allows it, a choice by its index).

    Raises
    ------
    ParameterError
        Naming the parameter, the value and the valid range.
    """
    is_number = isinstance(value, numbers.Number) and not isinstance(value, bool)
    if is_number and (spec.kind == "choice" or (spec.auto and value == AUTO_NUMBER)):
        return spec.from_number(value)
    return spec.check(value)


def _accessors(name):
    spec = SPECS[name]
    doc = f"{spec.doc}{f' [{spec.unit}]' if spec.unit else ''}; valid: {spec.range_text()}"

    def setter(self, value):
        self._set_param(name, value)

    def getter(self):
        return getattr(self.params, name)

    setter.__name__, getter.__name__ = f"Set{spec.vtk}", f"Get{spec.vtk}"
    numbers_note = (f"; from VTK, {AUTO_NUMBER} = auto" if spec.auto else
                    "; from VTK, the index of a choice" if spec.kind == "choice" else "")
    setter.__doc__ = f"Set ``{name}``: {doc}{numbers_note}."
    getter.__doc__ = f"``{name}`` (default {spec.default!r})."
    return setter, getter


class CTSegAlgorithm(VTKPythonAlgorithmBase):
    """Base of the ctseg filters.

    Subclasses implement ``_request(request, in_info, out_info)`` and declare
    ``PARAMETERS``; an error is reported through VTK's error mechanism (ParaView shows it
    in its output window) and kept in ``last_error``, and the output is left empty rather
    than wrong.
    """

    PARAMETERS = ()
    """Spec names of the parameters this filter takes."""

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "PARAMETERS" not in cls.__dict__:
            return  # inherits its parent's accessors (e.g. a ParaView proxy class)
        cls.PARAMETERS = spec_names(names=cls.PARAMETERS)
        for name in cls.PARAMETERS:
            setter, getter = _accessors(name)
            for method in (setter, getter):
                if method.__name__ not in cls.__dict__:
                    setattr(cls, method.__name__, method)

    def __init__(self, n_inputs=1, input_type="vtkImageData", n_outputs=1,
                 output_type="vtkPolyData"):
        super().__init__(nInputPorts=n_inputs, inputType=input_type,
                         nOutputPorts=n_outputs, outputType=output_type)
        self.last_error = None
        self.params = DEFAULTS

    # --- parameters ---------------------------------------------------------------------
    def _own_name(self, key):
        """The spec name(s) ``key`` stands for among this filter's parameters, or
        ParameterError naming the closest one (or the closest spec name)."""
        close = difflib.get_close_matches(str(key), self.PARAMETERS, n=1, cutoff=0.5)
        mine = f"(the parameters of {type(self).__name__}: {', '.join(self.PARAMETERS) or 'none'})"
        hint = f"; did you mean {close[0]!r}?" if close else ""
        try:
            names = [n for n in resolve_name(key) if n in self.PARAMETERS]
        except ParameterError as exc:
            if not close:
                raise ParameterError(f"{exc} {mine}") from None
            raise ParameterError(f"{key}: not a ctseg parameter{hint} {mine}") from None
        if not names:
            raise ParameterError(f"{key}: not a parameter of {type(self).__name__} (another "
                                 f"stage's){hint} {mine}")
        return names

    def _set_param(self, name, value):
        value = spec_value(SPECS[name], value)
        if getattr(self.params, name) != value:
            self.params = self.params.replace(**{name: value})
            self.Modified()

    def SetParameter(self, name, value):
        """Set one of this filter's parameters by its spec name (``ctseg params`` lists
        them); Python values or VTK numbers, as the Set<Vtk> methods take them."""
        for own in self._own_name(name):
            self._set_param(own, value)

    def GetParameter(self, name):
        """The value of one of this filter's parameters, by its spec name."""
        return getattr(self.params, self._own_name(name)[0])

    def GetParameters(self):
        """{spec name: value} of every parameter this filter takes."""
        return {name: getattr(self.params, name) for name in self.PARAMETERS}

    # --- the request --------------------------------------------------------------------
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

    def _progress(self, start=0.0, share=1.0):
        """A ``progress(fraction, stage)`` callback for ctseg reporting into this filter's
        progress between ``start`` and ``start + share``."""
        return lambda fraction, *_: self.UpdateProgress(start + share * fraction)

    # --- inputs and outputs -------------------------------------------------------------
    @staticmethod
    def _input(in_info, port=0):
        return vtkDataObject.GetData(in_info[port], 0)

    def gray_array_name(self):
        """The point array read as the gray values: the one chosen with VTK's
        ``SetInputArrayToProcess(0, port, 0, vtkDataObject.FIELD_ASSOCIATION_POINTS, name)``
        (ParaView's "Gray values" property), or None for the active scalars."""
        info = self.GetInputArrayInformation(0)
        key = vtkDataObject.FIELD_NAME()
        return info.Get(key) if info is not None and info.Has(key) else None

    def _input_slice(self, in_info, port=0):
        """The image on ``port`` as a (rows, cols) array and its geometry; volumes refused."""
        image = vtkImageData.GetData(in_info[port], 0)
        if image is None:
            raise InputError(f"input {port}: expected a vtkImageData")
        arr, geom = image_to_array(image, self.gray_array_name())
        if arr.ndim != 2:
            raise InputError(f"image: {arr.shape[0]} slices; {type(self).__name__} takes one "
                             "slice (CTSegmentFilter segments volumes, in 3D or slice by slice; "
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
