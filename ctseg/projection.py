"""Parallel-beam projection and filtered back-projection of 2D images.

Shared by the CT simulation (:mod:`ctseg.phantoms`) and the metal-streak correction
(:mod:`ctseg.beam_hardening`). Geometry: rotation about the image centre, detector
bins one pixel wide spanning the image diagonal, angles over 180 degrees.
"""
import numpy as np
from numba import njit, prange

from . import _threads

_BAND_ROWS = 8  # rows per band of the threaded back-projection


def detector_bins(shape):
    """Number of detector bins covering an image of ``shape`` (odd, so one is central)."""
    return int(np.ceil(np.hypot(shape[0], shape[1]))) | 1


@njit(cache=True)
def _splat(rows, cols, weights, cy, cx, cos_a, sin_a, n_det, out):
    half = (n_det - 1) / 2.0
    for a in range(cos_a.shape[0]):
        ca, sa = cos_a[a], sin_a[a]
        for i in range(rows.shape[0]):
            # the pixel as four quarter-pixel points (one point per pixel aliases: its
            # projection of a solid mask ripples), each shared linearly between two bins
            w = 0.25 * weights[i]
            for dy in (-0.25, 0.25):
                for dx in (-0.25, 0.25):
                    t = (cols[i] + dx - cx) * ca + (rows[i] + dy - cy) * sa + half
                    j = int(np.floor(t))
                    f = t - j
                    if 0 <= j < n_det:
                        out[a, j] += w * (1.0 - f)
                    if 0 <= j + 1 < n_det:
                        out[a, j + 1] += w * f


def forward_project(image, angles):
    """Line integrals (pixel units) of an image along parallel rays, pixel-driven.

    Only the nonzero pixels are visited, so a sparse map (a metal mask) is cheap.

    Parameters
    ----------
    image : (rows, cols) array_like
    angles : (n_angles,) array_like
        Ray directions in radians; the detector axis is (cos a, sin a) in (x, y).

    Returns
    -------
    sinogram : (n_angles, n_det) float64 ndarray, ``n_det = detector_bins(shape)``
    """
    img = np.asarray(image, float)
    angles = np.asarray(angles, float)
    rows, cols = np.nonzero(img)
    out = np.zeros((len(angles), detector_bins(img.shape)))
    _splat(rows.astype(np.float64), cols.astype(np.float64), img[rows, cols],
           (img.shape[0] - 1) / 2.0, (img.shape[1] - 1) / 2.0,
           np.cos(angles), np.sin(angles), out.shape[1], out)
    return out


@njit(cache=True)
def _backproject_rows(proj, cos_a, sin_a, ny, nx, r0, r1, out):
    """Add the back-projection of every angle onto rows r0..r1-1 of ``out`` (angles in
    order, so a pixel's sum does not depend on how the rows are split)."""
    n_det = proj.shape[1]
    half = (n_det - 1) / 2.0
    cy, cx = (ny - 1) / 2.0, (nx - 1) / 2.0
    for a in range(cos_a.shape[0]):
        ca, sa = cos_a[a], sin_a[a]
        for r in range(r0, r1):
            base = (r - cy) * sa + half
            for c in range(nx):
                t = (c - cx) * ca + base
                j = int(np.floor(t))
                if 0 <= j and j + 1 < n_det:
                    f = t - j
                    out[r, c] += proj[a, j] * (1.0 - f) + proj[a, j + 1] * f
                elif j == n_det - 1 and t == j:
                    out[r, c] += proj[a, j]


@njit(cache=True)
def _backproject(proj, cos_a, sin_a, ny, nx, out):
    _backproject_rows(proj, cos_a, sin_a, ny, nx, 0, ny, out)


@njit(cache=True, parallel=True)
def _backproject_parallel(proj, cos_a, sin_a, ny, nx, out):
    """:func:`_backproject`, bands of rows in parallel: the same bits."""
    for b in prange((ny + _BAND_ROWS - 1) // _BAND_ROWS):
        _backproject_rows(proj, cos_a, sin_a, ny, nx, b * _BAND_ROWS,
                          min(ny, (b + 1) * _BAND_ROWS), out)


def filtered_backprojection(sinogram, angles, shape):
    """Filtered back-projection (ramp x sinc, Shepp-Logan window) onto an image of ``shape``.

    Parameters
    ----------
    sinogram : (n_angles, n_det) array_like
        Line integrals in pixel units over 180 degrees, geometry of :func:`forward_project`.
    angles : (n_angles,) array_like
    shape : (rows, cols)

    Returns
    -------
    image : (rows, cols) float64 ndarray
    """
    sino = np.asarray(sinogram, float)
    angles = np.asarray(angles, float)
    n_det = sino.shape[1]
    pad = int(2 ** np.ceil(np.log2(2 * n_det)))
    freq = np.fft.fftfreq(pad)
    filt = 2 * np.abs(freq) * np.sinc(freq)  # Shepp-Logan: ramp x sinc
    proj = np.fft.ifft(np.fft.fft(sino, pad, axis=1) * filt, axis=1).real[:, :n_det]
    rec = np.zeros((int(shape[0]), int(shape[1])))
    backproject = _threads.pick(_backproject, _backproject_parallel)
    backproject(np.ascontiguousarray(proj), np.cos(angles), np.sin(angles),
                rec.shape[0], rec.shape[1], rec)
    return rec * np.pi / (2 * len(angles))
