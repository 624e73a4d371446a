"""Stage 1 in 3D next to a dense material: the density volume raised where the volume clipped
below the dense material shows edges that the full volume hides (SPEC 9.1)."""
import numpy as np
from scipy import ndimage

from .density import _checked_volume, _gradient_scale, _rho_from_gradient, _volume_gradient
from .errors import InputError
from .params import DEFAULTS

CAP_MARGIN_PX = 2.5
"""Distance (voxels of the finest axis) from the voxels at or above the cap within which
:func:`capped_density_volume` keeps the full volume's density: the clipped volume's false
edge, in the dense material's blurred edge (a blur up to about a voxel), lies within it."""


def capped_density_volume(volume, cap, spacing=(1.0, 1.0, 1.0),
                          density_sigma_px=DEFAULTS.density_sigma_px,
                          density_floor=DEFAULTS.density_floor,
                          density_saturation=DEFAULTS.density_saturation,
                          density_ridge=DEFAULTS.density_ridge):
    """:func:`ctseg.density.density_volume`, raised where the volume clipped at ``cap`` has
    the stronger edges, away from the voxels at or above ``cap``.

    A dense material (steel in aluminium) has edges many times steeper than the others'.
    Smoothed, its edge cancels the opposite edge of a thin gap next to it, and the ridge
    sharpening divides a weak edge near it by its gradient. Clipped at ``cap`` (the next
    material's level: the dense material then looks like that one), the volume shows
    those edges. Its density follows :func:`ctseg.density.density_volume`'s rule with the
    full volume's normalisation (the same min-max units, noise gradient and full-density
    gradient), so that the two compare. The result is the larger of the two at each voxel
    farther than :data:`CAP_MARGIN_PX` voxels (of the finest axis) from every voxel at or
    above ``cap``, and the full volume's density elsewhere: nearer, the clipped volume
    has a false edge where it cuts the dense material's blurred edge.

    Parameters
    ----------
    volume : (nz, ny, nx) array_like
        Gray volume, as :func:`ctseg.density.density_volume`.
    cap : float
        In the volume's units. A cap at or above the volume's maximum, or at or below its
        minimum, gives :func:`ctseg.density.density_volume`'s result.
    spacing, density_sigma_px, density_floor, density_saturation, density_ridge
        As :func:`ctseg.density.density_volume`.

    Returns
    -------
    rho : (nz, ny, nx) float64 ndarray
        At least :func:`ctseg.density.density_volume`'s value at every voxel, at most
        ``density_floor + 1``.

    Raises
    ------
    InputError
        As :func:`ctseg.density.density_volume`, or a ``cap`` that is not a finite number.
    ParameterError
        As :func:`ctseg.density.density_volume`.

    References
    ----------
    SPEC 9.1 (the density in 3D); Yang et al. 2014, section 5.1 (the density map).

    Example
    -------
    A 2-voxel groove of air in aluminium (gray 10), 3 voxels from steel (gray 1000); the
    groove's far wall, between voxels 11 and 12, is raised:

    >>> from ctseg.density import density_volume
    >>> vol = np.zeros((8, 8, 32)); vol[:, :, 4:] = 10.0
    >>> vol[:, :, 10:12] = 0.0; vol[:, :, 15:] = 1000.0
    >>> rho, raised = density_volume(vol), capped_density_volume(vol, cap=100.0)
    >>> bool((raised >= rho).all()), bool(raised[:, :, 12].mean() > 2 * rho[:, :, 12].mean())
    (True, True)
    """
    vol, sp, sigma, floor, saturation, ridge = _checked_volume(
        volume, spacing, density_sigma_px, density_floor, density_saturation, density_ridge)
    if isinstance(cap, (bool, np.bool_)) or not isinstance(cap, (int, float, np.integer, np.floating)) \
            or not np.isfinite(cap):
        raise InputError(f"cap: expected a finite number, got {cap!r}")
    lo, hi = float(vol.min()), float(vol.max())
    if hi == lo:
        return np.full(vol.shape, floor)
    mag, size = _volume_gradient((vol - lo) / (hi - lo), sp, sigma)
    scale = _gradient_scale(mag, saturation) if mag.max() > 0 else None
    rho = _rho_from_gradient(mag, floor, saturation, ridge, size, scale)
    if not lo < cap < hi or scale is None:
        return rho
    del mag
    clipped, _ = _volume_gradient((np.minimum(vol, cap) - lo) / (hi - lo), sp, sigma)
    raised = np.maximum(rho, _rho_from_gradient(clipped, floor, saturation, ridge, size, scale))
    near = _near(vol >= cap, CAP_MARGIN_PX, sp[::-1] / sp.min())
    return np.where(near, rho, raised)


def _near(mask, radius, sampling):
    """Voxels within Euclidean distance ``radius`` of a True voxel of ``mask`` (nz, ny, nx),
    with ``sampling`` the voxel sides along z, y, x: the ellipsoid's rows along x, each a
    1D maximum filter, shifted along z and y and OR-ed (exact; much faster than a
    distance transform for a radius of a few voxels)."""
    sz, sy, sx = (float(s) for s in sampling)
    m = mask.view(np.uint8)
    near = np.zeros(mask.shape, bool)
    rows = {}  # half-width along x -> the mask dilated along x by it
    kz, ky = int(radius // sz), int(radius // sy)
    for dz in range(-kz, kz + 1):
        for dy in range(-ky, ky + 1):
            rest = radius ** 2 - (dz * sz) ** 2 - (dy * sy) ** 2
            if rest < 0:
                continue
            w = int(np.sqrt(rest) // sx)
            if w not in rows:
                rows[w] = ndimage.maximum_filter1d(m, 2 * w + 1, axis=2, mode="constant").view(bool)
            src = rows[w][max(0, -dz):mask.shape[0] - max(0, dz), max(0, -dy):mask.shape[1] - max(0, dy)]
            near[max(0, dz):mask.shape[0] - max(0, -dz) or None,
                 max(0, dy):mask.shape[1] - max(0, -dy) or None] |= src
    return near
