"""The machinery of the parameter spec (:mod:`ctseg.params` holds the spec itself): what a
parameter is, how a value is checked, and how it is written where only numbers or text fit."""
import dataclasses
import numbers
from dataclasses import dataclass, field

import numpy as np

from .errors import ParameterError

AUTO = "auto"
"""The one sentinel for "derived from the data"."""

AUTO_NUMBER = 0
"""How AUTO is written where only a number fits (VTK properties, spin boxes)."""


@dataclass(frozen=True)
class Param:
    """What one parameter is: the spec entry behind every layer's version of it.

    ``kind`` is 'int', 'float', 'bool', 'choice' or 'floats' (a strictly ascending list of
    numbers, written as text ``'40, 115, 150'`` where only text fits); ``low``/``high``
    bound numbers (``low_open``/``high_open`` exclude the bound); ``auto`` says whether :data:`AUTO` is
    allowed; ``vtk`` is the CamelCase name of the VTK/ParaView/Slicer property; ``cli`` the
    command-line option of the common parameters (the others go through ``--set``).
    """

    name: str
    group: str
    kind: str
    default: object
    doc: str
    unit: str = ""
    low: float = None
    high: float = None
    low_open: bool = False
    high_open: bool = False
    auto: bool = False
    choices: tuple = ()
    vtk: str = ""
    cli: str = ""

    def range_text(self):
        """The valid values in words, for messages and tables."""
        if self.kind == "bool":
            text = "true or false"
        elif self.kind == "choice":
            text = "one of " + ", ".join(repr(c) for c in self.choices)
        elif self.kind == "floats":
            text = "strictly ascending numbers, comma-separated"
        else:
            lo = "-inf" if self.low is None else _number_text(self.low)
            hi = "inf" if self.high is None else _number_text(self.high)
            text = f"{'(' if self.low_open else '['}{lo}, {hi}{')' if self.high_open else ']'}"
        return text + (" or 'auto'" if self.auto else "")

    def check(self, value):
        """``value`` as this parameter's type, or ParameterError naming the parameter, the
        value and the valid range. None and 'auto' give AUTO where allowed."""
        if self.auto and (value is None or (isinstance(value, str) and value.lower() == AUTO)):
            return AUTO
        bad = ParameterError(f"{self.name}: {value!r} is not valid; valid: {self.range_text()}")
        if self.kind == "bool":
            if isinstance(value, (bool, np.bool_)):
                return bool(value)
            if isinstance(value, str) and value.lower() in ("true", "false", "1", "0", "yes", "no", "on", "off"):
                return value.lower() in ("true", "1", "yes", "on")
            if isinstance(value, numbers.Integral) and value in (0, 1):
                return bool(value)
            raise bad
        if self.kind == "choice":
            if value in self.choices:
                return value
            raise bad
        if self.kind == "floats":
            return self._check_floats(value, bad)
        if isinstance(value, str):
            try:
                value = float(value)
            except ValueError:
                raise bad from None
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
            raise bad
        if self.kind == "int":
            if not np.isfinite(float(value)) or float(value) != int(value):
                raise bad
            value = int(value)
        else:
            value = float(value)
            if not np.isfinite(value):
                raise bad
        if self.low is not None and (value < self.low or (self.low_open and value == self.low)):
            raise bad
        if self.high is not None and (value > self.high or (self.high_open and value == self.high)):
            raise bad
        return value

    def _check_floats(self, value, bad):
        if isinstance(value, str):
            parts = value.replace(",", " ").split()
        elif isinstance(value, (list, tuple, np.ndarray)):
            parts = list(np.ravel(np.asarray(value, dtype=object)))
        elif isinstance(value, numbers.Real):  # one level: one material
            parts = [value]
        else:
            raise bad
        if any(isinstance(t, (bool, np.bool_)) for t in parts):
            raise bad
        try:
            values = [float(t) for t in parts]
        except (TypeError, ValueError):
            raise bad from None
        if not values or not all(np.isfinite(values)):
            raise bad
        if any(b <= a for a, b in zip(values, values[1:])):
            raise ParameterError(f"{self.name}: {value!r} is not valid; the values must be "
                                 f"strictly ascending (one per material, lowest first)")
        return tuple(values)

    def to_text(self, value):
        """The value as text that :meth:`parse` reads back (CLI, parameter nodes, ParaView
        string properties)."""
        if value == AUTO:
            return AUTO
        if self.kind == "floats":
            # exact: repr round-trips every float
            return ", ".join(str(int(v)) if float(v).is_integer() and abs(v) < 1e15
                             else repr(float(v)) for v in value)
        if self.kind == "bool":
            return "true" if value else "false"
        return str(value)

    def to_number(self, value):
        """The value as a number (AUTO as :data:`AUTO_NUMBER`, a choice as its index)."""
        if self.kind == "choice" and (value != AUTO or AUTO in self.choices):
            return self.choices.index(value)  # 'auto' among the choices: its index, like the others
        if value == AUTO:
            return AUTO_NUMBER
        if self.kind == "bool":
            return int(value)
        return value

    def from_number(self, number):
        """Inverse of :meth:`to_number`, checked."""
        if self.auto and number == AUTO_NUMBER and AUTO not in (self.choices or ()):
            return AUTO
        if self.kind == "choice":
            index = int(number)
            if not 0 <= index < len(self.choices):
                raise ParameterError(f"{self.name}: choice index {number!r} is not valid; "
                                     f"valid: 0..{len(self.choices) - 1} ({self.range_text()})")
            return self.choices[index]
        return self.check(number)

    def parse(self, text):
        """A value from command-line or parameter-node text ('auto', or
        :data:`AUTO_NUMBER`, for AUTO)."""
        text = str(text).strip()
        if self.kind in ("int", "float") and not (self.auto and text.lower() == AUTO):
            try:
                number = float(text)
            except ValueError:
                raise ParameterError(f"{self.name}: {text!r} is not a number; valid: "
                                     f"{self.range_text()}") from None
            return self.from_number(number)
        return self.check(text)


def _number_text(x):
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else f"{x:g}"


def _param(default, kind, doc, unit="", *, low=None, high=None, low_open=False,
           high_open=False, auto=False, choices=(), vtk="", cli=""):
    spec = dict(kind=kind, default=default, doc=doc, unit=unit, low=low, high=high,
                low_open=low_open, high_open=high_open, auto=auto, choices=tuple(choices),
                vtk=vtk, cli=cli)
    return field(default=default, metadata={"param": spec})


def _camel(name):
    return "".join(part.capitalize() for part in name.split("_"))


class _Group:
    """Base of the stage groups: every field checked (and normalised) on construction."""

    group = ""

    def __post_init__(self):
        for f in dataclasses.fields(self):
            object.__setattr__(self, f.name, self.spec(f.name).check(getattr(self, f.name)))

    @classmethod
    def spec(cls, name):
        """The :class:`Param` of field ``name``."""
        f = {f.name: f for f in dataclasses.fields(cls)}[name]
        meta = dict(f.metadata["param"])
        meta["vtk"] = meta["vtk"] or _camel(name)
        return Param(name=name, group=cls.group, **meta)
