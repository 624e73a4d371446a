"""Mixed tetrahedra in the 3D labelling (and, last, :func:`relabel_beyond_iso50`): an
element that straddles a boundary between two materials averages them, and that average
can be the gray of a third material (a tetrahedron half aluminium, half air reads as
polymer). Its voxels tell: each voxel votes for the material whose gray level is nearest
its own, or, inside a transition between a lower and a higher material, for the nearer of
those two (:func:`transition_votes`: the blur's voxels read as the middle material too),
and a tetrahedron whose own material gets less than :data:`MIXED_OWN_SHARE` of its
volume while one material gets at least :data:`MIXED_WIN_SHARE` takes that material, if a face
neighbour has it and it is the lowest or the highest of those holding at least
:data:`MIXED_MIN_SHARE` of the votes: the blur between two materials gives voxels of
every gray between them, so a mixture is made of its extremes (the blur tail of steel
next to air reads as aluminium, and must not make aluminium).

Only tetrahedra whose voxels spread more than :data:`MIXED_NOISE_SPREAD` noise units are
asked (the others hold one material and its noise), so the voxel overlaps are computed
for a few of them (from overlaps kept for all, :class:`ctseg.tetra_gray.VoxelOverlaps`).
"""
import numpy as np

from .tetra_gray import VoxelOverlaps

MIXED_OWN_SHARE = 0.3
"""A tetrahedron whose own material gets less than this share of its voxels' votes is
relabelled (when another gets at least half)."""

MIXED_WIN_SHARE = 0.5
"""The material a relabelled tetrahedron takes holds at least this share of the votes."""

MIXED_MIN_SHARE = 0.1
"""Materials with less than this share of a tetrahedron's votes do not count among its
constituents."""

MIXED_NOISE_SPREAD = 3.0
"""Tetrahedra whose voxels spread more than this many voxel-noise units are asked."""


def voxel_noise(volume):
    """Robust noise scale of a volume: the median absolute deviation of differences of
    neighbouring voxels along each axis, as :func:`ctseg.intensity.estimate_noise` in 2D."""
    v = np.asarray(volume, float)
    # the differences written into one buffer and the medians taken in place: a median
    # needs no order, and the copies cost more than the medians (256^3)
    d = np.empty(sum(v.size - v.size // n for n in v.shape))
    pos = 0
    for a, n in enumerate(v.shape):
        lo, hi = (v[(slice(None),) * a + (s,)] for s in (slice(None, -1), slice(1, None)))
        np.subtract(hi, lo, out=d[pos:pos + lo.size].reshape(lo.shape))
        pos += lo.size
    centre = np.median(d, overwrite_input=True)
    np.abs(np.subtract(d, centre, out=d), out=d)
    return float(1.4826 * np.median(d, overwrite_input=True) / np.sqrt(2.0))


def tetra_spread(volume_255, overlaps, mean_255=None):
    """Standard deviation of each tetrahedron's voxels (overlap-weighted) and the volume's
    voxel noise (:func:`voxel_noise`).

    Parameters
    ----------
    volume_255 : (nz, ny, nx) array_like
    overlaps : ctseg.tetra_gray.VoxelOverlaps
        The mesh's voxel overlaps on the volume's shape.
    mean_255 : (m,) array_like, optional
        Each tetrahedron's mean of ``volume_255``, if known already.

    Returns
    -------
    spread : (m,) ndarray
    noise : float

    Example
    -------
    >>> from ctseg.tetrahedra import delaunay_tetrahedra
    >>> cube = delaunay_tetrahedra(np.array([[x, y, z] for x in (0, 3) for y in (0, 3)
    ...                                      for z in (0, 3)], float), (3, 3, 3))
    >>> vol = np.zeros((4, 4, 4)); vol[:, :, 2:] = 100.0
    >>> spread, noise = tetra_spread(vol, VoxelOverlaps(cube.points, cube.tetrahedra, vol.shape))
    >>> sorted(np.round(spread, 1).tolist()), noise  # each holds voxels of 0 and 100; no noise
    ([33.1, 33.1, 33.1, 33.1, 50.0, 50.0], 0.0)
    """
    vol = np.asarray(volume_255, float)
    mean = overlaps.tetra_mean(vol) if mean_255 is None else np.asarray(mean_255, float)
    spread = np.sqrt(np.maximum(overlaps.tetra_mean(vol * vol) - mean ** 2, 0.0))
    return spread, voxel_noise(vol)


TRANSITION_STEP_VOX = 1.5
"""How far along its gradient, each way, :func:`transition_votes` looks from a voxel."""


def _nearest_level(values, level):
    """Index of the level nearest each value."""
    return np.argmin(np.abs(np.asarray(values)[:, None] - level[None, :]), axis=1)


def _index_gradient(vol, idx):
    """Gradient (index units, order z, y, x) of ``vol`` at the flat indices ``idx``: the
    central difference along each axis averaged over the 3 x 3 voxels across it, which
    keeps its direction steady under noise."""
    shape = np.array(vol.shape)
    zyx = np.stack(np.unravel_index(idx, vol.shape), axis=1)
    flat = vol.ravel()
    grad = np.zeros((len(idx), 3))
    offsets = [(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1)]
    for axis in range(3):
        across = [ax for ax in range(3) if ax != axis]
        for a, b in offsets:
            for sign in (-1, 1):
                q = zyx.copy()
                q[:, axis] += sign
                q[:, across[0]] += a
                q[:, across[1]] += b
                q = np.clip(q, 0, shape - 1)
                grad[:, axis] += sign * flat[np.ravel_multi_index(q.T, vol.shape)]
    return grad / 18.0


def transition_votes(volume_255, voxel, level_255, vote):
    """Votes of the voxels inside a transition between two materials that read as a third
    in between: such a voxel votes for the nearer of the two (by the half-way gray between
    them), not for the level its gray happens to be nearest.

    A voxel voting for an intermediate level b is inside a transition when the volume
    :data:`TRANSITION_STEP_VOX` voxels down its gradient is nearest a level below b and
    as far up it nearest a level above b: the blur of a step between air and aluminium
    passes through the polymer's gray, but a polymer region is polymer that far in.

    Parameters
    ----------
    volume_255 : (nz, ny, nx) float ndarray
    voxel : (r,) int ndarray, flat indices into the volume
    level_255 : (K,) float ndarray, ascending
    vote : (r,) int ndarray, each voxel's nearest level

    Returns
    -------
    (r,) int64 ndarray, the votes

    Notes
    -----
    A layer of the middle material thinner than about twice the step reads as a
    transition too (its elements then go by their share of votes, as before).

    Example
    -------
    >>> from scipy.ndimage import gaussian_filter
    >>> vol = np.zeros((5, 5, 10)); vol[:, :, 5:] = 100.0
    >>> vol = gaussian_filter(vol, 0.8)  # x = 4, 5 read 25.1 and 74.9: nearest 50
    >>> voxel = np.ravel_multi_index((2, 2, 4), vol.shape) + np.arange(2)
    >>> transition_votes(vol, voxel, np.array([0.0, 50.0, 100.0]), np.array([1, 1])).tolist()
    [0, 2]
    """
    from scipy.ndimage import map_coordinates

    level = np.asarray(level_255, float)
    vote = np.asarray(vote, np.int64).copy()
    ask = np.flatnonzero((vote > 0) & (vote < len(level) - 1))
    if not len(ask):
        return vote
    idx, inverse = np.unique(voxel[ask], return_inverse=True)
    grad = _index_gradient(volume_255, idx)
    norm = np.linalg.norm(grad, axis=1)
    unit = grad / np.maximum(norm, 1e-12)[:, None]
    zyx = np.stack(np.unravel_index(idx, volume_255.shape), axis=1).astype(float)
    step = TRANSITION_STEP_VOX * unit
    lo, hi = (map_coordinates(volume_255, (zyx + sgn * step).T, order=1, mode="nearest")
              for sgn in (-1.0, 1.0))
    lo_level, hi_level = _nearest_level(lo, level), _nearest_level(hi, level)
    own = volume_255.ravel()[idx]
    b = vote[ask]
    lo_level, hi_level, own = lo_level[inverse], hi_level[inverse], own[inverse]
    inside = (norm[inverse] > 0) & (lo_level < b) & (hi_level > b)
    half = 0.5 * (level[lo_level] + level[hi_level])
    vote[ask[inside]] = np.where(own[inside] < half[inside], lo_level[inside], hi_level[inside])
    return vote


def _vote_shares(vol, overlaps, which, level):
    """(len(which), K): each tetrahedron's share of its voxels' votes for each level."""
    tet, voxel, overlap = overlaps.rows(which)
    vote = transition_votes(vol, voxel, level, _nearest_level(vol.ravel()[voxel], level))
    votes = np.zeros((len(which), len(level)))
    np.add.at(votes, (tet, vote), overlap)
    return votes / np.maximum(votes.sum(axis=1, keepdims=True), 1e-300)


def own_vote_share(volume_255, overlaps, material, level_255, which):
    """Share of each tetrahedron's voxels' votes (as :func:`relabel_mixed` counts them)
    that goes to its own material.

    Parameters
    ----------
    volume_255 : (nz, ny, nx) array_like
    overlaps : ctseg.tetra_gray.VoxelOverlaps
    material : (m,) int array_like, index into ``level_255``
    level_255 : (K,) array_like, ascending
    which : (r,) int array_like, the tetrahedra asked

    Returns
    -------
    (r,) ndarray

    Example
    -------
    >>> from ctseg.tetrahedra import delaunay_tetrahedra
    >>> box = np.array([[x, y, z] for x in (0, 5) for y in (0, 5) for z in (0, 5)], float)
    >>> mesh = delaunay_tetrahedra(box, (5, 5, 5))
    >>> ov = VoxelOverlaps(mesh.points, mesh.tetrahedra, (6, 6, 6))
    >>> levels = [0.0, 100.0]  # every voxel reads 100: no votes for level 0
    >>> own_vote_share(np.full((6, 6, 6), 100.0), ov, np.zeros(6, int), levels, [0, 5]).tolist()
    [0.0, 0.0]
    """
    vol = np.asarray(volume_255, float)
    which = np.asarray(which, np.int64)
    share = _vote_shares(vol, overlaps, which, np.asarray(level_255, float))
    return share[np.arange(len(which)), np.asarray(material, np.int64)[which]]


def relabel_mixed(volume_255, points, tetrahedra, material, level_255, spacing=(1.0, 1.0, 1.0),
                  mean_255=None, adjacency=None, overlaps=None, spread=None):
    """Relabel the mixed tetrahedra by their voxels' votes (see the module's docstring).

    Parameters
    ----------
    volume_255 : (nz, ny, nx) array_like
        The volume on the 0-255 scale of the levels.
    points : (n, 3) float ndarray
        Physical coordinates of the box, (x, y, z) = (i, j, k) x spacing.
    tetrahedra : (m, 4) int ndarray
    material : (m,) int ndarray
        Index into ``level_255`` of each tetrahedron's material.
    level_255 : (K,) array_like
        Each material's gray level.
    spacing : (3,) floats
    adjacency : (a, 2) int array_like, optional
        Tetrahedra sharing a face: a tetrahedron then takes only a material one of its
        neighbours has (a flip never makes two materials touch that did not).
    mean_255 : (m,) array_like, optional
        Each tetrahedron's mean of ``volume_255`` (:func:`ctseg.tetra_gray.tetra_gray`), if
        known already.
    overlaps : ctseg.tetra_gray.VoxelOverlaps, optional
        The mesh's voxel overlaps, if computed already.
    spread : (spread_255, noise_255), optional
        :func:`tetra_spread` of the volume, if computed already.

    Returns
    -------
    material : (m,) int64 ndarray
    changed : int
        Tetrahedra relabelled.

    Example
    -------
    >>> from ctseg.tetrahedra import delaunay_tetrahedra
    >>> vol = np.zeros((4, 4, 4)); vol[:, :, 2:] = 100.0
    >>> cube = delaunay_tetrahedra(np.array([[x, y, z] for x in (0, 3) for y in (0, 3)
    ...                                      for z in (0, 3)], float), (3, 3, 3))
    >>> mat = np.full(len(cube.tetrahedra), 1)  # all read as the middle level's
    >>> new, changed = relabel_mixed(vol, cube.points, cube.tetrahedra, mat, [0, 50, 100])
    >>> changed == len(mat), sorted(set(new.tolist()))
    (True, [0, 2])
    """
    vol = np.asarray(volume_255, float)
    material = np.asarray(material, np.int64).copy()
    level = np.asarray(level_255, float)
    if len(level) < 2 or len(material) == 0:
        return material, 0
    if overlaps is None:
        overlaps = VoxelOverlaps(points, tetrahedra, vol.shape, spacing)
    spread, noise = tetra_spread(vol, overlaps, mean_255) if spread is None else spread
    asked = np.flatnonzero(spread > MIXED_NOISE_SPREAD * noise)
    if not len(asked):
        return material, 0
    share = _vote_shares(vol, overlaps, asked, level)
    own = share[np.arange(len(asked)), material[asked]]
    winner = np.argmax(share, axis=1)
    present = share >= MIXED_MIN_SHARE
    idx = np.arange(len(level))
    lowest = np.where(present, idx, len(level)).min(axis=1)
    highest = np.where(present, idx, -1).max(axis=1)
    flip = ((own < MIXED_OWN_SHARE) & (share[np.arange(len(asked)), winner] >= MIXED_WIN_SHARE)
            & ((winner == lowest) | (winner == highest)))
    if adjacency is not None:
        adj = np.asarray(adjacency, np.int64).reshape(-1, 2)
        where = np.full(len(material), -1)
        where[asked] = np.arange(len(asked))
        has = np.zeros((len(asked), len(level)), bool)
        for a, b in ((adj[:, 0], adj[:, 1]), (adj[:, 1], adj[:, 0])):
            hit = where[a] >= 0
            has[where[a[hit]], material[b[hit]]] = True
        flip &= has[np.arange(len(asked)), winner]
    material[asked[flip]] = winner[flip]
    return material, int(flip.sum())


ISO50_MIN_CONTRAST = 10.0
""":func:`relabel_beyond_iso50` leaves pairs of materials whose levels are closer than this
many voxel-noise units to the graph cut: there a tetrahedron's offset from the half-way
gray is as much streak, cupping and correlated noise as partial volume (README, Method:
what the gate is worth on the sample volume)."""

def relabel_beyond_iso50(gray_255, material, level_255, adjacency, noise_255, max_rounds=8):
    """Tetrahedra whose gray lies beyond the half-way gray (ISO-50) between their material's
    level and the adjacent level of a face neighbour's material take that material.

    The graph cut's neighbour terms close narrow gaps between two materials (in 3D the
    tetrahedra along a thin air gap share many faces with the grains on either side), and
    the recursive cut's pocket rules absorb small pieces; a tetrahedron on the boundary
    whose mean gray lies beyond ISO-50 is more of the neighbour's material than of its own
    (the rule the hand reference of a two-phase scan applies, per element). No noise
    margin: beyond ISO-50 the neighbour's material is the likelier one for the element's
    mean, and a margin of 1-3 standard errors of that mean left the gaps half closed
    (README, *Granular volumes with known truth*). Only materials adjacent in level order
    are considered (a mixture of air and aluminium reads as polymer: the mixed-tetrahedron
    rule decides those), at least :data:`ISO50_MIN_CONTRAST` noise units apart, and only a
    material a face neighbour has. Repeated on the updated labels until nothing moves (at
    most ``max_rounds``), a tetrahedron moving once at most: a narrow gap reopens from its
    sides inwards, but a mixture never walks down the levels one material at a time.

    Parameters
    ----------
    gray_255 : (m,) array_like
        Tetrahedron mean gray, 0-255 scale of the levels.
    material : (m,) int array_like
        Index into ``level_255``.
    level_255 : (K,) array_like, ascending
    adjacency : (a, 2) int array_like
        Tetrahedra sharing a face.
    noise_255 : float
        Noise of one voxel (the contrast gate's unit).
    max_rounds : int

    Returns
    -------
    material : (m,) int64 ndarray
    changed : int
        Tetrahedra whose material differs from the input's.

    Example
    -------
    >>> relabel_beyond_iso50([10.0, 40.0, 90.0], [0, 1, 1], [0.0, 100.0], [[0, 1], [1, 2]],
    ...                      5.0)[0].tolist()
    [0, 0, 1]
    """
    f = np.asarray(gray_255, float)
    start = np.asarray(material, np.int64)
    mat = start.copy()
    level = np.asarray(level_255, float)
    adj = np.asarray(adjacency, np.int64).reshape(-1, 2)
    if len(level) < 2 or len(adj) == 0:
        return mat, 0
    for _ in range(max_rounds):
        new = mat.copy()
        for i, j in ((adj[:, 0], adj[:, 1]), (adj[:, 1], adj[:, 0])):
            mi, mj = mat[i], mat[j]
            mid = 0.5 * (level[mi] + level[mj])
            beyond = np.where(mj > mi, f[i] - mid, mid - f[i])
            contrast = np.abs(level[mi] - level[mj]) >= ISO50_MIN_CONTRAST * noise_255
            move = ((np.abs(mi - mj) == 1) & contrast & (beyond > 0.0)
                    & (mat[i] == start[i]))
            new[i[move]] = mj[move]
        if np.array_equal(new, mat):
            break
        mat = new
    return mat, int(np.sum(mat != start))
