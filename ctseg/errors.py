"""The errors ctseg raises on purpose.

Every error a user can cause is one of these, raised where the problem is known, with a
message that names the input or parameter, the value seen and what would be valid.
"""


class CTSegError(Exception):
    """Base class of every error ctseg raises on purpose."""


class InputError(CTSegError, ValueError):
    """The input image or file is unusable (shape, values, format, corrupt file)."""


class ParameterError(CTSegError, ValueError):
    """A parameter is out of its valid range or inconsistent with the input."""


class MeshCheckError(CTSegError, RuntimeError):
    """A mesh failed the checks that every written mesh must pass."""


class ResumeError(InputError):
    """Saved slices cannot be resumed: made from another input or other parameters."""
