"""Lets Debian's ParaView 5.11.0 load Python plugins on Python 3.11.

Its ``paraview.detail.pythonalgorithm`` (the module behind the ``smproxy`` decorators)
imports ``inspect.getargspec``, which Python 3.11 removed, so every Python plugin fails
with "Failed to import paraview.detail.pythonalgorithm". ParaView's embedded Python runs
``sitecustomize`` at start-up: with this folder on PYTHONPATH the function is back before
ParaView needs it. It only counts a function's positional parameters, which is all ParaView
uses. Debian's own sitecustomize (an optional apport hook) is run afterwards.
"""
import inspect
from collections import namedtuple

if not hasattr(inspect, "getargspec"):
    _ArgSpec = namedtuple("ArgSpec", "args varargs keywords defaults")

    def getargspec(func):
        spec = inspect.getfullargspec(func)
        return _ArgSpec(spec.args, spec.varargs, spec.varkw, spec.defaults)

    inspect.getargspec = getargspec

try:  # Debian's /etc/python3.11/sitecustomize.py, which this file shadows
    import apport_python_hook
except ImportError:
    pass
else:
    apport_python_hook.install()
