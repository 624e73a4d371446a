"""Sub-pixel placement of material boundaries (SPEC 10): boundary vertices moved to the
ISO-50 crossing of the gray between their two materials' levels."""
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter, map_coordinates

from .errors import InputError, ParameterError
from .params import DEFAULTS
from .recursive_cut import order_by_gray
from .triangle_gray import triangle_gray
from .triangulation import triangle_areas, triangle_edges

MIN_AREA_RATIO = 0.2
"""A move is refused when it leaves an incident triangle with less than this share of its
area (or inverts it)."""

BACKTRACK_STEPS = 4
"""A refused move is retried at half the shift, this many times."""


def material_levels_of_mesh(gray, area, material, interior, n_materials):
    """Each material's level: the area-weighted median gray of its triangles away from the
    boundary, or of all its triangles where those cover less than half its area (small
    parts: a few interior triangles there can be stray ones).

    Example
    -------
    >>> material_levels_of_mesh([1.0, 2.0, 9.0, 50.0], np.ones(4), [0, 0, 0, 1],
    ...                         [True, True, False, True], 2).tolist()
    [1.0, 50.0]
    """
    gray, area = np.asarray(gray, float), np.asarray(area, float)
    material, interior = np.asarray(material), np.asarray(interior, bool)
    levels = np.full(n_materials, np.nan)
    for k in range(n_materials):
        sel = (material == k) & interior
        if area[sel].sum() < 0.5 * area[material == k].sum():
            sel = material == k
        if sel.any():
            g, w = gray[sel], area[sel]
            o = np.argsort(g, kind="stable")
            cw = np.cumsum(w[o])
            levels[k] = g[o][np.searchsorted(cw, 0.5 * cw[-1])]
    return levels


def _vertex_materials(triangles, material, n_points):
    """Per vertex: the lowest and highest material of its triangles, and how many
    different ones (-1, -1, 0 for a vertex of no triangle)."""
    pairs = np.unique(np.column_stack([triangles.ravel(), np.repeat(material, 3)]), axis=0)
    count = np.bincount(pairs[:, 0], minlength=n_points)
    lo = np.full(n_points, -1)
    hi = np.full(n_points, -1)
    first = np.searchsorted(pairs[:, 0], np.arange(n_points))
    has = count > 0
    lo[has] = pairs[first[has], 1]
    hi[has] = pairs[first[has] + count[has] - 1, 1]
    return lo, hi, count


def place_boundary_vertices(points, triangles, material, image, levels, *,
                            max_shift_fraction=DEFAULTS.subpixel_max_shift, smooth_px=0.0,
                            step_px=0.1):
    """Move each vertex between exactly two materials to the ISO-50 crossing of the gray.

    For a vertex whose incident triangles hold exactly two materials a and b, the gray
    (smoothed by a Gaussian of ``smooth_px``, interpolated bilinearly) is sampled every
    ``step_px`` along the gradient direction through the vertex, up to
    ``max_shift_fraction`` of its shortest incident edge either way; the vertex moves to
    the crossing of ``(levels[a] + levels[b]) / 2`` nearest to it where the gray passes
    from a's side to b's. Vertices with one or three or more materials, vertices on the
    image border, and vertices with no crossing in reach stay. A move that would invert an
    incident triangle or leave it with less than :data:`MIN_AREA_RATIO` of its area is
    retried at half the shift (:data:`BACKTRACK_STEPS` times), then dropped; moves that
    are each valid but together spoil a triangle are undone until none does. The labels
    do not change.

    Parameters
    ----------
    points : (n, 2) array_like
        Vertices (x, y) = (col, row) in pixel units.
    triangles : (m, 3) int array_like
        Counter-clockwise triangles.
    material : (m,) int array_like
        Material per triangle, 0..K-1.
    image : (rows, cols) array_like
        The gray image the labels were found on.
    levels : (K,) array_like
        Each material's gray level in the image's units (NaN: its vertices stay).
    max_shift_fraction : float
        Largest move as a share of the vertex's shortest incident edge, in (0, 1).
    smooth_px : float
        Gaussian smoothing of the image before sampling (0 = none), px.
    step_px : float
        Sampling step along the gradient, px.

    Returns
    -------
    moved : (n, 2) float64 ndarray
        The vertices, boundary vertices moved.
    n_moved : int
        How many moved.

    Raises
    ------
    InputError
        Shapes that do not match.
    ParameterError
        ``max_shift_fraction`` outside (0, 1), negative ``smooth_px``, ``step_px`` <= 0.

    References
    ----------
    The ISO-50 rule of CT metrology surface determination (e.g. VDI/VDE 2630-1.2); SPEC 10.

    Example
    -------
    >>> img = np.where(np.arange(20)[None, :] < 9.7, 10.0, 90.0).repeat(20, 0)
    >>> pts = np.array([[0, 0], [19, 0], [19, 19], [0, 19], [9, 0], [9, 19], [9, 9.5]], float)
    >>> tri = np.array([[0, 4, 6], [4, 1, 6], [1, 2, 6], [2, 5, 6], [5, 3, 6], [3, 0, 6]])
    >>> mat = np.array([0, 1, 1, 1, 0, 0])
    >>> moved, n = place_boundary_vertices(pts, tri, mat, img, [10.0, 90.0], smooth_px=0)
    >>> n, round(float(moved[6, 0]), 2)
    (1, 9.5)
    """
    pts = np.asarray(points, float)
    tri = np.asarray(triangles, np.int64)
    mat = np.asarray(material, np.int64)
    img = np.asarray(image, float)
    lv = np.asarray(levels, float).ravel()
    if pts.ndim != 2 or pts.shape[1] != 2 or tri.ndim != 2 or tri.shape[1] != 3:
        raise InputError(f"points (n, 2) and triangles (m, 3) expected, got {pts.shape} and {tri.shape}")
    if mat.shape != (len(tri),) or img.ndim != 2:
        raise InputError(f"material: one per triangle ({len(tri)}) and a 2D image expected, got "
                         f"{mat.shape} and {img.shape}")
    if len(tri) and (mat.min() < 0 or mat.max() >= len(lv)):
        raise InputError(f"material: values must index levels (0..{len(lv) - 1})")
    if not 0.0 < max_shift_fraction < 1.0:
        raise ParameterError(f"max_shift_fraction: {max_shift_fraction!r} is not in (0, 1)")
    if smooth_px < 0 or step_px <= 0:
        raise ParameterError(f"smooth_px >= 0 and step_px > 0 needed, got {smooth_px!r}, {step_px!r}")
    moved = pts.copy()
    if len(tri) == 0 or len(lv) < 2:
        return moved, 0
    n = len(pts)
    vt_v, vt_t = tri.ravel(), np.repeat(np.arange(len(tri)), 3)
    lo, hi, count = _vertex_materials(tri, mat, n)
    xmin, ymin = pts.min(axis=0)
    xmax, ymax = pts.max(axis=0)
    border = (np.isclose(pts[:, 0], xmin) | np.isclose(pts[:, 0], xmax)
              | np.isclose(pts[:, 1], ymin) | np.isclose(pts[:, 1], ymax))
    cand = np.flatnonzero((count == 2) & ~border)
    cand = cand[np.isfinite(lv[lo[cand]]) & np.isfinite(lv[hi[cand]]) & (lv[lo[cand]] != lv[hi[cand]])]
    if len(cand) == 0:
        return moved, 0
    # shortest incident edge per vertex
    e = triangle_edges(tri)[0]
    elen = np.hypot(*(pts[e[:, 0]] - pts[e[:, 1]]).T)
    shortest = np.full(n, np.inf)
    np.minimum.at(shortest, e[:, 0], elen)
    np.minimum.at(shortest, e[:, 1], elen)
    smooth = gaussian_filter(img, smooth_px, mode="nearest") if smooth_px > 0 else img
    gy, gx = np.gradient(smooth)
    p = pts[cand]
    coords = [p[:, 1], p[:, 0]]
    g = np.column_stack([map_coordinates(gx, coords, order=1, mode="nearest"),
                         map_coordinates(gy, coords, order=1, mode="nearest")])
    gnorm = np.hypot(g[:, 0], g[:, 1])
    ok = gnorm > 0
    cand, p, g, gnorm = cand[ok], p[ok], g[ok], gnorm[ok]
    if len(cand) == 0:
        return moved, 0
    la, lb = lv[lo[cand]], lv[hi[cand]]
    # +direction: from a's gray towards b's
    direction = g / gnorm[:, None] * np.sign(lb - la)[:, None]
    reach = max_shift_fraction * shortest[cand]
    n_steps = int(np.ceil(reach.max() / step_px))
    s = np.linspace(-1.0, 1.0, 2 * n_steps + 1)[None, :] * reach[:, None]
    qx = p[:, 0:1] + s * direction[:, 0:1]
    qy = p[:, 1:2] + s * direction[:, 1:2]
    prof = map_coordinates(smooth, [qy.ravel(), qx.ravel()], order=1, mode="nearest").reshape(s.shape)
    f = (prof - 0.5 * (la + lb)[:, None]) * np.sign(lb - la)[:, None]
    up = (f[:, :-1] <= 0) & (f[:, 1:] > 0)
    denom = np.where(up, f[:, 1:] - f[:, :-1], 1.0)
    s_cross = s[:, :-1] + (-f[:, :-1] / denom) * (s[:, 1:] - s[:, :-1])
    s_cross = np.where(up, s_cross, np.inf)
    best = np.argmin(np.abs(s_cross), axis=1)
    shift = s_cross[np.arange(len(cand)), best]
    found = np.isfinite(shift)
    cand, direction, shift = cand[found], direction[found], shift[found]
    if len(cand) == 0:
        return moved, 0
    # each vertex alone: no incident triangle inverted or squashed, else half the shift
    area0 = triangle_areas(pts, tri)
    inc_t = vt_t[np.argsort(vt_v, kind="stable")]
    starts = np.concatenate([[0], np.cumsum(np.bincount(vt_v, minlength=n))])
    accepted = np.zeros(len(cand), bool)
    for _ in range(BACKTRACK_STEPS + 1):
        todo = np.flatnonzero(~accepted & (shift != 0))
        if len(todo) == 0:
            break
        good = _moves_valid(pts, tri, area0, inc_t, starts, cand[todo],
                            pts[cand[todo]] + shift[todo, None] * direction[todo])
        accepted[todo[good]] = True
        shift[todo[~good]] *= 0.5
    cand, new = cand[accepted], pts[cand[accepted]] + shift[accepted, None] * direction[accepted]
    moved[cand] = new
    # together: undo the moves around any triangle the combination spoils
    active = np.ones(len(cand), bool)
    for _ in range(len(cand) + 1):
        bad = triangle_areas(moved, tri) < MIN_AREA_RATIO * area0
        if not bad.any():
            break
        spoiled = np.isin(cand, np.unique(tri[bad])) & active
        if not spoiled.any():  # a triangle bad before any move: not ours to fix
            break
        moved[cand[spoiled]] = pts[cand[spoiled]]
        active &= ~spoiled
    return moved, int(active.sum())


def _moves_valid(pts, tri, area0, inc_t, starts, verts, targets):
    """For each vertex, whether moving it alone to its target keeps every incident triangle
    positively oriented with at least MIN_AREA_RATIO of its area."""
    counts = starts[verts + 1] - starts[verts]
    owner = np.repeat(np.arange(len(verts)), counts)
    offs = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    t = inc_t[starts[verts][owner] + offs]
    p = pts[tri[t]].copy()
    slot = tri[t] == verts[owner][:, None]
    p[slot] = targets[owner]
    area = triangle_areas(p.reshape(-1, 2), np.arange(3 * len(p)).reshape(-1, 3))
    ok_t = area >= MIN_AREA_RATIO * area0[t]
    return np.bincount(owner, ~ok_t, len(verts)) == 0


@dataclass
class MovedMesh:
    """A segmented mesh after :func:`subpixel_mesh`.

    Attributes
    ----------
    points : (n, 2) float64 ndarray
    gray : (m,) float64 ndarray, measured again where a vertex moved
    material : (m,) int64 ndarray
    material_gray : (K,) ndarray or None
        Each material's area-weighted mean gray, ascending (None without ``renumber``).
    n_moved : int
    """

    points: np.ndarray
    gray: np.ndarray
    material: np.ndarray
    material_gray: object
    n_moved: int


def subpixel_mesh(image, points, triangles, gray, material,
                  subpixel_max_shift=DEFAULTS.subpixel_max_shift, renumber=True):
    """A segmented mesh with its boundary vertices at the ISO-50 crossings
    (:func:`place_boundary_vertices`), each material's level from its triangles away from
    the boundary (:func:`material_levels_of_mesh`), and the grays of the triangles around
    a moved vertex measured again (:func:`ctseg.triangle_gray`). With ``renumber`` the
    materials are numbered again by ascending mean gray (the moves change the means a
    little: on a coarse mesh, their order); without, the numbers stay (given levels).

    Returns
    -------
    MovedMesh

    Example
    -------
    >>> img = np.where(np.arange(20)[None, :] < 9.7, 10.0, 90.0).repeat(20, 0)
    >>> pts = np.array([[0, 0], [19, 0], [19, 19], [0, 19], [9, 0], [9, 19], [9, 9.5]], float)
    >>> tri = np.array([[0, 4, 6], [4, 1, 6], [1, 2, 6], [2, 5, 6], [5, 3, 6], [3, 0, 6]])
    >>> mat = np.array([0, 1, 1, 1, 0, 0])
    >>> out = subpixel_mesh(img, pts, tri, triangle_gray(img, pts, tri), mat)
    >>> out.n_moved, bool(abs(out.points[6, 0] - 9.5) < 0.1)  # the edge is at x = 9.5
    (1, True)
    """
    pts = np.asarray(points, float)
    tri = np.asarray(triangles, np.int64)
    mat = np.asarray(material, np.int64)
    new_gray = np.array(gray, float)
    if len(tri) == 0:
        return MovedMesh(pts.copy(), new_gray, mat, np.zeros(0) if renumber else None, 0)
    n_mat = int(mat.max()) + 1
    # vertices between materials: their triangles do not measure a material's level
    interior = ~(_vertex_materials(tri, mat, len(pts))[2] > 1)[tri].any(axis=1)
    area = triangle_areas(pts, tri)
    levels = material_levels_of_mesh(new_gray, area, mat, interior, n_mat)
    moved, n_moved = place_boundary_vertices(pts, tri, mat, image, levels,
                                             max_shift_fraction=subpixel_max_shift)
    touched = np.any(moved[tri] != pts[tri], axis=(1, 2))
    if touched.any():  # only triangles with a moved vertex change
        new_gray[touched] = triangle_gray(image, moved, tri[touched])
    mat_gray = None
    if renumber:
        mat, mat_gray, _ = order_by_gray(mat, new_gray, triangle_areas(moved, tri))
    return MovedMesh(moved, new_gray, mat, mat_gray, n_moved)
