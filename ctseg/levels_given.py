"""Material gray levels given by the user (the ``gray_levels`` parameter): checked against
the data they are for, and put on the 0-255 scale the labelling works on."""
import numpy as np

from .errors import ParameterError
from .params import AUTO, check


def check_gray_levels(gray_levels, data):
    """Refuse given levels that no material of ``data`` can have.

    A level outside the range of the data's gray values means the wrong units or a typing
    error; the check runs on the input as given, before any correction changes its values.

    Parameters
    ----------
    gray_levels : sequence of float or 'auto'
        As the parameter ``gray_levels``; 'auto' passes.
    data : array_like
        The gray values (an image, a volume or sampled slices of it).

    Raises
    ------
    ParameterError
        Naming the first level outside the data's range, and the range.

    Example
    -------
    >>> check_gray_levels((10.0, 60.0), np.array([[10.0, 110.0]]))
    >>> try:
    ...     check_gray_levels((10.0, 600.0), np.array([[10.0, 110.0]]))
    ... except ValueError as err:
    ...     print(str(err)[:60])
    gray_levels: 600 lies outside the gray values of the data, [
    """
    levels = check("gray_levels", gray_levels)
    if levels == AUTO:
        return
    data = np.asarray(data)
    lo, hi = float(data.min()), float(data.max())
    outside = [v for v in levels if not lo <= v <= hi]
    if outside:
        raise ParameterError(f"gray_levels: {outside[0]:g} lies outside the gray values of "
                             f"the data, [{lo:g}, {hi:g}]; give the levels in the input's "
                             f"units")


def given_levels_255(gray_levels, scale):
    """Given levels (input units) on the 0-255 scale of ``scale`` = (offset, factor).

    Example
    -------
    >>> given_levels_255((10.0, 60.0), (10.0, 2.0)).tolist()
    [0.0, 100.0]
    """
    offset, factor = scale
    return (np.asarray(check("gray_levels", gray_levels), float) - offset) * factor
