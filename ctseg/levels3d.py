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

A thin low-contrast layer (a polymer coating 3-4 voxels thick, a few noise units above
air) leaves no mode in either histogram: its voxels and its tetrahedra drown in the
partial-volume continuum between air and aluminium, which is as bright. The tetrahedra
that hold one material do not: their voxels spread as the noise, while a tetrahedron
across a blurred edge spreads as the contrast. A mode of the grays of the homogeneous
tetrahedra (voxels spreading less than :data:`HOMOGENEOUS_SPREAD` voxel-noise units) that
lies between two levels and that no level explains (farther from each than the merge
rules' separation) is a material of its own, and is added.

A small dense insert leaves too few flat voxels for a level, and under 0.5% of the voxels
it escapes the tail rule of the volume's levels too. Its tetrahedra show it: a
mode of the tetrahedron grays above the highest level, farther than the separation, is
a denser material (:func:`denser_levels`), since partial volume only mixes the materials
the levels already hold. The separation is taken in the smaller of the flat voxels' and
the tetrahedra's spreads: thin struts (a stent's, 1-2 voxels across) mix into many
tetrahedra and widen theirs, as partial-volume voxels widen the flat voxels' spread.
Below the lowest level no such rule applies: a dark band next to a dense part, an
artefact, would make one.
"""
import numpy as np

from .levels import dominant_spread, material_modes
from .params import AUTO, resolve

FLAT_TO_ELEMENT_SPREAD = 2.0
"""Flat voxels spreading more than this many times the tetrahedra's grays (in the dominant
material) count as holding partial-volume voxels."""


HOMOGENEOUS_SPREAD = 1.5
"""Tetrahedra whose voxels spread less than this many voxel-noise units count as holding
one material (the homogeneous tetrahedra)."""

HOMOGENEOUS_MIN_FRACTION = 3e-3
"""A level of the homogeneous tetrahedra holds at least this share of the whole mesh's
volume. A few flat tetrahedra lying along a blurred edge read its half-way gray with
little spread: on a granular phantom (48^3, 614 sites) six of them, 0.09% of the volume,
made a mode; the 3.5-voxel polymer layer of a 96^3 part holds 0.8%."""


def tetra_levels(gray_255, volume, params=None, min_volume=None):
    """Material levels from the tetrahedra: modes of the volume-weighted histogram of
    their grays, merged by the rules of :func:`ctseg.levels.pixel_material_levels`
    (``merge_k`` times the dominant material's spread plus ``merge_rel`` of the gray, or
    ``merge_threshold_255``; at least ``min_volume`` per level, default
    ``level_min_fraction`` of their volume).

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
    min_volume = p.level_min_fraction * w.sum() if min_volume is None else float(min_volume)
    levels, _ = material_modes(f, w, max(sigma, 0.5), min_volume, separation)
    return levels, float(sigma)


def homogeneous_levels(gray_255, volume, spread_255, noise_255, params=None):
    """The levels of the homogeneous tetrahedra (see the module's docstring):
    :func:`tetra_levels` of the tetrahedra whose voxels spread less than
    :data:`HOMOGENEOUS_SPREAD` times ``noise_255``, each holding at least
    :data:`HOMOGENEOUS_MIN_FRACTION` of the whole ``volume``.

    Parameters
    ----------
    gray_255, volume : (m,) array_like
        Tetrahedron grays (0-255 scale) and volumes.
    spread_255 : (m,) array_like
        Standard deviation of each tetrahedron's voxels (overlap-weighted, 0-255 scale:
        :func:`ctseg.mixed_tetra.tetra_spread`).
    noise_255 : float
        Noise of one voxel (:func:`ctseg.mixed_tetra.voxel_noise`).
    params : ctseg.params.SegmentParams, optional

    Returns
    -------
    levels_255 : (h,) ndarray
        Ascending; empty with fewer than two homogeneous tetrahedra.
    sigma_255 : float
        The spread of the dominant material's homogeneous tetrahedron grays.

    Example
    -------
    >>> rng = np.random.default_rng(2)  # air, its blurred edge to aluminium, a polymer, aluminium
    >>> gray = np.concatenate([rng.normal(20, 1, 500), rng.uniform(20, 80, 400),
    ...                        rng.normal(45, 1, 40), rng.normal(80, 1, 300)])
    >>> spread = np.concatenate([np.full(500, 5.0), np.full(400, 20.0), np.full(340, 5.0)])
    >>> levels, _ = homogeneous_levels(gray, np.ones(1240), spread, 5.0)
    >>> np.round(levels).tolist()
    [20.0, 45.0, 80.0]
    """
    sel = np.asarray(spread_255, float) < HOMOGENEOUS_SPREAD * float(noise_255)
    if sel.sum() < 2:
        return np.zeros(0), 0.0
    w = np.asarray(volume, float)
    return tetra_levels(np.asarray(gray_255, float)[sel], w[sel], params,
                        HOMOGENEOUS_MIN_FRACTION * w.sum())


def hidden_levels(candidates_255, sigma_255, levels_255, params=None):
    """The candidate levels a partial-volume continuum can hide: between the lowest and
    the highest level of ``levels_255``, and farther from each than the merge rules'
    separation (``merge_k`` times ``sigma_255`` plus ``merge_rel`` of the gray, at least
    ``merge_floor_255``). Beyond the outermost levels no continuum hides a material
    (there a dark band next to a dense part, an artefact, would make one).

    Example
    -------
    >>> hidden_levels([5.0, 20.0, 45.0, 84.0], 1.0, [20.0, 80.0]).tolist()
    [45.0]
    """
    p = resolve(params)
    found = np.asarray(candidates_255, float)
    level = np.asarray(levels_255, float)
    if len(level) < 2:
        return found[:0]
    separation = np.maximum(p.merge_floor_255, p.merge_k * sigma_255 + p.merge_rel * found)
    far = np.abs(found[:, None] - level[None, :]).min(axis=1) > separation
    return found[far & (found > level.min()) & (found < level.max())]


def denser_levels(modes_255, sigma_255, levels_255, params=None):
    """The tetrahedron-gray modes above the highest level by more than the merge rules'
    separation (``merge_k`` times ``sigma_255`` plus ``merge_rel`` of the mode, at least
    ``merge_floor_255``): a material denser than every flat voxel showed (a thin steel
    rod in aluminium, too small for a level of its own among the flat voxels). Partial
    volume mixes materials, so no tetrahedron of known materials reads above the highest.

    Example
    -------
    >>> denser_levels([11.0, 95.0, 252.0], 1.0, [11.0, 96.0]).tolist()
    [252.0]
    """
    p = resolve(params)
    modes = np.asarray(modes_255, float)
    level = np.asarray(levels_255, float)
    if len(level) == 0:
        return modes[:0]
    separation = np.maximum(p.merge_floor_255, p.merge_k * sigma_255) + p.merge_rel * modes
    return modes[modes > level.max() + separation]


def checked_levels(levels_255, flat_sigma_255, gray_255, volume, params=None, spread_255=None,
                   noise_255=None):
    """The flat voxels' levels, or the tetrahedra's where the flat voxels hold partial
    volume, with the levels the homogeneous tetrahedra add (see the module's docstring;
    only with ``spread_255`` and ``noise_255``). A given ``n_materials`` keeps the count
    of the flat voxels' levels, which honour it: with hidden levels (:func:`hidden_levels`)
    the levels are the lowest and the highest of the count's (a clipped end is a material
    of its own) and, of the others and the hidden ones, those that hold the most
    tetrahedron volume, each tetrahedron counted at its nearest level (a level the count
    forced out of a partial-volume bump gives way to the hidden material). With
    ``n_materials`` 'auto', a tetrahedron mode above the highest level is added
    (:func:`denser_levels`), its separation from the smaller of the two spreads: partial
    volume widens one or the other, never the noise of both.

    Returns
    -------
    levels_255 : (K,) ndarray
    report : dict
        ``method`` ('given', 'flat_voxels', 'tetrahedra' or 'homogeneous_tetrahedra'),
        both spreads and both level sets; ``homogeneous_levels_255`` and
        ``homogeneous_added_255``, the homogeneous tetrahedra's levels and those added;
        ``denser_added_255``, the levels :func:`denser_levels` added.

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
    homogeneous = spread_255 is not None and noise_255 is not None and len(gray_255) > 0
    if homogeneous:
        found, h_sigma = homogeneous_levels(gray_255, volume, spread_255, noise_255, p)
        report.update(homogeneous_levels_255=[float(v) for v in found], homogeneous_added_255=[])
    if p.n_materials != AUTO or len(gray_255) == 0:
        hidden = hidden_levels(found, h_sigma, levels_255, p) if homogeneous else []
        if len(hidden):  # the K of both that hold the most volume, each tetrahedron at its nearest
            both = np.sort(np.concatenate([levels_255, hidden]))
            nearest = np.abs(np.asarray(gray_255, float)[:, None] - both[None, :]).argmin(axis=1)
            held = np.bincount(nearest, weights=np.asarray(volume, float), minlength=len(both))
            held[[0, -1]] = np.inf  # the outermost stay: a clipped end is a material of its own
            kept = both[np.sort(np.argsort(-held, kind="stable")[:len(levels_255)])]
            if not np.array_equal(kept, levels_255):
                report.update(method="homogeneous_tetrahedra", homogeneous_added_255=[
                    float(v) for v in np.setdiff1d(kept, levels_255)])
                levels_255 = kept
        return levels_255, report
    t_levels, t_sigma = tetra_levels(gray_255, volume, p)
    report.update(tetra_sigma_255=t_sigma, tetra_levels_255=[float(v) for v in t_levels])
    if flat_sigma_255 > FLAT_TO_ELEMENT_SPREAD * t_sigma and len(t_levels) > len(levels_255):
        report["method"] = "tetrahedra"
        levels_255 = np.asarray(t_levels, float)
    if homogeneous:  # added to the levels chosen (the same rule against either set)
        added = hidden_levels(found, h_sigma, levels_255, p)
        report["homogeneous_added_255"] = [float(v) for v in added]
        levels_255 = np.sort(np.concatenate([levels_255, added]))
    # the smaller spread is the noise: the larger one holds partial volume (the flat voxels'
    # in a small volume, the tetrahedra's in a scan whose thin struts mix into them)
    denser = denser_levels(t_levels, min(t_sigma, flat_sigma_255), levels_255, p)
    report["denser_added_255"] = [float(v) for v in denser]
    return np.concatenate([levels_255, denser]), report
