"""Input checks shared by the stages: one place that turns bad input into a clear error."""
import numbers

import numpy as np

from .errors import InputError, ParameterError


def as_image(image, name="image", min_size=2):
    """Return `image` as a finite float64 2D array, or raise InputError saying what is wrong."""
    try:
        arr = np.asarray(image)
    except Exception as exc:  # e.g. ragged nested lists
        raise InputError(f"{name}: cannot be read as an array ({exc})") from None
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise InputError(f"{name}: expected a numeric array, got dtype {arr.dtype}")
    if np.iscomplexobj(arr):
        raise InputError(f"{name}: complex values are not a CT image (dtype {arr.dtype})")
    if arr.ndim != 2:
        raise InputError(
            f"{name}: expected a 2D array (rows, cols), got shape {arr.shape}; "
            "mesh volumes with ctseg.segment_volume and convert colour images to one channel"
        )
    if arr.size == 0:
        raise InputError(f"{name}: the array is empty (shape {arr.shape})")
    if min(arr.shape) < min_size:
        raise InputError(
            f"{name}: shape {arr.shape} is too small; each side needs at least {min_size} pixels"
        )
    arr = arr.astype(np.float64)
    bad = ~np.isfinite(arr)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise InputError(
            f"{name}: {int(bad.sum())} pixel(s) are NaN or infinite (first at row {r}, col {c})"
        )
    return arr


SPAN_LIMITS = (1e-150, 1e150)
"""Gray values whose span (when not 0) or magnitude fall outside these are refused: their
squares (variances, fits) and sums over a large image must stay finite and nonzero in
float64 (no scanner writes such values)."""


def check_value_range(arr, name):
    """InputError unless a float image's values lie within :data:`SPAN_LIMITS` (checked once,
    at the public entries: a slice or a stage's array may span less than the whole)."""
    arr = np.asarray(arr)
    if arr.dtype.kind != "f" or arr.size == 0:
        return
    lo, hi = float(arr.min()), float(arr.max())
    span = hi - lo
    if (span and not SPAN_LIMITS[0] <= span <= SPAN_LIMITS[1]) or max(-lo, hi) > SPAN_LIMITS[1]:
        raise InputError(f"{name}: values {lo:g}..{hi:g} are out of the range ctseg can compute "
                         f"with (span and size within {SPAN_LIMITS[0]:g}..{SPAN_LIMITS[1]:g}); "
                         "rescale the data")


def check_number(value, name, low=None, high=None, low_open=False, high_open=False,
                 integer=False):
    """Check a scalar parameter against its range and return it (as int or float)."""
    kind = numbers.Integral if integer else numbers.Real
    if isinstance(value, bool) or not isinstance(value, (kind, np.integer if integer else np.number)):
        raise ParameterError(f"{name}: expected {'an integer' if integer else 'a number'}, got {value!r}")
    value = int(value) if integer else float(value)
    if not integer and not np.isfinite(value):
        raise ParameterError(f"{name}: must be finite, got {value!r}")
    if low is not None and (value < low or (low_open and value == low)):
        raise ParameterError(f"{name}: must be {'>' if low_open else '>='} {low}, got {value!r}")
    if high is not None and (value > high or (high_open and value == high)):
        raise ParameterError(f"{name}: must be {'<' if high_open else '<='} {high}, got {value!r}")
    return value


def as_volume(volume, name="volume", min_side=1):
    """Return ``volume`` as a 3D numeric array (a 2D one as one slice), or raise InputError
    saying what is wrong. NaN and infinite values are refused here, before any slice runs;
    ``min_side`` is the fewest voxels along every axis (2 for the 3D stages)."""
    try:
        vol = np.asarray(volume)
    except Exception as exc:
        raise InputError(f"{name}: cannot be read as an array ({exc})") from None
    if vol.ndim == 2:
        vol = vol[None]
    if vol.ndim != 3:
        raise InputError(f"{name}: expected a 3D array (slices, rows, cols), got shape {vol.shape}")
    if vol.size == 0:
        raise InputError(f"{name}: the array is empty (shape {vol.shape})")
    if min(vol.shape) < min_side:
        raise InputError(f"{name}: shape {vol.shape} is too small; each side needs at least "
                         f"{min_side} voxels")
    if vol.dtype == object or not (np.issubdtype(vol.dtype, np.number) or vol.dtype == bool) \
            or np.iscomplexobj(vol):
        raise InputError(f"{name}: expected real numbers, got dtype {vol.dtype}")
    if np.issubdtype(vol.dtype, np.floating):
        bad = ~np.isfinite(vol)
        if bad.any():
            k, r, c = np.argwhere(bad)[0]
            raise InputError(f"{name}: {int(bad.sum())} voxel(s) are NaN or infinite (first in "
                             f"slice {k}, row {r}, col {c})")
    return vol


MAX_LABEL = 255
"""The largest truth label :func:`as_labels` takes: labels number materials, few of them."""


def as_labels(labels, name="labels"):
    """``labels`` as int64 material numbers (0, 1, ... by ascending gray), or InputError:
    whole numbers from 0 to :data:`MAX_LABEL`, nothing else."""
    arr = np.asarray(labels)
    if arr.dtype.kind not in "biuf":
        raise InputError(f"{name}: labels must be numbers, got {arr.dtype}")
    if arr.size and not (np.all(np.isfinite(arr)) and np.all(arr == np.round(arr))
                         and arr.min() >= 0 and arr.max() <= MAX_LABEL):
        finite = arr[np.isfinite(arr)]
        seen = f"{finite.min():g}..{finite.max():g}" if finite.size else "none finite"
        raise InputError(f"{name}: labels must be whole numbers 0..{MAX_LABEL} (material 0, 1, "
                         f"... by ascending gray); got values {seen}"
                         + (", NaN or infinite ones" if finite.size < arr.size else ""))
    return arr.astype(np.int64)


def check_spacing(spacing):
    """``spacing`` as a float64 array (sx, sy, sz): three finite numbers > 0, or
    ParameterError."""
    try:
        sp = np.asarray(spacing, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError(f"spacing: expected three numbers (sx, sy, sz), got {spacing!r}") from None
    if sp.shape != (3,) or not np.all(np.isfinite(sp)) or not np.all(sp > 0):
        raise ParameterError(f"spacing: expected three finite numbers > 0 (sx, sy, sz), got {spacing!r}")
    return sp
