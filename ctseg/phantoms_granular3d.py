"""A synthetic granular volume with known truth (benchmarks, tests): packed balls.

Balls of random radius (``radius_vox``) at uniformly random centres, overlapping where
they meet, are added until they fill ``fill`` of the volume; painted at ``supersample``
sub-voxels per voxel side. The image is the ball fraction of each voxel (partial volume)
at gray 1 in air at 0, blurred by a Gaussian (the scanner's point spread), plus Gaussian
noise; the truth is the per-voxel majority of the sub-voxels. The air gaps between balls
are 0 to a few voxels wide, as in snow, sand or sintered powder. Deterministic for a
given ``seed``.
"""
from dataclasses import dataclass

import numpy as np
from scipy import ndimage


@dataclass
class GranularVolume:
    """image (n, n, n) float32; truth (n, n, n) uint8 (0 air, 1 grain); ``fraction``: each
    voxel's grain fraction."""

    image: np.ndarray
    truth: np.ndarray
    fraction: np.ndarray


def make_granular_3d(size, seed, fill=0.55, radius_vox=(2.5, 4.0), blur_vox=0.9,
                     noise=0.05, supersample=2, max_balls=20000):
    """Packed balls in air with their voxel truth (see the module docstring).

    Parameters
    ----------
    size : int
        Voxels per side.
    seed : int
    fill : float
        Grain volume fraction to reach (of the supersampled grid).
    radius_vox : (float, float)
        Range of the balls' radii, voxels (uniform).
    blur_vox, noise : float
        Gaussian blur sd (voxels) and noise sd (grain gray 1).
    supersample : int
    max_balls : int

    Returns
    -------
    GranularVolume

    Example
    -------
    >>> g = make_granular_3d(16, seed=1)
    >>> g.image.shape, g.truth.dtype.name, bool(0.4 < g.truth.mean() < 0.7)
    ((16, 16, 16), 'uint8', True)
    """
    rng = np.random.default_rng(seed)
    big = int(size) * int(supersample)
    axis = (np.arange(big) + 0.5) / supersample - 0.5
    grains = np.zeros((big,) * 3, bool)
    for _ in range(max_balls):
        if grains.mean() >= fill:
            break
        c = rng.uniform(0, size, 3)
        r = rng.uniform(*radius_vox)
        lo = [max(0, int((c[a] - r + 0.5) * supersample) - 1) for a in range(3)]
        hi = [min(big, int((c[a] + r + 0.5) * supersample) + 2) for a in range(3)]
        z, y, x = np.ix_(axis[lo[0]:hi[0]], axis[lo[1]:hi[1]], axis[lo[2]:hi[2]])
        ball = (z - c[0]) ** 2 + (y - c[1]) ** 2 + (x - c[2]) ** 2 < r * r
        grains[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] |= ball
    s = int(supersample)
    frac = grains.reshape(size, s, size, s, size, s).mean(axis=(1, 3, 5))
    image = ndimage.gaussian_filter(frac, blur_vox) + rng.normal(0.0, noise, frac.shape)
    return GranularVolume(image=image.astype(np.float32), truth=(frac >= 0.5).astype(np.uint8),
                          fraction=frac)
