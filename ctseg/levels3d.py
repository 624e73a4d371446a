"""Material levels of a volume, checked against its tetrahedra.

The levels of the 3D mode come from the flat voxels of sampled slices, as in slices mode
(:func:`ctseg.levels.volume_levels`). In a small volume a thin part is seen flat in a
slice while the gray changes across the slices (its surface runs along the slice), so
partial-volume voxels count as flat: their spread, taken as the noise, then merges
materials that differ by a few noise units. The tetrahedra tell: a flat voxel's value is
a 3 x 3 mean, a tetrahedron's gray the mean of tens of voxels, so in the dominant material
the flat voxels spread more than the tetrahedra, but not by much; when they spread more
than :data:`FLAT_TO_ELEMENT_SPREAD` times as much, the levels are taken from the modes of
the volume-weighted histogram of the tetrahedron grays instead (the paper's own rule on
triangles, in 3D: large elements fill the inside of materials).
"""
import numpy as np

from .levels import dominant_spread, material_modes
from .params import AUTO, resolve

FLAT_TO_ELEMENT_SPREAD = 2.0
"""Flat voxels spreading more than this many times the tetrahedra's grays (in the dominant
material) count as holding partial-volume voxels."""


def tetra_levels(gray_255, volume, params=None):
    """Material levels from the tetrahedra: modes of the volume-weighted histogram of
    their grays, merged by the rules of :func:`ctseg.levels.pixel_material_levels`
    (``merge_k`` times the dominant material's spread plus ``merge_rel`` of the gray, or
    ``merge_threshold_255``; at least ``level_min_fraction`` of the volume per level).

    Parameters
    ----------
    gray_255 : (m,) array_like
        Tetrahedron grays on the 0-255 scale.
    volume : (m,) array_like
        Their volumes (any unit).
    params : ctseg.params.SegmentParams, optional

    Returns
    -------
    levels_255 : (K,) ndarray, ascending
    sigma_255 : float
        The spread of the dominant material's tetrahedron grays.

    Example
    -------
    >>> rng = np.random.default_rng(0)
    >>> gray = np.concatenate([rng.normal(20, 1, 500), rng.normal(90, 1, 300)])
    >>> levels, sigma = tetra_levels(gray, np.ones(800))
    >>> np.round(levels).tolist()
    [20.0, 90.0]
    """
    p = resolve(params)
    f = np.clip(np.asarray(gray_255, float), 0.0, 255.0)
    w = np.asarray(volume, float)
    sigma = dominant_spread(f, w)
    base = max(p.merge_floor_255, p.merge_k * sigma)
    if p.merge_threshold_255 == AUTO:
        separation = lambda g: base + p.merge_rel * g  # noqa: E731
    else:
        separation = lambda g: p.merge_threshold_255  # noqa: E731
    levels, _ = material_modes(f, w, max(sigma, 0.5), p.level_min_fraction * w.sum(), separation)
    return levels, float(sigma)


def checked_levels(levels_255, flat_sigma_255, gray_255, volume, params=None):
    """The flat voxels' levels, or the tetrahedra's where the flat voxels hold partial
    volume (see the module's docstring). A given ``n_materials`` keeps the flat voxels'
    levels, which honour it.

    Returns
    -------
    levels_255 : (K,) ndarray
    report : dict
        ``method`` ('given', 'flat_voxels' or 'tetrahedra'), both spreads and both level
        sets.

    Example
    -------
    >>> rng = np.random.default_rng(1)
    >>> gray = np.concatenate([rng.normal(20, 1, 500), rng.normal(50, 1, 300)])
    >>> levels, rep = checked_levels(np.array([22.0]), 9.0, gray, np.ones(800))
    >>> rep["method"], np.round(levels).tolist()
    ('tetrahedra', [20.0, 50.0])
    """
    p = resolve(params)
    levels_255 = np.asarray(levels_255, float)
    report = {"method": "flat_voxels", "flat_sigma_255": float(flat_sigma_255),
              "flat_levels_255": [float(v) for v in levels_255]}
    if p.gray_levels != AUTO:
        report["method"] = "given"
        return levels_255, report
    if p.n_materials != AUTO or len(gray_255) == 0:
        return levels_255, report
    t_levels, t_sigma = tetra_levels(gray_255, volume, p)
    report.update(tetra_sigma_255=t_sigma, tetra_levels_255=[float(v) for v in t_levels])
    if flat_sigma_255 > FLAT_TO_ELEMENT_SPREAD * t_sigma and len(t_levels) > len(levels_255):
        report["method"] = "tetrahedra"
        return np.asarray(t_levels, float), report
    return levels_255, report
