"""The partial-volume rules of the labelling (SPEC 7): leaves of the recursive cut without
interior elements, thin layers chopped into pieces, and mixed elements along a boundary.
They work on any element graph (triangles sharing edges, tetrahedra sharing faces)."""
import numpy as np
from numba import njit

from .graph import connected_pieces, core_bounds, neighbour_lists


def label_fragmented_layers(area, leaf, leaf_material, adjacency, nearest, in_core,
                             min_layer_area, k_modes):
    """Give a material to runs of adjacent partial-volume leaves that form a thin layer, in place.

    A thin layer between two other materials (a polymer sleeve between a steel core and an
    air gap) has no interior triangles, and the cuts between its neighbours can chop it
    into pieces too small for the thin-layer rule. Taken together, adjacent unlabelled
    leaves covering at least ``min_layer_area``, more than half of it in one material's
    core, are a layer of that material; a band of partial-volume triangles along a
    boundary spreads over the gray range between its two sides instead.
    """
    n = len(leaf_material)
    pending = leaf_material < 0
    if pending.sum() < 2:
        return
    a, b = leaf[adjacency[:, 0]], leaf[adjacency[:, 1]]
    join = (a != b) & pending[a] & pending[b]
    _, run = connected_pieces(np.column_stack([a[join], b[join]]), n)
    tri = pending[leaf]
    run_of_tri = run[leaf[tri]]
    run_area = np.bincount(run_of_tri, area[tri], n)
    core = tri & in_core
    core_mass = np.zeros((n, k_modes))
    np.add.at(core_mass, (run[leaf[core]], nearest[core]), area[core])
    best = np.argmax(core_mass, axis=1)
    layer = (run_area >= min_layer_area) & (core_mass.max(axis=1) > 0.5 * run_area)
    fix = pending & layer[run]
    leaf_material[fix] = best[run[fix]]


def label_partial_volume_leaves(f, area, leaf, leaf_material, adjacency, means, min_area=np.inf):
    """Give leaves without interior triangles a material, in place.

    A partial-volume mix lies between the grays of the materials around it and joins the
    closest of those, unless it covers ``min_area`` or more and its gray is in the core of
    a material in between (then it is that material: a mixed band is thin); anything else
    (a small pore, a speck) joins the closest level.
    """
    n = len(leaf_material)
    la = np.bincount(leaf, area, n)
    lg = np.bincount(leaf, area * f, n) / np.maximum(la, 1e-300)
    half_lo, half_hi = core_bounds(means)

    def in_core_of(g, k):
        return -half_lo[k] <= g - means[k] <= half_hi[k]

    a, b = leaf[adjacency[:, 0]], leaf[adjacency[:, 1]]
    cross = a != b
    start, dst = neighbour_lists(np.column_stack([a[cross], b[cross]]), n)
    solid = leaf_material >= 0  # labelled by interior triangles, not by this function
    pending = np.flatnonzero(~solid)
    while len(pending):
        progressed = False
        for k in pending[np.argsort(-la[pending], kind="stable")]:
            nb = dst[start[k]:start[k + 1]]
            # neighbours labelled by their own interior come first: a partial-volume leaf
            # next to another one must not copy the gray-alike label it got
            use = nb[solid[nb]] if solid[nb].any() else nb[leaf_material[nb] >= 0]
            ng = np.unique(leaf_material[use])
            if len(ng) == 0:
                continue
            lv = means[ng]
            if len(ng) >= 2 and lv.min() <= lg[k] <= lv.max():
                closest = int(np.argmin(np.abs(means - lg[k])))
                if la[k] >= min_area and in_core_of(lg[k], closest):
                    # too large to be a mixed band: a piece of the material in between
                    leaf_material[k] = closest
                else:
                    leaf_material[k] = ng[int(np.argmin(np.abs(lv - lg[k])))]
            else:
                leaf_material[k] = int(np.argmin(np.abs(means - lg[k])))
            progressed = True
        pending = np.flatnonzero(leaf_material < 0)
        if not progressed:
            leaf_material[pending] = [int(np.argmin(np.abs(means - lg[k]))) for k in pending]
            break


def partial_volume_elements(f, material, interior, adjacency, means):
    """A boundary element whose gray lies between the levels of two materials it touches
    takes the closer of the two (the material covering most of it); two sweeps.

    Parameters
    ----------
    f : (m,) array_like
        Element grays (0-255 scale).
    material : (m,) int ndarray
        Material of each element, an index into ``means``.
    interior : (m,) bool ndarray
        Elements inside a material; the others are swept.
    adjacency : (k, 2) int ndarray
    means : (K,) array_like
        Material levels.

    Returns
    -------
    material : (m,) int ndarray
        A changed copy.
    """
    mat = material.copy()
    start, dst = neighbour_lists(adjacency, len(f))
    boundary = np.flatnonzero(~interior)
    means = np.asarray(means, np.float64)
    for _ in range(2):
        if not _partial_volume_pass(np.asarray(f, np.float64), mat, boundary, start, dst, means):
            break
    return mat


# Compiled (numba): this loop over boundary triangles was 75% of the graph-cut stage.
@njit(cache=True)
def _partial_volume_pass(f, mat, boundary, start, dst, means):
    """One in-place sweep of the rule above, in triangle order; True if a label changed.
    Ties go to the lower material number."""
    changed = False
    for t in boundary:
        own = mat[t]
        lo = means[own]
        hi = means[own]
        for e in range(start[t], start[t + 1]):
            lo = min(lo, means[mat[dst[e]]])
            hi = max(hi, means[mat[dst[e]]])
        if lo == hi or not (lo <= f[t] <= hi):
            continue  # one material around, or the gray outside their levels
        best = own
        for e in range(start[t] - 1, start[t + 1]):
            k = own if e < start[t] else mat[dst[e]]
            d = abs(means[k] - f[t])
            db = abs(means[best] - f[t])
            if d < db or (d == db and k < best):
                best = k
        if best != own:
            mat[t] = best
            changed = True
    return changed


def claim_missing_levels(f, material, levels, adjacency):
    """Give every level that no element holds the elements leaning most toward it.

    Where the user fixed the number of materials, a material thinner
    than the elements (a one-voxel sheet, a wire) has no element of its own gray: each of
    its elements averages it with a neighbour. An element's lean toward a missing level k
    is how far its gray has moved from its own level toward k,
    ``(f - level[own]) / (level[k] - level[own])`` (0 at its own level, 1 at k's). The
    element leaning most, and the elements leaning at least half as much connected to it
    through such elements, take k, save the least leaning element of a level they would
    empty; levels are claimed in order of their best lean.

    Parameters
    ----------
    f : (m,) array_like
        Element grays, in the units of ``levels``.
    material : (m,) int array_like
        Each element's level index.
    levels : (K,) array_like, ascending
    adjacency : (a, 2) int array_like
        Elements sharing an edge (2D) or a face (3D).

    Returns
    -------
    material : (m,) int64 ndarray
        Every level index 0..K-1 held by at least one element (when there are K elements).

    Example
    -------
    >>> claim_missing_levels([0, 10, 130, 100], [0, 0, 1, 1], [0, 100, 200],
    ...                      [[0, 1], [1, 2], [2, 3]]).tolist()
    [0, 0, 2, 1]
    """
    f = np.asarray(f, float)
    material = np.asarray(material, np.int64).copy()
    levels = np.asarray(levels, float)
    adjacency = np.asarray(adjacency, np.int64).reshape(-1, 2)
    a, b = adjacency[:, 0], adjacency[:, 1]
    for _ in range(len(levels)):  # each pass gives one missing level its elements
        count = np.bincount(material, minlength=len(levels))
        missing = np.flatnonzero(count == 0)
        if len(missing) == 0 or len(f) <= np.count_nonzero(count):
            break
        own = levels[material]
        span = levels[missing][:, None] - own[None, :]  # never 0: own levels are held
        lean = np.where(count[material] > 1, (f - own) / span, -np.inf)  # no level emptied
        row = int(np.argmax(lean.max(axis=1)))
        best = int(np.argmax(lean[row]))
        near = (lean[row] >= 0.5 * lean[row, best]) if lean[row, best] > 0 else (np.arange(len(f)) == best)
        near &= count[material] > 1
        keep = near[a] & near[b]
        _, piece = connected_pieces(np.column_stack([a[keep], b[keep]]), len(f))
        take = near & (piece == piece[best])
        for lev in np.unique(material[take]):  # each level keeps its least leaning element
            members = np.flatnonzero(material == lev)
            if take[members].all():
                take[members[np.argmin(lean[row, members])]] = False
        material[take] = missing[row]
    return material


PIECE_OWN_SHARE = 0.3
"""A piece with interior elements whose voxels give its own material less than this share
of their votes is a mix all the same (:func:`relabel_partial_volume_pieces`)."""


def relabel_partial_volume_pieces(f, material, levels, adjacency, size, interior,
                                  max_size=np.inf, own_share=None, max_rounds=4):
    """Pieces of a material between a darker and a brighter one, made of boundary
    elements only, take the darkest or brightest material they touch.

    A piece is a connected set of elements of one material. One that has no interior
    element, touches both a material of a lower level and one of a higher level, and is
    smaller than ``max_size`` is a partial-volume mix of its neighbours, not a material
    of its own: air and aluminium average to polymer along a housing's surface, and the
    blur halo of steel in air reads as aluminium. A mix is made of its extremes (the blur
    between two materials gives every gray between them), so it takes the darkest or the
    brightest material it touches, whichever level is nearer its size-weighted mean gray:
    never another material in between, which would only be a mix again. A piece of
    ``max_size`` or more is a thin layer (the recursive cut's thin-layer rule decides
    those); where no element is interior, nothing is relabelled. With ``own_share``, a
    piece that holds interior elements is a mix too when its elements' voxels give its
    own material less than :data:`PIECE_OWN_SHARE` of their votes (size-weighted): next
    to a far denser material the flat test calls elements of a blurred edge interior.

    Parameters
    ----------
    f : (m,) array_like
        Element grays, in the units of ``levels``.
    material : (m,) int array_like
        Each element's level index.
    levels : (K,) array_like, ascending
    adjacency : (a, 2) int array_like
        Elements sharing an edge (2D) or a face (3D).
    size : (m,) array_like
        Element areas or volumes.
    interior : (m,) bool array_like
        Elements inside a material (away from its edges).
    max_size : float
        Pieces this large or larger are kept.
    own_share : callable, optional
        ``own_share(elements, material)``: for each of those element indices, the share of
        its voxels' votes for its material in ``material``
        (:func:`ctseg.mixed_tetra.own_vote_share`).
    max_rounds : int
        Passes over the pieces as the previous pass left them, until nothing moves: a
        polymer piece between air and aluminium that becomes aluminium while its aluminium
        neighbour, between it and steel, becomes steel is a new mix of air and steel.

    Returns
    -------
    material : (m,) int64 ndarray
    changed : int
        Pieces relabelled, over all passes.

    Example
    -------
    >>> # a middle-gray piece of two elements between a dark and a bright one
    >>> relabel_partial_volume_pieces([0, 40, 45, 100, 100], [0, 1, 1, 2, 2], [0, 50, 100],
    ...                               [[0, 1], [1, 2], [2, 3], [3, 4]], [1, 1, 1, 1, 1],
    ...                               [True, False, False, False, True])[0].tolist()
    [0, 0, 0, 2, 2]
    """
    f = np.asarray(f, float)
    mat = np.asarray(material, np.int64).copy()
    level = np.asarray(levels, float)
    adj = np.asarray(adjacency, np.int64).reshape(-1, 2)
    size = np.asarray(size, float)
    interior = np.asarray(interior, bool)
    if len(level) < 3 or len(adj) == 0 or not interior.any():
        return mat, 0
    total = 0
    for _ in range(max_rounds):  # a flip can make a new mix: air | polymer | aluminium | steel
        mat, changed = _pieces_round(f, mat, level, adj, size, interior, max_size, own_share)
        total += changed
        if not changed:
            break
    return mat, total


def _pieces_round(f, mat, level, adj, size, interior, max_size, own_share):
    """One pass of :func:`relabel_partial_volume_pieces` over the pieces as they are (``mat``
    relabelled in place)."""
    a, b = adj[:, 0], adj[:, 1]
    same = mat[a] == mat[b]
    n_pieces, piece = connected_pieces(np.column_stack([a[same], b[same]]), len(mat))
    piece_size = np.bincount(piece, size, n_pieces)
    piece_gray = np.bincount(piece, size * f, n_pieces) / np.maximum(piece_size, 1e-300)
    has_interior = np.bincount(piece, interior, n_pieces) > 0
    piece_mat = np.empty(n_pieces, np.int64)
    piece_mat[piece] = mat
    touches = np.zeros((n_pieces, len(level)), bool)
    for i, j in ((a[~same], b[~same]), (b[~same], a[~same])):
        touches[piece[i], mat[j]] = True
    idx = np.arange(len(level))
    darkest = np.where(touches, idx, len(level)).min(axis=1)
    brightest = np.where(touches, idx, -1).max(axis=1)
    between = (darkest < piece_mat) & (brightest > piece_mat)
    dark, bright = np.minimum(darkest, len(level) - 1), np.maximum(brightest, 0)
    nearest = np.where(piece_gray - level[dark] <= level[bright] - piece_gray, dark, bright)
    flip = between & (piece_size < max_size)
    mixed = ~has_interior
    asked = flip & has_interior
    if own_share is not None and asked.any():
        el = np.flatnonzero(asked[piece])
        share = np.bincount(piece[el], size[el] * own_share(el, mat), n_pieces)
        mixed |= asked & (share < PIECE_OWN_SHARE * piece_size)
    flip &= mixed
    mat[flip[piece]] = nearest[piece[flip[piece]]]
    return mat, int(flip.sum())
